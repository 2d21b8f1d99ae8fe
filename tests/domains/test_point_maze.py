"""The PointMaze domain plugins: registration, subgoal check, one route per pattern, the report map."""

from __future__ import annotations

from pathlib import Path

import pytest

from torchrl_subgoal import Box, Circle, domains, load_patterns
from torchrl_subgoal.domains import point_maze as plugin
from torchrl_subgoal.envs.point_maze import ROUTES, point_maze_task
from torchrl_subgoal.experiments.plots import ReportMap, plot_pattern_maps
from torchrl_subgoal.training import LearnerDomain


@pytest.mark.parametrize("maze", ["umaze", "medium"])
def test_both_mazes_register_a_learner_set_up_and_a_map(maze: str) -> None:
    name = f"point_maze_{maze}"
    domain = domains.get(name)
    learners = domain.part(LearnerDomain)
    assert learners is not None and domain.part(ReportMap) is not None
    assert set(learners.defaults) == {"ppo", "ddpg"}  # continuous actions: the learners that take them
    patterns = load_patterns(learners.participants, domain=name)  # the shipped file passes the map check
    assert sorted(patterns) == sorted(route.name for route in ROUTES[maze])


@pytest.mark.parametrize("maze", ["umaze", "medium"])
def test_a_learner_runs_the_route_its_pattern_names(maze: str) -> None:
    learners = domains.part(f"point_maze_{maze}", LearnerDomain)
    for route in ROUTES[maze]:
        for seed in (0, 1, 7, 2**62 + 3):
            task = point_maze_task(maze, plugin._route_seed(maze, route.name, seed))
            assert task.route.name == route.name
    assert learners.env_for("top_to_bottom" if maze == "umaze" else "bottom_right_to_top_left", 5) is not None
    with pytest.raises(ValueError, match=r"^pattern 'alice' names no route of the"):
        learners.env_for("alice", 0)


def test_the_seed_draws_different_points_for_one_route() -> None:
    first = plugin.route_env("umaze", "bottom_to_top", 0)(1).reset()["observation"][0, :2]
    other = plugin.route_env("umaze", "bottom_to_top", 2)(1).reset()["observation"][0, :2]
    again = plugin.route_env("umaze", "bottom_to_top", 0)(1).reset()["observation"][0, :2]
    assert bool((first == again).all()) and not bool((first == other).all())


@pytest.mark.parametrize(
    ("predicate", "message"),
    [
        (Circle((1.0, -1.0), 0.65), None),
        (
            Circle((0.0, 0.0), 0.65),
            "centre (0, 0) lies in a wall cell (2, 2) of the umaze maze; move it to where the ball can go",
        ),
        (Circle((3.0, 0.0), 0.5), "centre (3, 0) is outside the umaze maze"),
        (Circle((1.0, -1.0), 0.0), "radius must be positive, got 0.0"),
        (Circle((1.0, -1.0, 0.0), 0.5), "a PointMaze subgoal circle covers (x, y), dims [0, 1], not [0, 1, 2]"),
        (Box((1.0,), (0.5,), (0,)), "PointMaze subgoals are circles over the ball's (x, y), not box"),
    ],
)
def test_subgoal_check(predicate: object, message: str | None) -> None:
    assert domains.get("point_maze_umaze").check_subgoal(predicate) == message  # type: ignore[misc,arg-type]


def test_a_subgoal_file_with_a_circle_in_a_wall_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "walls.yaml"
    path.write_text(
        "domain: point_maze_umaze\npatterns:\n  p:\n    subgoals:\n"
        "      - {circle: {centre: [0.0, 0.0], radius: 0.5}}\n"
    )
    with pytest.raises(ValueError, match=r"wall cell \(2, 2\)"):
        load_patterns(path)


def test_the_report_map_draws_the_shipped_waypoints(tmp_path: Path) -> None:
    learners = domains.part("point_maze_medium", LearnerDomain)
    patterns = {n: s.to_dict() for n, s in load_patterns(learners.participants).items()}
    figure = plot_pattern_maps("point_maze_medium", patterns, tmp_path / "maps.png")
    assert figure.path is not None and figure.path.stat().st_size > 5_000, figure.note
