"""The studio's pick-and-place form: box subgoals over named observation components, saved as the recipe reads them."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import pytest
from flask.testing import FlaskClient

from torchrl_subgoal import load_patterns
from torchrl_subgoal.envs import fetch
from torchrl_subgoal.subgoals import Box


def box(components: list[str], centre: list[float], margin: Any = 0.01, **extra: Any) -> dict[str, Any]:
    return {"box": {"components": components, "centre": centre, "margin": margin, **extra}}


def drawing(*patterns: tuple[str, list[dict[str, Any]]]) -> dict[str, Any]:
    return {"domain": "pick_and_place", "patterns": [{"name": n, "subgoals": s, "order": None} for n, s in patterns]}


AT_OBJECT = box(["object_relative_position"], [0.0, 0.0, 0.0])
GRASPED = box(["object_relative_position", "finger_joints"], [0.0, 0.0, 0.0, 0.02, 0.02])


def test_geometry_is_a_form_over_the_components(client: FlaskClient) -> None:
    domains = {d["name"]: d for d in client.get("/api/domains").get_json()}
    assert domains["pick_and_place"]["limits"] == {}
    assert "too slow" in domains["pick_and_place"]["try_note"]
    geometry = client.get("/api/geometry?domain=pick_and_place").get_json()
    assert geometry["kind"] == "form"
    assert geometry["default_margin"] == fetch.SUBGOAL_MARGIN
    assert [(c["name"], c["start"], c["size"]) for c in geometry["components"]] == [
        (n, s.start, s.stop - s.start) for n, s in fetch.COMPONENTS.items()
    ]


def test_save_writes_what_the_recipe_loads_and_opens_back(client: FlaskClient, tmp_path: Path) -> None:
    request = drawing(
        ("participants", [AT_OBJECT, GRASPED]),
        ("lift", [box(["object_position"], [1.3, 0.7, 0.6], margin=[0.02, 0.02, 0.05])]),
    )
    response = client.put("/api/files/mine", json=request)
    assert response.status_code == 200, response.get_json()
    assert response.get_json()["recipe"].startswith("torchrl-subgoal reproduce pick-and-place --subgoals ")
    saved = tmp_path / "files" / "mine.yaml"
    patterns = fetch.human_patterns(str(saved))  # the recipe's loader
    assert list(patterns) == ["participants", "lift"]
    first, second = patterns["participants"].predicates
    assert first == Box((0.0, 0.0, 0.0), (0.01,) * 3, (6, 7, 8))
    assert second == Box((0.0, 0.0, 0.0, 0.02, 0.02), (0.01,) * 5, (6, 7, 8, 9, 10))
    assert patterns["lift"].predicates[0] == Box((1.3, 0.7, 0.6), (0.02, 0.02, 0.05), (3, 4, 5))
    opened = client.get("/api/files/mine.yaml").get_json()
    assert opened["domain"] == "pick_and_place"
    assert [p["name"] for p in opened["patterns"]] == ["participants", "lift"]
    assert opened["patterns"][0]["subgoals"][1] == {"name": None, **GRASPED}
    assert opened["patterns"][1]["subgoals"][0]["box"]["margin"] == [0.02, 0.02, 0.05]


def test_the_participants_file_opens_and_saves_back_equivalently(client: FlaskClient, tmp_path: Path) -> None:
    folder = tmp_path / "files"
    shutil.copy(fetch.PARTICIPANTS_FILE, folder / "participants.yaml")
    opened = client.get("/api/files/participants.yaml").get_json()
    assert opened["domain"] == "pick_and_place"
    assert opened["patterns"][0]["subgoals"] == [{"name": None, **AT_OBJECT}, {"name": None, **GRASPED}]
    request = {"domain": "pick_and_place", "patterns": opened["patterns"]}
    assert client.put("/api/files/again", json=request).status_code == 200
    assert load_patterns(folder / "again.yaml") == load_patterns(fetch.PARTICIPANTS_FILE)


def test_a_file_of_partial_components_is_refused_with_where(client: FlaskClient, tmp_path: Path) -> None:
    (tmp_path / "files" / "part.yaml").write_text(
        "patterns:\n  p:\n    subgoals:\n      - {box: {centre: [0.0, 0.0], margin: 0.01, dims: [6, 7]}}\n"
    )
    response = client.get("/api/files/part.yaml")
    assert response.status_code == 422
    assert (
        "part.yaml: pattern 'p': subgoals[0]: box entries [6, 7] are not whole observation components"
        in (response.get_json()["error"])
    )


@pytest.mark.parametrize(
    ("subgoal", "message"),
    [
        (
            box(["object_relativ_position"], [0.0, 0.0, 0.0]),
            "patterns[0].subgoals[0].box.components: unknown observation component(s) ['object_relativ_position']",
        ),
        (
            box(["finger_joints"], [0.02, 0.02, 0.02]),
            "patterns[0].subgoals[0].box.centre: 3 values, but finger_joints has 2 coordinates",
        ),
        (
            box(["finger_joints"], [0.02, 0.02], margin=-0.01),
            "pattern 'p': subgoals[0].box.margin: must be non-negative",
        ),
        (
            box(["finger_joints"], [0.02, 0.02], margin=[0.01, 0.01, 0.01]),
            "pattern 'p': subgoals[0].box.margin: has 3 entries but the centre has 2",
        ),
        (box(["finger_joints"], [0.02, None]), "pattern 'p': subgoals[0].box.centre"),
        (box([], []), "patterns[0].subgoals[0].box.components: expected a non-empty list"),
        (box(["finger_joints"], [0.0, 0.0], dims=[9, 10]), "give 'components' or 'dims'/'slice', not both"),
        (
            {"circle": {"centre": [0.5, 0.5], "radius": 0.1}},
            "pattern 'p': subgoals[0].circle: pick-and-place subgoals are boxes",
        ),
        ({"box": {"centre": [0.0], "margin": 0.01, "dims": [40]}}, "box entries [40] lie outside the 25-d observation"),
    ],
)
def test_bad_boxes_are_4xx_with_their_message(client: FlaskClient, subgoal: dict[str, Any], message: str) -> None:
    for method, url in (("post", "/api/validate"), ("put", "/api/files/bad")):
        response = getattr(client, method)(url, json=drawing(("p", [subgoal])))
        assert response.status_code == 400, response.get_json()
        assert message in response.get_json()["error"]


def test_try_it_is_refused_with_the_reason(client: FlaskClient) -> None:
    response = client.post("/api/try", json=drawing(("p", [AT_OBJECT])))
    assert response.status_code == 400
    assert response.get_json()["error"].startswith("Try it: Not offered for pick-and-place")


def test_descriptions_survive_open_and_save(client: FlaskClient, tmp_path: Path) -> None:
    folder = tmp_path / "files"
    (folder / "described.yaml").write_text(
        "description: two tries\npatterns:\n  p:\n    description: the participants' boxes\n    subgoals:\n"
        "      - {box: {centre: [0.0, 0.0, 0.0], margin: 0.01, slice: [6, 9]}}\n"
    )
    opened = client.get("/api/files/described.yaml").get_json()
    assert opened["description"] == "two tries"
    assert opened["patterns"][0]["description"] == "the participants' boxes"
    request = {"domain": opened["domain"], "description": opened["description"], "patterns": opened["patterns"]}
    assert client.put("/api/files/described.yaml?overwrite=1", json=request).status_code == 200  # as the page re-saves
    again = client.get("/api/files/described.yaml").get_json()
    assert (again["description"], again["patterns"][0]["description"]) == ("two tries", "the participants' boxes")
