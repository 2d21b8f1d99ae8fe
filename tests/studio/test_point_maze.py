"""The studio's PointMaze tables: the maze's plane (y up), its walls, the routes' ends, the loader's wall check."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import pytest
from flask.testing import FlaskClient

from torchrl_subgoal import load_patterns
from torchrl_subgoal.envs import point_maze
from torchrl_subgoal.subgoals import Circle


def drawing(maze: str, *patterns: tuple[str, list[tuple[float, float, float]]]) -> dict[str, Any]:
    return {
        "domain": f"point_maze_{maze}",
        "patterns": [
            {"name": name, "subgoals": [{"circle": {"centre": [x, y], "radius": r}} for x, y, r in circles]}
            for name, circles in patterns
        ],
    }


def test_both_mazes_are_listed_without_try_it(client: FlaskClient) -> None:
    domains = {d["name"]: d for d in client.get("/api/domains").json}
    for maze in ("umaze", "medium"):
        listed = domains[f"point_maze_{maze}"]
        assert listed["title"] == f"PointMaze {maze.capitalize()}" and listed["maps"] == [] and listed["limits"] == {}
        assert f"torchrl-subgoal train --algo ppo --domain point_maze_{maze} --subgoals FILE" in listed["try_note"]
        assert listed["pattern_names"] == [route.name for route in point_maze.ROUTES[maze]]


def test_umaze_geometry_is_the_maze_in_its_own_coordinates(client: FlaskClient) -> None:
    geometry = client.get("/api/geometry?domain=point_maze_umaze").json
    assert geometry["kind"] == "table" and geometry["y_up"] is True
    assert geometry["bounds"] == [-2.5, -2.5, 2.5, 2.5]
    walls = [cell for row in point_maze.MAZES["umaze"] for cell in row if cell == 1]
    assert len(geometry["polygons"]) == len(walls) == 18
    assert [[-0.5, 0.5], [0.5, 0.5], [0.5, -0.5], [-0.5, -0.5]] in geometry["polygons"]  # wall cell (2, 2)
    assert geometry["start"] == [-1.0, -1.0] and geometry["target"] == [-1.0, 1.0, point_maze.GOAL_RADIUS]
    assert geometry["routes"]["top_to_bottom"] == {"start": [-1.0, 1.0], "target": [-1.0, -1.0, 0.45]}
    assert geometry["ball_radius"] == 0.1 and geometry["default_radius"] == point_maze.WAYPOINT_RADIUS


@pytest.mark.parametrize("maze", ["umaze", "medium"])
def test_the_shipped_file_opens_validates_and_saves_back(client: FlaskClient, tmp_path: Path, maze: str) -> None:
    folder = tmp_path / "files"
    shutil.copy(point_maze.SUBGOAL_FILES[maze], folder / "waypoints.yaml")  # names no domain: inferred
    opened = client.get("/api/files/waypoints.yaml").json
    assert opened["domain"] == f"point_maze_{maze}", opened
    assert f"torchrl-subgoal train --algo ppo --domain point_maze_{maze} --subgoals" in opened["recipe"]
    request = {"domain": opened["domain"], "description": opened["description"], "patterns": opened["patterns"]}
    assert client.post("/api/validate", json=request).status_code == 200
    saved = client.put("/api/files/again", json=request)
    assert saved.status_code == 200, saved.json
    assert load_patterns(folder / "again.yaml", domain=f"point_maze_{maze}") == point_maze.waypoint_patterns(maze)
    assert client.get("/api/files/again.yaml").json["patterns"] == opened["patterns"]


def test_a_drawn_series_round_trips(client: FlaskClient, tmp_path: Path) -> None:
    request = drawing("umaze", ("bottom_to_top", [(0.9, -1.1, 0.5), (1.2, 0.8, 0.65)]))
    saved = client.put("/api/files/mine", json=request)
    assert saved.status_code == 200, saved.json
    series = load_patterns(tmp_path / "files" / "mine.yaml", domain="point_maze_umaze")["bottom_to_top"]
    assert series.predicates == (Circle((0.9, -1.1), 0.5), Circle((1.2, 0.8), 0.65))
    opened = client.get("/api/files/mine.yaml").json
    assert opened["domain"] == "point_maze_umaze"  # the file names it
    assert [s["circle"] for s in opened["patterns"][0]["subgoals"]] == [
        {"centre": [0.9, -1.1], "radius": 0.5},
        {"centre": [1.2, 0.8], "radius": 0.65},
    ]


def test_a_medium_file_whose_circles_also_fit_the_umaze_opens_as_medium(client: FlaskClient) -> None:
    request = drawing("medium", ("top_left_to_bottom_right", [(0.5, 0.5, 0.65)]))
    assert client.put("/api/files/medium", json=request).status_code == 200
    assert client.get("/api/files/medium.yaml").json["domain"] == "point_maze_medium"


@pytest.mark.parametrize(
    ("circle", "message"),
    [
        (
            (0.0, 0.0, 0.5),
            "pattern 'bottom_to_top': subgoals[0].circle: centre (0, 0) lies in a wall cell (2, 2) of the umaze maze",
        ),
        ((-2.0, 2.0, 0.5), "centre (-2, 2) lies in a wall cell (0, 0) of the umaze maze"),
        ((3.0, 0.0, 0.5), "subgoals[0].circle: centre (3, 0) is outside the umaze maze"),
        ((1.0, -1.0, 0.0), "subgoals[0].circle.radius: must be positive, got 0.0"),
    ],
)
def test_a_circle_in_a_wall_or_outside_is_refused(
    client: FlaskClient, circle: tuple[float, float, float], message: str
) -> None:
    for method, url in (("post", "/api/validate"), ("put", "/api/files/bad")):
        response = getattr(client, method)(url, json=drawing("umaze", ("bottom_to_top", [circle])))
        assert response.status_code == 400, response.json
        assert message in response.json["error"]
    assert client.get("/api/files").json["files"] == []


def test_a_pattern_not_named_after_a_route_is_refused(client: FlaskClient) -> None:
    response = client.post("/api/validate", json=drawing("umaze", ("pattern_1", [(1.0, -1.0, 0.65)])))
    assert response.status_code == 400
    assert response.json["error"] == (
        "drawing.yaml: pattern 'pattern_1': PointMaze Umaze runs each pattern on the task it is named after; "
        "name it one of bottom_to_top, top_to_bottom"
    )


def test_try_it_is_refused_with_the_reason(client: FlaskClient) -> None:
    response = client.post("/api/try", json=drawing("umaze", ("bottom_to_top", [(1.0, -1.0, 0.65)])))
    assert response.status_code == 400
    assert response.json["error"].startswith("Try it: Not offered for PointMaze")
