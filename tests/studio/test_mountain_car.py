"""The studio's MountainCar form: boxes over position and velocity, saved as the learners read them."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

from flask.testing import FlaskClient

from torchrl_subgoal import load_patterns
from torchrl_subgoal.envs import mountain_car
from torchrl_subgoal.subgoals import Box


def box(components: list[str], centre: list[float], margin: Any) -> dict[str, Any]:
    return {"box": {"components": components, "centre": centre, "margin": margin}}


def drawing(*subgoals: dict[str, Any]) -> dict[str, Any]:
    return {"domain": "mountain_car", "patterns": [{"name": "p", "subgoals": list(subgoals), "order": None}]}


def test_geometry_is_a_form_of_position_and_velocity(client: FlaskClient) -> None:
    listed = {d["name"]: d for d in client.get("/api/domains").json}["mountain_car"]
    assert listed["limits"] == {} and "--domain mountain_car --subgoals FILE" in listed["try_note"]
    geometry = client.get("/api/geometry?domain=mountain_car").json
    assert geometry["kind"] == "form" and geometry["observation_size"] == 2 and geometry["ticked"] == ["position"]
    assert geometry["components"] == [
        {"name": "position", "start": 0, "size": 1, "range": [-1.2, 0.6]},
        {"name": "velocity", "start": 1, "size": 1, "range": [-0.07, 0.07]},
    ]


def test_the_shipped_file_opens_and_saves_back(client: FlaskClient, tmp_path: Path) -> None:
    folder = tmp_path / "files"
    shutil.copy(mountain_car.SUBGOAL_FILE, folder / "car.yaml")  # names no domain: inferred
    opened = client.get("/api/files/car.yaml").json
    assert opened["domain"] == "mountain_car", opened
    assert "torchrl-subgoal train --algo dqn --domain mountain_car --subgoals" in opened["recipe"]
    assert [s["box"] for s in opened["patterns"][0]["subgoals"]] == [
        {"components": ["position"], "centre": [-1.025], "margin": 0.175},
        {"components": ["position", "velocity"], "centre": [0.15, 0.0525], "margin": [0.45, 0.0175]},
    ]
    request = {"domain": "mountain_car", "description": opened["description"], "patterns": opened["patterns"]}
    assert client.put("/api/files/again", json=request).status_code == 200
    assert load_patterns(folder / "again.yaml", domain="mountain_car") == load_patterns(mountain_car.SUBGOAL_FILE)


def test_a_drawn_box_saves_as_dims(client: FlaskClient, tmp_path: Path) -> None:
    response = client.put("/api/files/mine", json=drawing(box(["velocity"], [0.04], 0.02)))
    assert response.status_code == 200, response.json
    series = load_patterns(tmp_path / "files" / "mine.yaml", domain="mountain_car")["p"]
    assert series.predicates == (Box((0.04,), (0.02,), (1,)),)


def test_a_box_outside_the_state_space_is_refused(client: FlaskClient) -> None:
    response = client.post("/api/validate", json=drawing(box(["position"], [2.0], 0.1)))
    assert response.status_code == 400
    assert "subgoals[0].box: position: the box [1.9, 2.1] lies outside [-1.2, 0.6]" in response.json["error"]
    response = client.post("/api/validate", json=drawing(box(["acceleration"], [0.0], 0.1)))
    assert response.status_code == 400
    assert "box.components: unknown observation component(s) ['acceleration']" in response.json["error"]
