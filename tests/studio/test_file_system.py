"""The studio's save folder under concurrency and a hostile file system: concurrent first saves of one
name (exactly one wins, its content intact), a folder deleted or replaced by a file while the studio
runs, a read-only and an unreadable folder, a file system without hard links. Every answer is one the
page shows (4xx, 503), never a 500.
"""

from __future__ import annotations

import ctypes
import errno
import http.client
import json
import os
import shutil
import sys
import tempfile
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
from flask import Flask
from flask.testing import FlaskClient

from tests.studio.browser import live_studio
from torchrl_subgoal import load_patterns
from torchrl_subgoal.studio.server import create_app

SAVERS = 15  # concurrent saves of one name: the issue saw 2, 7 and 8 of 15 "win"
ROUNDS = 6  # names raced for, one after the other
NOBODY = 65534


def drawing(pattern: str) -> dict[str, Any]:
    return {"domain": "four_rooms", "patterns": [{"name": pattern, "subgoals": [{"cell": [3, 6]}], "order": None}]}


def race(port: int, token: str, name: str, overwrite: bool) -> list[tuple[int, str]]:
    """:data:`SAVERS` threads PUT their own drawing of ``name`` at once (a barrier releases them): each
    one's (status, pattern name)."""
    barrier = threading.Barrier(SAVERS)
    answers: list[tuple[int, str]] = [(0, "")] * SAVERS
    query = "?overwrite=1" if overwrite else ""

    def save(i: int) -> None:
        connection = http.client.HTTPConnection("127.0.0.1", port, timeout=300)
        body = json.dumps(drawing(f"saver_{i}"))
        headers = {"Content-Type": "application/json", "X-Studio-Token": token}
        connection.connect()
        barrier.wait()
        connection.request("PUT", f"/api/files/{name}{query}", body=body, headers=headers)
        response = connection.getresponse()
        answers[i] = (response.status, json.loads(response.read()).get("error", ""))
        connection.close()

    threads = [threading.Thread(target=save, args=(i,)) for i in range(SAVERS)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    return [(status, error) for status, error in answers]


def test_concurrent_first_saves_of_one_name_one_wins_the_others_get_409(tmp_path: Path) -> None:
    """Two tabs (or fifteen) saving the same new name: exactly one creates the file, every other one is
    told it exists, and the file holds the winner's drawing, whole."""
    folder = tmp_path / "files"
    with live_studio(folder) as (url, _):
        port, token = int(url.split(":")[2].split("/")[0]), url.split("token=")[1]
        for round_ in range(ROUNDS):
            name = f"plan{round_}.yaml"
            answers = race(port, token, name, overwrite=False)
            winners = [i for i, (status, _) in enumerate(answers) if status == 200]
            assert len(winners) == 1, answers
            losers = [answer for i, answer in enumerate(answers) if i != winners[0]]
            assert all(status == 409 and f"{name} exists in the save folder" in error for status, error in losers)
            assert list(load_patterns(folder / name)) == [f"saver_{winners[0]}"]
        replaced = race(port, token, "plan0.yaml", overwrite=True)  # overwrite: every save lands, whole
        assert {status for status, _ in replaced} == {200}
        assert next(iter(load_patterns(folder / "plan0.yaml"))) in {f"saver_{i}" for i in range(SAVERS)}
    assert sorted(p.name for p in folder.iterdir()) == [f"plan{r}.yaml" for r in range(ROUNDS)]  # no temporary left


def test_without_hard_links_a_first_save_is_still_exclusive(
    client: FlaskClient, app: Flask, monkeypatch: pytest.MonkeyPatch
) -> None:
    """On a file system without hard links (FAT, some network mounts) the name is claimed exclusively
    instead, then the written file renamed over the claim."""

    def no_link(*args: Any, **kwargs: Any) -> None:
        raise OSError(errno.EPERM, "Operation not permitted")

    monkeypatch.setattr(os, "link", no_link)
    folder = Path(app.extensions["studio"].folder)
    barrier = threading.Barrier(8)
    statuses: list[int] = [0] * 8

    def save(i: int) -> None:
        own = app.test_client()
        barrier.wait()
        statuses[i] = own.put("/api/files/plan.yaml", json=drawing(f"saver_{i}")).status_code

    threads = [threading.Thread(target=save, args=(i,)) for i in range(8)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert sorted(statuses) == [200] + [409] * 7, statuses
    assert list(load_patterns(folder / "plan.yaml")) == [f"saver_{statuses.index(200)}"]
    assert client.put("/api/files/plan.yaml?overwrite=1", json=drawing("again")).status_code == 200
    assert list(load_patterns(folder / "plan.yaml")) == ["again"]
    assert [p.name for p in folder.iterdir()] == ["plan.yaml"]


def every_file_route(client: FlaskClient) -> dict[str, tuple[int, str]]:
    """List, open, download and save: route -> (status, error)."""

    def answer(response: Any) -> tuple[int, str]:
        error = response.json.get("error", "") if response.is_json and isinstance(response.json, dict) else ""
        return response.status_code, error

    return {
        "list": answer(client.get("/api/files")),
        "open": answer(client.get("/api/files/kept.yaml")),
        "download": answer(client.get("/files/kept.yaml")),
        "save": answer(client.put("/api/files/new.yaml", json=drawing("p"))),
        "overwrite": answer(client.put("/api/files/kept.yaml?overwrite=1", json=drawing("p"))),
    }


@pytest.mark.parametrize("replacement", ["deleted", "a file"])
def test_a_save_folder_gone_while_the_studio_runs_is_503_on_every_route(
    client: FlaskClient, app: Flask, replacement: str
) -> None:
    folder = Path(app.extensions["studio"].folder)
    assert client.put("/api/files/kept.yaml", json=drawing("p")).status_code == 200
    shutil.rmtree(folder)
    if replacement == "a file":
        folder.write_text("not a folder\n")
    answers = every_file_route(client)
    assert {route: status for route, (status, _) in answers.items()} == dict.fromkeys(answers, 503), answers
    for _, error in answers.values():
        assert f"the save folder {folder.resolve()} is gone" in error and "--folder" in error
    if replacement == "a file":
        assert folder.read_text() == "not a folder\n"  # nothing written into (or over) it
        folder.unlink()
    folder.mkdir()  # the folder is back: the studio works again
    assert client.put("/api/files/kept.yaml", json=drawing("p")).status_code == 200
    assert client.get("/api/files").json["files"] == [
        {"name": "kept.yaml", "bytes": (folder / "kept.yaml").stat().st_size}
    ]


@contextmanager
def unprivileged() -> Iterator[None]:
    """File-system access as ``nobody`` in this thread, where it runs as root (root passes every permission
    check): Linux's ``setfsuid`` changes only the calling thread's file-system ids, restored after."""
    if os.geteuid() != 0:
        yield
        return
    libc = ctypes.CDLL(None, use_errno=True)
    libc.setfsgid(NOBODY)
    libc.setfsuid(NOBODY)
    try:
        yield
    finally:
        libc.setfsuid(0)
        libc.setfsgid(0)


@pytest.mark.skipif(sys.platform != "linux", reason="as root, needs Linux's per-thread setfsuid")
def test_a_read_only_or_unreadable_folder_is_403_with_the_reason() -> None:
    with tempfile.TemporaryDirectory(prefix="studio-permissions-") as tmp:
        os.chmod(tmp, 0o755)
        folder = Path(tmp) / "files"
        app = create_app(folder)
        client = app.test_client()
        assert client.put("/api/files/kept.yaml", json=drawing("p")).status_code == 200
        every_file_route(client)  # once with every permission: whatever is compiled or cached on first use
        (folder / "new.yaml").unlink()
        answers = {}
        try:
            for name, mode in (("read-only", 0o555), ("unreadable", 0o000)):
                os.chmod(folder, mode)
                with unprivileged():
                    answers[name] = every_file_route(client)
        finally:
            os.chmod(folder, 0o755)
            app.extensions["studio"].jobs.shutdown()
        files = sorted(p.name for p in folder.iterdir())
    read_only, unreadable = answers["read-only"], answers["unreadable"]
    assert {route: status for route, (status, _) in read_only.items()} == {
        "list": 200,
        "open": 200,
        "download": 200,
        "save": 403,
        "overwrite": 403,
    }, read_only
    assert read_only["save"][1].startswith(f"cannot save new.yaml in the save folder {folder} (Permission denied)")
    assert "let this user read and write it" in read_only["save"][1]
    assert {route: status for route, (status, _) in unreadable.items()} == dict.fromkeys(unreadable, 403), unreadable
    assert unreadable["list"][1].startswith(f"cannot list the files in the save folder {folder} (Permission denied)")
    assert unreadable["open"][1].startswith(f"cannot read kept.yaml in the save folder {folder} (Permission denied)")
    assert unreadable["download"][1] == unreadable["open"][1]
    assert files == ["kept.yaml"]  # nothing written, no temporary file left
