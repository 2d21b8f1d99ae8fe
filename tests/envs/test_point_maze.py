"""PointMaze: start and goal fixed per seed and different across seeds, the sparse terminating task, the
waypoint subgoals on hand-made observations and along a driven path."""

from __future__ import annotations

import math

import pytest
import torch
from torchrl.envs import TransformedEnv

pytest.importorskip("gymnasium_robotics")

from torchrl_subgoal import SubgoalPotentialTransform, TabularPotential
from torchrl_subgoal.envs import point_maze
from torchrl_subgoal.envs.point_maze import (
    MAX_EPISODE_STEPS,
    ROUTES,
    WAYPOINT_RADIUS,
    cell_centre,
    make_point_maze,
    point_maze_task,
    waypoint_patterns,
)

from .trajectory import subgoal_path


def _goal(env) -> torch.Tensor:  # type: ignore[no-untyped-def]
    """The goal point of the first env of a batch (gymnasium's ``goal``)."""
    return torch.tensor(env._env.envs[0].unwrapped.goal, dtype=torch.float32)


@pytest.mark.parametrize("maze", ["umaze", "medium"])
def test_start_and_goal_fixed_per_seed_different_across_seeds(maze: str) -> None:
    starts, goals = [], []
    for seed in range(4):
        env = make_point_maze(maze, num_envs=2, seed=seed)
        env.set_seed(1234 + seed)  # a caller's seed does not change the task
        first = env.reset()["observation"]
        goal = _goal(env)
        env.rollout(20, break_when_any_done=False)  # move, reset again: the same start and goal
        again = env.reset()["observation"]
        assert torch.equal(first, again) and torch.equal(first[0], first[1]) and torch.equal(_goal(env), goal)
        assert torch.equal(first[0, 2:], torch.zeros(2))  # at rest
        route = point_maze_task(maze, seed).route
        assert route is ROUTES[maze][seed % 2]
        for point, cell in ((first[0, :2], route.start), (goal, route.goal)):  # inside its cell
            assert (point - torch.tensor(cell_centre(maze, cell))).abs().max() <= 0.25
        starts.append(first[0, :2])
        goals.append(goal)
        env.close()
    for i in range(4):
        for j in range(i):
            assert not torch.equal(starts[i], starts[j]) and not torch.equal(goals[i], goals[j])


def test_maze_maps_mark_the_route_and_bad_input_is_named() -> None:
    task = point_maze_task("medium", seed=1)
    rows = task.maze_map()
    assert rows[6][6] == "r" and rows[1][1] == "g" and sum(row.count("r") + row.count("g") for row in rows) == 2
    with pytest.raises(ValueError, match="unknown maze 'large'"):
        make_point_maze("large", 1, 0)
    with pytest.raises(ValueError, match="num_envs must be >= 1"):
        make_point_maze("umaze", 0, 0)
    with pytest.raises(ValueError, match=r"cell \(0, 0\) is not a free cell"):
        cell_centre("umaze", (0, 0))


def _through(maze: str, points: list[tuple[float, float]]) -> list[int]:
    """z along a hand-made trajectory of positions."""
    series = waypoint_patterns(maze)[ROUTES[maze][0].name]
    return subgoal_path(series, torch.tensor([[x, y, 0.0, 0.0] for x, y in points]))


@pytest.mark.parametrize("maze", ["umaze", "medium"])
def test_waypoints_on_hand_made_observations(maze: str) -> None:
    route = ROUTES[maze][0]
    corners = [cell_centre(maze, c) for c in route.corners]
    start = cell_centre(maze, route.start)
    n = len(corners)
    assert _through(maze, [start, *corners]) == list(range(1, n + 1))  # in order: one step each
    assert _through(maze, [start, corners[-1], corners[0]])[0] == 0  # the last corner first: nothing
    # the circle's edge: the ball passing 0.64 from the first corner's centre achieves it, 0.66 does not
    x, y = corners[0]
    inside = (x + (WAYPOINT_RADIUS - 0.01) / math.sqrt(2), y + (WAYPOINT_RADIUS - 0.01) / math.sqrt(2))
    outside = (x + (WAYPOINT_RADIUS + 0.01) / math.sqrt(2), y + (WAYPOINT_RADIUS + 0.01) / math.sqrt(2))
    assert _through(maze, [start, inside]) == [1] and _through(maze, [start, outside]) == [0]
    patterns = waypoint_patterns(maze)
    assert set(patterns) == {r.name for r in ROUTES[maze]}
    back = ROUTES[maze][1]
    assert [p.centre for p in patterns[back.name].predicates] == [cell_centre(maze, c) for c in back.corners]


@pytest.mark.parametrize("maze, seed", [("umaze", 0), ("medium", 1)])
def test_a_driven_ball_passes_the_waypoints_in_order_and_ends_at_the_goal_with_reward_one(maze: str, seed: int) -> None:
    """A proportional controller steered through the route's corners: the transform advances z at each
    waypoint, in order; the episode terminates at the goal with reward 1 (0 before), within the time limit."""
    task = point_maze_task(maze, seed)
    series = task.pattern()
    env = TransformedEnv(
        make_point_maze(maze, 1, seed),
        SubgoalPotentialTransform(series, TabularPotential(series.num_abstract_states), gamma=0.99),
    )
    targets = [torch.tensor(cell_centre(maze, c)) for c in (*task.route.corners, task.route.goal)]
    td, k, zs, rewards = env.reset(), 0, [], []
    for _ in range(MAX_EPISODE_STEPS[maze]):
        position, velocity = td["observation"][0, :2], td["observation"][0, 2:]
        if k < len(targets) - 1 and (position - targets[k]).norm() < 0.3:
            k += 1
        td["action"] = (3.0 * (targets[k] - position) - velocity).clamp(-1.0, 1.0)[None]
        td = env.step(td)
        zs.append(int(td["next", "subgoal_index"]))
        rewards.append(float(td["next", "env_reward"]))
        if bool(td["next", "done"]):
            break
        td = td["next"]
    assert bool(td["next", "terminated"]) and not bool(td["next", "truncated"])
    assert rewards[-1] == 1.0 and set(rewards[:-1]) == {0.0}
    assert sorted(set(zs)) == list(range(len(series) + 1)) and zs == sorted(zs)  # each waypoint, in order
    env.close()


def test_module_names_its_extra() -> None:
    assert "fetch" in point_maze.__doc__  # type: ignore[operator]
