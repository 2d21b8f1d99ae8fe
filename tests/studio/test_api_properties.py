"""Property tests of the studio's JSON API: whatever a client sends, the answer is a 2xx or a 4xx
with a one-line ``{"error": ...}``, never a 500, and a refused request changes nothing.

Hypothesis runs derandomized (the same examples every run) and without deadlines.
"""

from __future__ import annotations

import json
import tempfile
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
from flask.testing import FlaskClient
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from torchrl_subgoal.studio import server

PROPERTY = settings(
    max_examples=200,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)

KEYS = [
    "domain",
    "map",
    "patterns",
    "name",
    "subgoals",
    "order",
    "description",
    "file",
    "cell",
    "circle",
    "centre",
    "radius",
    "box",
    "components",
    "margin",
    "state",
    "episodes",
    "learners",
    "pattern",
    "max_steps",
    "call",
    "\ud800",
    "",
]
LEAVES = (
    st.none()
    | st.booleans()
    | st.integers(-(10**6), 10**6)
    | st.integers()
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(max_size=12)
    | st.sampled_from(
        [
            "four_rooms",
            "pinball",
            "pick_and_place",
            "simple",
            "hard",
            "p",
            "sg1",
            "finger_joints",
            "object_relative_position",
        ]
    )
)
JSON = st.recursive(
    LEAVES,
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.sampled_from(KEYS) | st.text(max_size=6), inner, max_size=5)
    ),
    max_leaves=30,
)
CELL = st.lists(st.integers(-2, 14), min_size=2, max_size=2)
CIRCLE = st.fixed_dictionaries(
    {"centre": st.lists(st.floats(-0.5, 1.5), min_size=2, max_size=2), "radius": st.floats(-0.1, 0.6)}
)
BOX = st.fixed_dictionaries(
    {
        "components": st.lists(
            st.sampled_from(["finger_joints", "object_position", "position", "x"]), min_size=0, max_size=2
        ),
        "centre": st.lists(st.floats(-2, 2), max_size=6),
        "margin": st.floats(-0.1, 0.1) | st.lists(st.floats(0, 0.1), max_size=6),
    }
)
SUBGOAL = st.one_of(
    st.builds(lambda c: {"cell": c}, CELL),
    st.builds(lambda c: {"circle": c}, CIRCLE),
    st.builds(lambda b: {"box": b}, BOX),
    st.builds(lambda s: {"state": s}, st.integers(-1, 200)),
    JSON,
)
# drawings that are nearly right: valid structure, random values and now and then a random subtree
DRAWING = st.fixed_dictionaries(
    {
        "domain": st.sampled_from(
            ["four_rooms", "pinball", "pick_and_place", "point_maze_umaze", "point_maze_medium", "mountain_car"]
        )
        | JSON,
        "patterns": st.lists(
            st.fixed_dictionaries(
                {
                    "name": st.sampled_from(["p", "q", "bottom_to_top"]) | st.text(max_size=4) | JSON,
                    "subgoals": st.lists(SUBGOAL, max_size=4) | JSON,
                },
                optional={
                    "order": st.none()
                    | st.lists(st.lists(st.sampled_from(["sg1", "sg2", "a"]), min_size=2, max_size=2), max_size=3)
                    | JSON,
                    "description": st.text(max_size=8) | JSON,
                },
            ),
            max_size=3,
        )
        | JSON,
    },
    optional={
        "map": st.sampled_from(["", "simple", "hard", "moon"]) | JSON,
        "description": st.text(max_size=8) | JSON,
        "file": st.sampled_from(["a.yaml", "../x", ".hidden", "b"]) | JSON,
        "pattern": st.sampled_from(["p", "q"]) | JSON,
        "episodes": st.integers(-5, 3000) | JSON,
        "learners": st.integers(-5, 300) | JSON,
    },
)


@contextmanager
def studio() -> Iterator[tuple[FlaskClient, Path]]:
    """A fresh app on a fresh folder; "Try it" jobs end at once (their learning is not what is tested)."""
    with tempfile.TemporaryDirectory() as tmp, pytest.MonkeyPatch.context() as patch:
        patch.setattr(server, "try_pattern", lambda *args, **kwargs: {"ok": True})
        app = server.create_app(Path(tmp) / "files")
        try:
            yield app.test_client(), Path(tmp) / "files"
        finally:
            app.extensions["studio"].jobs.shutdown()


def check_answer(response: Any) -> None:
    assert response.status_code < 500, (response.status_code, response.get_data()[:300])
    if response.status_code >= 400:
        error = response.json["error"]
        assert isinstance(error, str) and error and "internal error" not in error


def send_everywhere(client: FlaskClient, folder: Path, body: bytes) -> None:
    """``body`` to every route that reads one; a refused save leaves the folder as it was."""
    before = sorted(p.name for p in folder.iterdir())
    for method, url in (("post", "/api/validate"), ("post", "/api/try"), ("put", "/api/files/h.yaml?overwrite=1")):
        response = getattr(client, method)(url, data=body, content_type="application/json")
        check_answer(response)
        if method == "put" and response.status_code != 200:
            assert sorted(p.name for p in folder.iterdir()) == before
        if method == "put" and response.status_code == 200:
            assert client.get("/api/files/h.yaml").status_code in (200, 422)  # what it saved opens (or says why)
    jobs = threading.enumerate()
    assert len([t for t in jobs if t.name.startswith("studio-job-")]) <= 2


@PROPERTY
@given(data=JSON)
def test_any_json_value_gets_a_4xx_or_an_answer(data: Any) -> None:
    with studio() as (client, folder):
        send_everywhere(client, folder, json.dumps(data).encode())


@PROPERTY
@given(data=DRAWING)
def test_near_drawings_get_a_4xx_or_an_answer(data: Any) -> None:
    with studio() as (client, folder):
        send_everywhere(client, folder, json.dumps(data).encode())


@PROPERTY
@given(body=st.binary(max_size=300) | st.text(max_size=300).map(lambda t: t.encode("utf-8", "surrogatepass")))
def test_any_bytes_get_a_4xx_or_an_answer(body: bytes) -> None:
    with studio() as (client, folder):
        send_everywhere(client, folder, body)


HOSTS = st.sampled_from(["localhost", "127.0.0.1:8765", "[::1]", "evil.example", "localhost.evil", "", "a b"])
ORIGINS = st.none() | st.sampled_from(["http://localhost", "http://evil.example", "null", "http://localhost:1"])
TYPES = st.sampled_from(
    ["application/json", "application/json; charset=utf-8", "text/plain", "application/x-www-form-urlencoded", ""]
)


@PROPERTY
@given(host=HOSTS, origin=ORIGINS, content_type=TYPES)
def test_a_save_succeeds_exactly_when_host_origin_and_content_type_are_the_studios(
    host: str, origin: str | None, content_type: str
) -> None:
    drawing = {"domain": "four_rooms", "patterns": [{"name": "p", "subgoals": [{"cell": [3, 6]}], "order": None}]}
    with studio() as (client, folder):
        headers = {"Host": host} | ({"Origin": origin} if origin is not None else {})
        response = client.put("/api/files/h.yaml", data=json.dumps(drawing), content_type=content_type, headers=headers)
        check_answer(response)
        served = host in ("localhost", "127.0.0.1:8765", "[::1]")
        same_origin = origin is None or origin == f"http://{host}"
        expected = served and same_origin and content_type.startswith("application/json")
        assert (response.status_code == 200) == expected, (response.status_code, response.json)
        assert (folder / "h.yaml").exists() == expected


# valid requests of every route that reads JSON; the property below puts a value of the wrong type
# (or nothing) at one place in one of them
FOUR_ROOMS = {
    "domain": "four_rooms",
    "map": "",
    "file": "a.yaml",
    "description": "hallways",
    "patterns": [
        {
            "name": "p",
            "subgoals": [{"name": "a", "cell": [3, 6]}, {"name": "b", "cell": [7, 9]}],
            "order": [["a", "b"]],
            "description": "one",
        },
        {"name": "q", "subgoals": [{"state": 5}], "order": None},
    ],
}
PINBALL = {
    "domain": "pinball",
    "map": "simple",
    "patterns": [{"name": "p", "subgoals": [{"circle": {"centre": [0.5, 0.1], "radius": 0.04}}], "order": None}],
}
PICK_AND_PLACE = {
    "domain": "pick_and_place",
    "patterns": [
        {
            "name": "p",
            "subgoals": [
                {"box": {"components": ["object_relative_position"], "centre": [0.0, 0.0, 0.0], "margin": 0.01}},
                {"box": {"components": ["object_position"], "centre": [1.3, 0.7, 0.6], "margin": [0.02, 0.02, 0.05]}},
            ],
        }
    ],
}
TRY = {"pattern": "p", "episodes": 5, "learners": 2, "max_steps": 50}
REQUESTS = [
    (method, url, body)
    for body in (FOUR_ROOMS, PINBALL, PICK_AND_PLACE)
    for method, url in (("post", "/api/validate"), ("put", "/api/files/h.yaml?overwrite=1"))
] + [("post", "/api/try", {**FOUR_ROOMS, **TRY}), ("post", "/api/try", {**PINBALL, **TRY})]
#: a value of each JSON type (a place that expects one type gets every other one)
KINDS = {
    "null": st.none(),
    "boolean": st.booleans(),
    "integer": st.integers(),
    "number": st.floats(allow_nan=False, allow_infinity=False),
    "string": st.text(max_size=8),
    "list": st.lists(LEAVES, max_size=3),
    "object": st.dictionaries(st.sampled_from(KEYS[:-2]) | st.text(max_size=4), LEAVES, max_size=3),
}
MISSING = object()


def places(value: Any, path: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Every place in a JSON value: the keys and indices that lead to each member, at every depth."""
    inner = value.items() if isinstance(value, dict) else enumerate(value) if isinstance(value, list) else []
    return [found for key, member in inner for found in [(*path, key), *places(member, (*path, key))]]


def put_at(value: Any, path: tuple[Any, ...], new: Any) -> Any:
    """A copy of ``value`` with ``new`` at ``path`` (:data:`MISSING`: the member removed)."""
    copy = json.loads(json.dumps(value))
    *parents, last = path
    holder = copy
    for key in parents:
        holder = holder[key]
    if new is MISSING:
        del holder[last]
    else:
        holder[last] = new
    return copy


@pytest.mark.parametrize("kind", [*KINDS, "missing"])
@settings(PROPERTY, max_examples=4)
@given(data=st.data())
def test_every_field_of_every_route_with_a_wrong_type_gets_a_4xx_or_an_answer(kind: str, data: st.DataObject) -> None:
    """Every place of every route's request gets a value of ``kind`` (or loses its member): a list or an
    object where a name is expected (``"pattern": ["p"]`` was a 500), a number where a list is. Each
    route answers with a 2xx or a 4xx saying what is wrong, and a refused save writes nothing."""
    new = MISSING if kind == "missing" else data.draw(KINDS[kind], label="value")
    with studio() as (client, folder):
        for method, url, valid in REQUESTS:
            for path in places(valid):
                body = json.dumps(put_at(valid, path, new))
                before = sorted(p.name for p in folder.iterdir())
                response = getattr(client, method)(url, data=body, content_type="application/json")
                check_answer(response)
                if response.status_code >= 400 and method == "put":
                    assert sorted(p.name for p in folder.iterdir()) == before, (url, path)
