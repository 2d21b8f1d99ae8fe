"""The studio's JSON API: every bad input is a 4xx whose message names the file, pattern and field."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from flask import Flask
from flask.testing import FlaskClient

from torchrl_subgoal import load_patterns
from torchrl_subgoal.studio import server
from torchrl_subgoal.studio.document import MAX_REQUEST_BYTES
from torchrl_subgoal.subgoals import Cell, Circle


def four_rooms(*cells: tuple[int, int], name: str = "p", **extra: Any) -> dict[str, Any]:
    subgoals = [{"cell": list(c)} for c in cells]
    return {"domain": "four_rooms", "patterns": [{"name": name, "subgoals": subgoals, "order": None}], **extra}


def pinball(*circles: tuple[float, float, float], map_: str = "simple") -> dict[str, Any]:
    subgoals = [{"circle": {"centre": [x, y], "radius": r}} for x, y, r in circles]
    return {"domain": "pinball", "map": map_, "patterns": [{"name": "p", "subgoals": subgoals, "order": None}]}


def named(order: list[list[str]] | None, **cells: tuple[int, int]) -> dict[str, Any]:
    subgoals = [{"name": n, "cell": list(c)} for n, c in cells.items()]
    return {"domain": "four_rooms", "patterns": [{"name": "p", "subgoals": subgoals, "order": order}]}


# --------------------------------------------------------------------------- what works


def test_domains_and_geometry_come_from_the_envs(client: FlaskClient) -> None:
    from torchrl_subgoal.envs import four_rooms as fr
    from torchrl_subgoal.envs.pinball import PinBallConfig

    listed = client.get("/api/domains").json
    assert [d["name"] for d in listed] == [
        "four_rooms",
        "pinball",
        "pick_and_place",
        "point_maze_umaze",
        "point_maze_medium",
        "mountain_car",
    ]
    domains = {d["name"]: d for d in listed}
    assert domains["pinball"]["maps"] == ["simple", "hard"]
    assert domains["four_rooms"]["limits"]["episodes"]["max"] >= domains["four_rooms"]["limits"]["episodes"]["default"]
    grid = client.get("/api/geometry?domain=four_rooms").json
    assert grid["rows"] == fr.LAYOUT.splitlines() and grid["start"] == list(fr.START) and grid["goal"] == list(fr.GOAL)
    hard = client.get("/api/geometry?domain=pinball&map=hard").json
    cfg = PinBallConfig.load("hard")
    assert hard["target"] == list(cfg.target) and len(hard["polygons"]) == len(cfg.polygons)
    assert "bounds" not in hard and "y_up" not in hard  # the page's default: the unit square, y down


def test_extra_pinball_map_file(tmp_path: Path) -> None:
    from torchrl_subgoal.envs.pinball import _DATA_DIR

    custom = tmp_path / "box.cfg"
    custom.write_text((_DATA_DIR / "simple.cfg").read_text().replace("target 0.9 0.2", "target 0.5 0.1"))
    client = server.create_app(tmp_path / "files", pinball_maps={"box": custom}).test_client()
    pinball = next(d for d in client.get("/api/domains").json if d["name"] == "pinball")
    assert pinball["maps"] == ["simple", "hard", "box"]
    assert client.get("/api/geometry?domain=pinball&map=box").json["target"][:2] == [0.5, 0.1]


def test_save_open_round_trip_with_names_partial_order_and_several_patterns(client: FlaskClient, app: Flask) -> None:
    body = {
        "domain": "four_rooms",
        "patterns": [
            {"name": "chain", "subgoals": [{"cell": [3, 6]}, {"cell": [7, 9]}], "order": None},
            {
                "name": "dag",
                "subgoals": [
                    {"name": "west", "cell": [6, 2]},
                    {"name": "east", "cell": [3, 6]},
                    {"name": "door", "cell": [10, 6]},
                ],
                "order": [["west", "door"], ["east", "door"]],
            },
            {"name": "named_chain", "subgoals": [{"name": "a", "cell": [1, 2]}, {"cell": [2, 2]}], "order": None},
        ],
    }
    saved = client.put("/api/files/mine", json=body)
    assert saved.status_code == 200, saved.json
    path = Path(saved.json["path"])
    assert path.name == "mine.yaml" and path.parent == app.extensions["studio"].folder.resolve()
    assert "torchrl-subgoal reproduce four-rooms --subgoals" in saved.json["recipe"]
    patterns = load_patterns(path, domain="four_rooms")  # what the recipes read
    assert patterns["chain"].predicates == (Cell(3, 6), Cell(7, 9)) and patterns["chain"].is_chain
    assert patterns["dag"].order == ((0, 2), (1, 2)) and patterns["dag"].names == ("west", "east", "door")
    assert patterns["named_chain"].names == ("a", "sg2") and patterns["named_chain"].is_chain
    opened = client.get("/api/files/mine.yaml").json
    assert opened["domain"] == "four_rooms"
    assert opened["patterns"][0] == {
        "name": "chain",
        "order": None,
        "description": None,
        "subgoals": [{"name": None, "cell": [3, 6]}, {"name": None, "cell": [7, 9]}],
    }
    assert opened["patterns"][1]["order"] == [["west", "door"], ["east", "door"]]
    assert (
        client.put("/api/files/again.yaml", json={"domain": "four_rooms", "patterns": opened["patterns"]}).status_code
        == 200
    )
    assert load_patterns(path.with_name("again.yaml")) == patterns  # a round trip changes nothing
    assert [f["name"] for f in client.get("/api/files").json["files"]] == ["again.yaml", "mine.yaml"]
    assert client.get("/files/mine.yaml").data == path.read_bytes()


def test_pinball_saves_circles_the_recipe_reads(client: FlaskClient) -> None:
    saved = client.put("/api/files/pb.json", json=pinball((0.5877, 0.6486, 0.04), (0.6442, 0.3202, 0.05)))
    assert saved.status_code == 200, saved.json
    assert "--map simple" in saved.json["recipe"]
    series = load_patterns(saved.json["path"], domain="pinball")["p"]
    assert series.predicates == (Circle((0.5877, 0.6486), 0.04), Circle((0.6442, 0.3202), 0.05))


def test_opening_the_shipped_participants_files(client: FlaskClient, app: Flask) -> None:
    from importlib.resources import files

    folder = app.extensions["studio"].folder
    for name, domain in (("four_rooms_participants.yaml", "four_rooms"), ("pinball_participants.yaml", "pinball")):
        (folder / name).write_text((files("torchrl_subgoal") / "domains" / domain / name).read_text())
        opened = client.get(f"/api/files/{name}").json
        assert opened["domain"] == domain and len(opened["patterns"]) == 10


def test_state_subgoals_open_as_cells(client: FlaskClient, app: Flask) -> None:
    (app.extensions["studio"].folder / "states.yaml").write_text("patterns:\n  p: {subgoals: [{state: 0}]}\n")
    assert client.get("/api/files/states.yaml").json["patterns"][0]["subgoals"] == [{"name": None, "cell": [1, 1]}]


# --------------------------------------------------------------------------- bad drawings


@pytest.mark.parametrize(
    ("body", "message"),
    [
        (four_rooms((3, 6), (0, 6)), "drawing.yaml: pattern 'p': subgoals[1].cell: (0, 6) is a wall"),
        (four_rooms((20, 3)), "drawing.yaml: pattern 'p': subgoals[0].cell: (20, 3) is off the 13x13 grid"),
        (four_rooms((-1, 3)), "subgoals[0].cell: (-1, 3) is off the 13x13 grid"),
        (pinball((1.2, 0.5, 0.04)), "subgoals[0].circle: centre (1.2, 0.5) is off the table"),
        (pinball((0.4, 0.8, 0.04)), "subgoals[0].circle: centre (0.4, 0.8) lies inside obstacle 7 of the 'simple' map"),
        (pinball((0.5, 0.5, 0.04), map_="hard"), "lies inside obstacle"),
        (pinball((0.5, 0.5, -0.1)), "subgoals[0].circle.radius: must be positive, got -0.1"),
        (
            named([["a", "b"], ["b", "a"]], a=(3, 6), b=(7, 9)),
            "pattern 'p': order: the order has a cycle through subgoal 'a'",
        ),
        (named([["a", "a"]], a=(3, 6)), "order: invalid pair (0, 0)"),
        (named([["a", "zz"]], a=(3, 6)), "order[0]: unknown subgoal 'zz'"),
        (
            named(None, a=(3, 6), b=(7, 9))
            | {
                "patterns": [
                    {
                        "name": "p",
                        "order": None,
                        "subgoals": [{"name": "a", "cell": [3, 6]}, {"name": "a", "cell": [7, 9]}],
                    }
                ]
            },
            "the subgoal name 'a' is used twice",
        ),
        (four_rooms(), "pattern 'p': a pattern needs at least one subgoal"),
        (
            four_rooms((3, 6)) | {"patterns": [{"name": "p", "subgoals": [{"cell": [3, 6]}]}] * 2},
            "patterns: the name 'p' is used by two patterns",
        ),
        (
            {"domain": "four_rooms", "patterns": [{"name": "p", "subgoals": [{"cell": "a3"}]}]},
            "subgoals[0].cell: expected a non-empty list of numbers, got 'a3'",
        ),
        (
            {"domain": "four_rooms", "patterns": [{"name": "p", "subgoals": [{"cell": [3.5, 6]}]}]},
            "subgoals[0].cell[0]: expected an integer, got 3.5",
        ),
        (
            {"domain": "four_rooms", "patterns": [{"name": "p", "subgoals": [{"name": "x"}]}]},
            "give exactly one predicate among state, cell, circle, box",
        ),
        (
            {
                "domain": "four_rooms",
                "patterns": [{"name": "p", "subgoals": [{"circle": {"centre": [3, 6], "radius": 1}}]}],
            },
            "four-rooms subgoals are cells or states, not circle",
        ),
        (
            {"domain": "pinball", "patterns": [{"name": "p", "subgoals": [{"cell": [3, 6]}]}]},
            "pinball subgoals are circles over (x, y), not cell",
        ),
        (
            {"domain": "chess", "patterns": []},
            "request: domain: expected one of ['four_rooms', 'mountain_car', 'pick_and_place', 'pinball', "
            "'point_maze_medium', 'point_maze_umaze'], got 'chess'",
        ),
        (pinball((0.5, 0.5, 0.04), map_="moon"), "request: map: expected one of ['simple', 'hard'], got 'moon'"),
        ({"domain": "four_rooms", "patterns": []}, "request: patterns: expected a non-empty list"),
        ({"domain": "four_rooms", "patterns": {"p": []}}, "request: patterns: expected a non-empty list"),
        (
            {"domain": "four_rooms", "patterns": [{"name": "", "subgoals": []}]},
            "patterns[0].name: expected a non-empty string",
        ),
        (
            {"domain": "four_rooms", "patterns": [{"name": "p", "subgoals": "here"}]},
            "patterns[0].subgoals: expected a list",
        ),
        (
            {"domain": "four_rooms", "patterns": [{"name": "p", "subgoals": [[3, 6]]}]},
            "patterns[0].subgoals[0]: expected an object",
        ),
        (
            {"domain": "four_rooms", "patterns": [{"name": "p", "subgoals": [], "colour": 1}]},
            "unknown field(s) ['colour']",
        ),
        (
            {"domain": "four_rooms", "patterns": [{"name": "p", "subgoals": [], "order": "any"}]},
            "patterns[0].order: expected null",
        ),
        ({"domain": "four_rooms", "patterns": [], "extra": 1}, "request: unknown field(s) ['extra']"),
        ([1, 2], "request: expected a JSON object"),
    ],
)
def test_bad_drawings_are_400_with_the_field(client: FlaskClient, body: Any, message: str) -> None:
    for method, url in (("post", "/api/validate"), ("put", "/api/files/bad")):
        response = getattr(client, method)(url, json=body)
        assert response.status_code == 400, response.json
        source = "drawing.yaml" if method == "post" else "bad.yaml"  # the file it would be
        assert message.replace("drawing.yaml", source) in response.json["error"]
    assert client.get("/api/files").json["files"] == []  # nothing saved


def test_messages_name_the_file_being_saved(client: FlaskClient) -> None:
    response = client.put("/api/files/my_plan", json=four_rooms((0, 6)))
    assert response.json["error"].startswith("my_plan.yaml: pattern 'p': subgoals[0].cell")
    response = client.post("/api/validate", json=four_rooms((0, 6), file="other.yml"))
    assert response.json["error"].startswith("other.yml: pattern 'p'")


@pytest.mark.parametrize(
    ("data", "status", "message"),
    [
        (b"{not json", 400, "request: not valid JSON: Expecting property name"),
        (b"", 400, "request: not valid JSON"),
        (b"\xff\xfe{}", 400, "request: the body is not UTF-8 text"),
        (b'{"domain": "four_rooms", "domain": "pinball"}', 400, "the key 'domain' appears twice"),
        (
            b'{"domain": "pinball", "patterns": [{"name": "p", "subgoals": [{"circle": {"centre": [NaN, 0.5], '
            b'"radius": 0.04}}]}]}',
            400,
            "request: NaN is not a JSON number",
        ),
        (b"[" * (MAX_REQUEST_BYTES + 10), 413, f"over the limit of {MAX_REQUEST_BYTES} bytes"),
    ],
)
def test_malformed_and_oversized_requests(client: FlaskClient, data: bytes, status: int, message: str) -> None:
    for method, url in (("post", "/api/validate"), ("put", "/api/files/x"), ("post", "/api/try")):
        response = getattr(client, method)(url, data=data, content_type="application/json")
        assert response.status_code == status, response.json
        assert message in response.json["error"]


# --------------------------------------------------------------------------- files


@pytest.mark.parametrize(
    "name",
    [
        "..%2Fescape",
        "../escape",
        "a/b",
        "%2Fetc%2Fpasswd",
        ".hidden",
        "-flag",
        "x" * 81,
        "a..b",
        "sp ace",
        "%00nul",
    ],
)
def test_file_names_cannot_escape_the_folder(client: FlaskClient, app: Flask, tmp_path: Path, name: str) -> None:
    response = client.put(f"/api/files/{name}", json=four_rooms((3, 6)))
    assert response.status_code in (400, 404), response.json
    assert "file name" in response.json["error"] or "not found" in response.json["error"].lower()
    assert client.get(f"/api/files/{name}").status_code in (400, 404)
    saved = {p for p in tmp_path.rglob("*") if p.is_file()}
    assert saved == set(), saved


def test_open_missing_and_malformed_files(client: FlaskClient, app: Flask) -> None:
    folder = app.extensions["studio"].folder
    missing = client.get("/api/files/nothing.yaml")
    assert missing.status_code == 404 and missing.json["error"] == "nothing.yaml: no such file in the save folder"
    (folder / "broken.yaml").write_text("patterns: {p: {subgoals: [{cell: [0, 0]}]}}\ndomain: four_rooms\n")
    broken = client.get("/api/files/broken.yaml")
    assert broken.status_code == 422
    assert broken.json["error"] == "broken.yaml: pattern 'p': subgoals[0].cell: (0, 0) is a wall"
    (folder / "calls.yaml").write_text("patterns: {p: {subgoals: [{call: 'tests.dict_env:at_door'}]}}\n")
    calls = client.get("/api/files/calls.yaml")
    assert calls.status_code == 422 and "fit none of the studio's domains" in calls.json["error"]
    (folder / "junk.yaml").write_text(": : :\n\t[")
    junk = client.get("/api/files/junk.yaml")
    assert junk.status_code == 422 and junk.json["error"].startswith("junk.yaml: not valid YAML/JSON")


def test_unknown_routes_and_methods_are_json_4xx(client: FlaskClient) -> None:
    assert client.get("/api/nothing").status_code == 404
    assert "error" in client.get("/api/nothing").json
    assert client.delete("/api/files/x.yaml").status_code == 405
    assert client.get("/api/geometry?domain=chess").status_code == 400
    assert "map: expected one of" in client.get("/api/geometry?domain=pinball&map=moon").json["error"]


# --------------------------------------------------------------------------- Try it


@pytest.fixture
def gated(monkeypatch: pytest.MonkeyPatch) -> Iterator[threading.Event]:
    """``try_pattern`` replaced by a job that reports progress until the gate opens (or it is cancelled)."""
    gate = threading.Event()

    def blocked(
        domain: str, series: Any, settings: Any, *, method: str = "HRS-D", map: Any = None, progress: Any = None
    ) -> Any:
        while not gate.wait(0.01):
            progress(0)  # raises once cancelled
        raise RuntimeError("the gate opened")

    monkeypatch.setattr(server, "try_pattern", blocked)
    yield gate
    gate.set()


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"episodes": 0}, "episodes: must be from 1 to 2000, got 0"),
        ({"episodes": 1_000_000}, "episodes: must be from 1 to 2000, got 1000000"),
        ({"learners": 201}, "learners: must be from 1 to 200, got 201"),
        ({"learners": 2.5}, "learners: expected a whole number from 1 to 200, got 2.5"),
        ({"episodes": "10"}, "episodes: expected a whole number from 1 to 2000, got '10'"),
        ({"episodes": True}, "episodes: expected a whole number"),
        ({"max_steps": 10}, "max_steps: must be from 50 to 1000, got 10"),
        ({"pattern": "q"}, "pattern: expected one of ['p'], got 'q'"),
    ],
)
def test_try_settings_are_bounded(client: FlaskClient, fields: dict[str, Any], message: str) -> None:
    response = client.post("/api/try", json=four_rooms((3, 6)) | fields)
    assert response.status_code == 400 and message in response.json["error"]


def test_try_bad_pattern_is_400(client: FlaskClient) -> None:
    response = client.post("/api/try", json=four_rooms((3, 6), (0, 0)))
    assert response.status_code == 400 and "subgoals[1].cell: (0, 0) is a wall" in response.json["error"]
    response = client.post("/api/try", json=pinball((0.5, 0.5, 0.04), map_="hard") | {"episodes": 5})
    assert response.status_code == 400 and "inside obstacle" in response.json["error"]


def test_one_job_per_pattern_and_a_few_at_once(client: FlaskClient, gated: threading.Event) -> None:
    first = client.post("/api/try", json=four_rooms((3, 6), name="a"))
    assert first.status_code == 202 and first.json["state"] == "running"
    again = client.post("/api/try", json=four_rooms((7, 9), name="a"))
    assert again.status_code == 409
    assert again.json["error"].startswith("four_rooms/a/HRS-D: a learning with this pattern is already running")
    second = client.post("/api/try", json=four_rooms((3, 6), name="b"))
    assert second.status_code == 202
    third = client.post("/api/try", json=four_rooms((3, 6), name="c"))
    assert third.status_code == 429 and "2 learnings are running" in third.json["error"]
    for job in (first.json["id"], second.json["id"]):
        assert client.delete(f"/api/try/{job}").status_code == 200
    jobs = client.application.extensions["studio"].jobs
    assert [jobs.wait(j, 60).state for j in (first.json["id"], second.json["id"])] == ["cancelled"] * 2
    assert client.post("/api/try", json=four_rooms((3, 6), name="a")).status_code == 202  # free again


def test_a_failing_job_reports_its_error_not_a_500(client: FlaskClient, gated: threading.Event) -> None:
    job = client.post("/api/try", json=four_rooms((3, 6))).json["id"]
    gated.set()
    client.application.extensions["studio"].jobs.wait(job, 60)
    status = client.get(f"/api/try/{job}")
    assert status.status_code == 200
    assert status.json["state"] == "failed" and status.json["error"] == "RuntimeError: the gate opened"


def test_unknown_job_is_404(client: FlaskClient) -> None:
    for method in ("get", "delete"):
        response = getattr(client, method)("/api/try/nope")
        assert response.status_code == 404 and response.json["error"].startswith("job 'nope': unknown")


def test_try_runs_and_reports_curves_and_potential(client: FlaskClient) -> None:
    started = client.post("/api/try", json=four_rooms((3, 6), (7, 9)) | {"episodes": 6, "learners": 3})
    assert started.status_code == 202 and started.json["total"] == 2 * 3 * 6
    job = client.application.extensions["studio"].jobs.wait(started.json["id"], 600)
    assert job.state == "done", job.error
    status = client.get(f"/api/try/{job.id}").json
    result = status["result"]
    assert status["progress"] == 1.0 and result["pattern"] == "p"
    assert len(result["shaped"]["mean"]) == len(result["baseline"]["sem"]) == 6
    assert len(result["potential"]) == 3 and result["settings"]["learners"] == 3


def test_try_it_takes_the_shaping_method(client: FlaskClient) -> None:
    """ "Try it" runs HRS-D (the library's default potential) by default, or the method the page chose (SRS:
    its fixed prior is the table shown; NRS: no table); any other method is a 400 naming the field."""
    jobs = client.application.extensions["studio"].jobs
    for method, table in (("HRS-D", None), ("SRS", [0.0, 0.333, 0.667]), ("NRS", [])):
        chosen = {} if method == "HRS-D" else {"method": method}
        started = client.post("/api/try", json=four_rooms((3, 6), (7, 9)) | {"episodes": 2, **chosen})
        assert started.status_code == 202, started.json
        job = jobs.wait(started.json["id"], 600)
        assert job.state == "done", job.error
        result = client.get(f"/api/try/{job.id}").json["result"]
        assert result["method"] == method
        if table is not None:
            assert [round(v, 3) for v in result["potential"]] == table
    wrong = client.post("/api/try", json=four_rooms((3, 6)) | {"method": "PBRS"})
    assert wrong.status_code == 400 and "method: expected one of ['HRS-D', 'HRS', 'SRS', 'NRS']" in wrong.json["error"]
