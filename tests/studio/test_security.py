"""The studio against a hostile environment: planted links, foreign hosts and origins, non-JSON
requests, a missing token, malformed bodies. Every refusal is a 4xx that changes nothing.
"""

from __future__ import annotations

import json
import os
import socket
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from flask import Flask
from flask.testing import FlaskClient

from tests.studio.browser import live_studio
from torchrl_subgoal import load_patterns
from torchrl_subgoal.studio import server
from torchrl_subgoal.studio.document import MAX_REQUEST_BYTES
from torchrl_subgoal.subgoals import Cell

DRAWING = {"domain": "four_rooms", "patterns": [{"name": "p", "subgoals": [{"cell": [3, 6]}], "order": None}]}
OTHER = {"domain": "four_rooms", "patterns": [{"name": "q", "subgoals": [{"cell": [7, 9]}], "order": None}]}
SECRET = "precious: do not overwrite\n"
MAX_DEPTH = 32  # the documented limit of nesting (studio.document.MAX_DEPTH)


def folder_of(app: Flask) -> Path:
    return Path(app.extensions["studio"].folder)


def snapshot(*roots: Path) -> dict[str, tuple[str, bytes | str]]:
    """Every entry below ``roots``: a link's target, a file's bytes (what a refused request must not change)."""
    seen: dict[str, tuple[str, bytes | str]] = {}
    for root in roots:
        for path in sorted(root.rglob("*")):
            if path.is_symlink():
                seen[str(path)] = ("link", os.readlink(path))
            elif path.is_file():
                seen[str(path)] = ("file", path.read_bytes())
    return seen


@pytest.fixture
def gated(monkeypatch: pytest.MonkeyPatch) -> Iterator[threading.Event]:
    """``try_pattern`` replaced by a job that waits for the gate (or its cancellation): jobs started stay visible."""
    gate = threading.Event()

    def blocked(
        domain: str, series: Any, settings: Any, *, method: str = "HRS-D", map: Any = None, progress: Any = None
    ) -> Any:
        while not gate.wait(0.01):
            progress(0)
        return {"ok": True}

    monkeypatch.setattr(server, "try_pattern", blocked)
    yield gate
    gate.set()


# --------------------------------------------------------------------------- links in the folder


def test_a_planted_temporary_link_is_never_written_through(client: FlaskClient, app: Flask, tmp_path: Path) -> None:
    """The name an earlier version wrote to first (``.NAME.tmp``), planted as a link to a file elsewhere."""
    outside = tmp_path / "outside.txt"
    outside.write_text(SECRET)
    folder = folder_of(app)
    (folder / ".plan.yaml.tmp").symlink_to(outside)
    saved = client.put("/api/files/plan.yaml", json=DRAWING)
    assert saved.status_code == 200, saved.json
    assert outside.read_text() == SECRET
    assert (folder / ".plan.yaml.tmp").is_symlink() and os.readlink(folder / ".plan.yaml.tmp") == str(outside)
    assert not (folder / "plan.yaml").is_symlink()
    assert load_patterns(folder / "plan.yaml")["p"].predicates == (Cell(3, 6),)
    assert sorted(p.name for p in folder.iterdir()) == [".plan.yaml.tmp", "plan.yaml"]  # no temporary file left


@pytest.mark.parametrize("target", ["outside", "inside"])
def test_a_link_at_the_name_is_replaced_only_when_asked_never_written_through(
    client: FlaskClient, app: Flask, tmp_path: Path, target: str
) -> None:
    folder = folder_of(app)
    victim = tmp_path / "outside.yaml" if target == "outside" else folder / "theirs.yaml"
    victim.write_text(SECRET)
    (folder / "plan.yaml").symlink_to(victim)
    before = snapshot(folder, tmp_path / "outside.yaml") if target == "outside" else snapshot(folder)
    refused = client.put("/api/files/plan.yaml", json=DRAWING)
    assert refused.status_code == 409, refused.json
    assert refused.json["error"] == "plan.yaml exists in the save folder; choose another name, or confirm replacing it"
    assert (snapshot(folder, tmp_path / "outside.yaml") if target == "outside" else snapshot(folder)) == before
    replaced = client.put("/api/files/plan.yaml?overwrite=1", json=DRAWING)
    assert replaced.status_code == 200, replaced.json
    assert victim.read_text() == SECRET  # the link was replaced, its target untouched
    assert not (folder / "plan.yaml").is_symlink()
    assert load_patterns(folder / "plan.yaml")["p"].predicates == (Cell(3, 6),)


def test_saving_over_an_existing_file_is_a_conflict_unless_asked(client: FlaskClient, app: Flask) -> None:
    folder = folder_of(app)
    assert client.put("/api/files/plan", json=DRAWING).status_code == 200
    first = (folder / "plan.yaml").read_bytes()
    for url in ("/api/files/plan", "/api/files/plan.yaml", "/api/files/plan.yaml?overwrite=0"):
        conflict = client.put(url, json=OTHER)
        assert conflict.status_code == 409 and "plan.yaml exists in the save folder" in conflict.json["error"]
        assert (folder / "plan.yaml").read_bytes() == first
    assert client.put("/api/files/plan?overwrite=1", json=OTHER).status_code == 200
    assert list(load_patterns(folder / "plan.yaml")) == ["q"]
    (folder / "dir.yaml").mkdir()
    for url in ("/api/files/dir.yaml", "/api/files/dir.yaml?overwrite=1"):
        refused = client.put(url, json=DRAWING)
        assert refused.status_code == 409 and "a directory" in refused.json["error"]
    assert (folder / "dir.yaml").is_dir() and not list((folder / "dir.yaml").iterdir())


def test_links_out_of_the_folder_are_neither_listed_nor_read(client: FlaskClient, app: Flask, tmp_path: Path) -> None:
    folder = folder_of(app)
    outside = tmp_path / "private.yaml"
    outside.write_text("patterns: {p: {subgoals: [{cell: [3, 6]}]}}\n")
    (folder / "leak.yaml").symlink_to(outside)
    (folder / "loop.yaml").symlink_to(folder / "loop.yaml")
    assert client.get("/api/files").json["files"] == []
    for url in ("/api/files/leak.yaml", "/files/leak.yaml"):
        response = client.get(url)
        assert response.status_code == 400 and "directly in the save folder" in response.json["error"]
    assert client.get("/api/files/loop.yaml").status_code == 404
    (folder / "mine.yaml").write_text(outside.read_text())
    (folder / "alias.yaml").symlink_to(folder / "mine.yaml")  # a link within the folder opens
    assert client.get("/api/files/alias.yaml").json["patterns"][0]["name"] == "p"
    assert client.get("/files/alias.yaml").data == outside.read_bytes()


# --------------------------------------------------------------------------- hosts, origins, content types


def requests_of_every_kind(
    client: FlaskClient, headers: dict[str, str], content_type: str = "application/json", job: str = "nope"
) -> dict[str, int]:
    """One request to every route with ``headers``: route -> status."""
    import json

    body = json.dumps(DRAWING)
    return {
        "page": client.get("/", headers=headers).status_code,
        "list": client.get("/api/files", headers=headers).status_code,
        "open": client.get("/api/files/kept.yaml", headers=headers).status_code,
        "download": client.get("/files/kept.yaml", headers=headers).status_code,
        "validate": client.post("/api/validate", data=body, content_type=content_type, headers=headers).status_code,
        "save": client.put("/api/files/new.yaml", data=body, content_type=content_type, headers=headers).status_code,
        "overwrite": client.put(
            "/api/files/kept.yaml?overwrite=1", data=body, content_type=content_type, headers=headers
        ).status_code,
        "try": client.post("/api/try", data=body, content_type=content_type, headers=headers).status_code,
        "cancel": client.delete(f"/api/try/{job}", headers=headers).status_code,
    }


@pytest.mark.parametrize(
    "host",
    [
        "evil.example",
        "evil.example:8765",
        "127.0.0.1.evil.example",
        "localhost.example",
        "10.0.0.1",
        "[::2]:80",
        "",
        "bad host",
    ],
)
def test_a_foreign_host_is_refused_and_changes_nothing(
    client: FlaskClient, app: Flask, gated: threading.Event, host: str
) -> None:
    """A DNS-rebinding page reaches the studio under its own name: every route refuses it."""
    folder = folder_of(app)
    assert client.put("/api/files/kept.yaml", json=OTHER).status_code == 200
    job = client.post("/api/try", json=OTHER).json["id"]
    before = snapshot(folder)
    statuses = requests_of_every_kind(client, {"Host": host}, job=job)
    assert set(statuses.values()) == {403}, statuses
    refused = client.get("/api/files", headers={"Host": host})
    assert "is not served by this studio" in refused.json["error"]
    assert snapshot(folder) == before
    jobs = app.extensions["studio"].jobs
    assert [j.id for j in jobs.running()] == [job]  # no job started, the running one not cancelled


def raw_request(port: int, method: str, path: str, headers: dict[str, str], body: bytes = b"") -> tuple[int, bytes]:
    """One HTTP/1.1 request written byte by byte on a socket (no client adds a ``Host``): status, body."""
    lines = [f"{method} {path} HTTP/1.1", *(f"{k}: {v}" for k, v in headers.items())]
    lines += [f"Content-Length: {len(body)}", "Connection: close"]
    with socket.create_connection(("127.0.0.1", port), timeout=120) as sock:
        sock.sendall(("\r\n".join(lines) + "\r\n\r\n").encode() + body)
        answer = b""
        while chunk := sock.recv(65536):
            answer += chunk
    head, _, content = answer.partition(b"\r\n\r\n")
    return int(head.split()[1]), content


def test_a_request_without_a_host_header_is_refused_and_changes_nothing(tmp_path: Path) -> None:
    """Browsers always send ``Host``; a request without one (HTTP/1.1, the right token) names no studio: 403."""
    folder = tmp_path / "files"
    with live_studio(folder) as (url, app):
        port, token = int(url.split(":")[2].split("/")[0]), url.split("token=")[1]
        (folder / "kept.yaml").write_text("patterns: {p: {subgoals: [{cell: [3, 6]}]}}\n")
        before = snapshot(folder)
        auth = {"X-Studio-Token": token}
        as_json = {**auth, "Content-Type": "application/json"}
        body = json.dumps(DRAWING).encode()
        requests = [
            ("GET", "/", auth, b""),
            ("GET", "/api/files", auth, b""),
            ("GET", "/api/files/kept.yaml", auth, b""),
            ("GET", "/files/kept.yaml", auth, b""),
            ("POST", "/api/validate", as_json, body),
            ("PUT", "/api/files/new.yaml", as_json, body),
            ("PUT", "/api/files/kept.yaml?overwrite=1", as_json, body),
            ("POST", "/api/try", as_json, body),
            ("DELETE", "/api/try/nope", auth, b""),
        ]
        answers = {
            (method, path): raw_request(port, method, path, headers, data) for method, path, headers, data in requests
        }
        assert {key: status for key, (status, _) in answers.items()} == {key: 403 for key in answers}
        assert b"no Host header" in answers[("GET", "/api/files")][1]
        assert snapshot(folder) == before
        assert app.extensions["studio"].jobs.running() == []
        served = raw_request(port, "GET", "/api/files", {**auth, "Host": f"127.0.0.1:{port}"})
        assert served[0] == 200 and b"kept.yaml" in served[1]  # the same request naming the studio is served


@pytest.mark.parametrize(
    "host", ["localhost", "localhost:8765", "127.0.0.1:8765", "127.0.0.2", "[::1]:8765", "LOCALHOST:1"]
)
def test_loopback_hosts_are_served(client: FlaskClient, gated: threading.Event, host: str) -> None:
    assert client.put("/api/files/kept.yaml", json=OTHER).status_code == 200
    statuses = requests_of_every_kind(client, {"Host": host})
    assert statuses == {
        "page": 200,
        "list": 200,
        "open": 200,
        "download": 200,
        "validate": 200,
        "save": 200,
        "overwrite": 200,
        "try": 202,
        "cancel": 404,
    }


def test_the_bound_address_and_allowed_hosts_are_served(tmp_path: Path) -> None:
    app = server.create_app(tmp_path / "files", hosts=["192.168.1.5", "Studio.LAN"])
    client = app.test_client()
    for host in ("192.168.1.5:8765", "studio.lan", "studio.lan.:80", "localhost"):
        assert client.get("/api/files", headers={"Host": host}).status_code == 200, host
    assert client.get("/api/files", headers={"Host": "192.168.1.6"}).status_code == 403
    assert server.served_hosts("192.168.1.5") == ["192.168.1.5"]


@pytest.mark.parametrize(
    "origin",
    ["http://evil.example", "http://localhost:1", "https://localhost", "null", "http://127.0.0.1.evil.example"],
)
@pytest.mark.parametrize("content_type", ["application/json", "text/plain"])
def test_a_foreign_origin_is_refused_and_changes_nothing(
    client: FlaskClient, app: Flask, gated: threading.Event, origin: str, content_type: str
) -> None:
    """What a page of another site can send, a "simple" text/plain POST included."""
    folder = folder_of(app)
    assert client.put("/api/files/kept.yaml", json=OTHER).status_code == 200
    job = client.post("/api/try", json=OTHER).json["id"]
    before = snapshot(folder)
    statuses = requests_of_every_kind(client, {"Origin": origin}, content_type=content_type, job=job)
    assert all(400 <= s < 500 for s in statuses.values()), statuses
    assert statuses["try"] == statuses["save"] == statuses["list"] == 403
    assert (
        "from another site"
        in client.post("/api/try", data="{}", content_type=content_type, headers={"Origin": origin}).json["error"]
    )
    assert snapshot(folder) == before
    assert [j.id for j in app.extensions["studio"].jobs.running()] == [job]


def test_the_studios_own_origin_is_served(client: FlaskClient, gated: threading.Event) -> None:
    for origin in ("http://localhost", "HTTP://LOCALHOST"):
        assert client.put("/api/files/a.yaml?overwrite=1", json=DRAWING, headers={"Origin": origin}).status_code == 200
    assert client.post("/api/try", json=DRAWING, headers={"Origin": "http://localhost"}).status_code == 202


@pytest.mark.parametrize("site", ["cross-site", "same-site"])
def test_requests_a_browser_marks_as_from_another_site_are_refused(client: FlaskClient, app: Flask, site: str) -> None:
    """Navigations and ``<img>``/``<script>`` loads carry no Origin; ``Sec-Fetch-Site`` says where they come from."""
    (folder_of(app) / "kept.yaml").write_text("patterns: {p: {subgoals: [{cell: [3, 6]}]}}\n")
    for url in ("/files/kept.yaml", "/api/files/kept.yaml", "/api/files"):
        assert client.get(url, headers={"Sec-Fetch-Site": site}).status_code == 403
        assert client.get(url, headers={"Sec-Fetch-Site": "same-origin"}).status_code == 200
    assert client.get("/", headers={"Sec-Fetch-Site": site}).status_code == 200  # a link to the page is fine


@pytest.mark.parametrize(
    "content_type",
    ["text/plain", "application/x-www-form-urlencoded", "multipart/form-data", "", "application/jsonx", "text/json"],
)
def test_state_changing_requests_must_be_json(
    client: FlaskClient, app: Flask, gated: threading.Event, content_type: str
) -> None:
    folder = folder_of(app)
    assert client.put("/api/files/kept.yaml", json=OTHER).status_code == 200
    before = snapshot(folder)
    statuses = requests_of_every_kind(client, {}, content_type=content_type)
    for route in ("validate", "save", "overwrite", "try"):
        assert statuses[route] == 415, statuses
    refused = client.put("/api/files/new.yaml", data="{}", content_type=content_type)
    assert "needs a JSON body (Content-Type: application/json)" in refused.json["error"]
    assert snapshot(folder) == before and app.extensions["studio"].jobs.running() == []
    assert client.delete("/api/try/x", data="{}", content_type=content_type or "text/plain").status_code == 415
    ok = client.put("/api/files/new.yaml", json=DRAWING, content_type="application/json; charset=utf-8")
    assert ok.status_code == 200


def test_responses_forbid_framing_sniffing_and_referrers(client: FlaskClient) -> None:
    for url in ("/", "/api/domains", "/api/nothing"):
        headers = client.get(url).headers
        assert headers["X-Frame-Options"] == "DENY" and "frame-ancestors 'none'" in headers["Content-Security-Policy"]
        assert headers["X-Content-Type-Options"] == "nosniff" and headers["Referrer-Policy"] == "no-referrer"


# --------------------------------------------------------------------------- the token


def test_with_a_token_every_request_but_static_files_needs_it(tmp_path: Path) -> None:
    app = server.create_app(tmp_path / "files", token="s3cret-token")
    client = app.test_client()
    (folder_of(app) / "kept.yaml").write_text("patterns: {p: {subgoals: [{cell: [3, 6]}]}}\n")
    before = snapshot(folder_of(app))
    for headers in ({}, {"X-Studio-Token": "wrong"}, {"X-Studio-Token": "s3cret-tokenX"}):
        statuses = requests_of_every_kind(client, headers)
        assert set(statuses.values()) == {403}, (headers, statuses)
    assert "token is missing or wrong" in client.get("/api/files").json["error"]
    assert "token is missing or wrong" in client.get("/").get_data(as_text=True)  # the page: plain text
    assert snapshot(folder_of(app)) == before
    good = {"X-Studio-Token": "s3cret-token"}
    assert client.get("/api/files", headers=good).status_code == 200
    assert client.get("/?token=s3cret-token").status_code == 200
    assert client.get("/files/kept.yaml?token=s3cret-token").status_code == 200  # the download link
    assert client.put("/api/files/new.yaml", json=DRAWING, headers=good).status_code == 200
    assert client.get("/static/studio.js").status_code == 200


def test_the_printed_address_carries_the_token() -> None:
    assert server.studio_url("127.0.0.1", 8765, "a-b_c") == "http://127.0.0.1:8765/?token=a-b_c"
    assert server.studio_url("::1", 1) == "http://[::1]:1/"


# --------------------------------------------------------------------------- malformed bodies


NESTED = [
    b"[" * 100_000,  # the RecursionError, within the size limit
    b"[" * 5000 + b"]" * 5000,
    b'{"a":' * 20_000 + b"1" + b"}" * 20_000,
    b"[" * (MAX_DEPTH + 1) + b"]" * (MAX_DEPTH + 1),
    b'{"domain": "four_rooms", "description": ' + b"[" * 40 + b"]" * 40 + b', "patterns": []}',
]


@pytest.mark.parametrize("body", NESTED, ids=["open-100000", "closed-5000", "objects-20000", "just-over", "in-a-field"])
def test_deep_nesting_is_a_400_not_a_500(client: FlaskClient, body: bytes) -> None:
    assert len(body) <= MAX_REQUEST_BYTES
    for method, url in (("post", "/api/validate"), ("put", "/api/files/x"), ("post", "/api/try")):
        response = getattr(client, method)(url, data=body, content_type="application/json")
        assert response.status_code == 400, (url, response.status_code, response.get_data()[:200])
        assert response.json["error"] == f"request: nested deeper than {MAX_DEPTH} levels"
    assert client.get("/api/files").json["files"] == []


def test_nesting_up_to_the_limit_and_brackets_in_strings_are_fine(client: FlaskClient) -> None:
    body = b"[" * MAX_DEPTH + b"]" * MAX_DEPTH
    assert (
        "expected a JSON object"
        in client.post("/api/validate", data=body, content_type="application/json").json["error"]
    )
    name = "[" * 1000
    drawing = {**DRAWING, "patterns": [{"name": name, "subgoals": [{"cell": [3, 6]}], "order": None}]}
    assert client.post("/api/validate", json=drawing).json == {"ok": True, "patterns": [name]}


@pytest.mark.parametrize(
    ("body", "message"),
    [
        (b'{"domain": ' + b"1" * 5000 + b"}", "request: not valid JSON: Exceeds the limit"),
        (
            b'{"domain": "four_rooms", "patterns": [{"name": "p", "subgoals": [{"circle": {"centre": [1e400, 0.5], '
            b'"radius": 0.04}}]}]}',
            "request: a number is too large to be finite (inf)",
        ),
        (b'{"domain": "four_rooms", "description": "\\ud800", "patterns": []}', "lone surrogate"),
        (b'{"\\udfff": 1}', "lone surrogate"),
    ],
)
def test_numbers_and_strings_json_cannot_hold_are_400(client: FlaskClient, body: bytes, message: str) -> None:
    for method, url in (("post", "/api/validate"), ("put", "/api/files/x"), ("post", "/api/try")):
        response = getattr(client, method)(url, data=body, content_type="application/json")
        assert response.status_code == 400 and message in response.json["error"], response.json
    assert client.get("/api/files").json["files"] == []
