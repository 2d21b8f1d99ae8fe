"""FourRoomsEnv: layout facts, dynamics, batching, partial resets, specs."""

from __future__ import annotations

import pytest
import torch
from torchrl.envs.utils import check_env_specs

from torchrl_subgoal import Cell, State
from torchrl_subgoal.domains.four_rooms import check_subgoal
from torchrl_subgoal.envs import FourRoomsEnv
from torchrl_subgoal.envs.four_rooms import (
    GOAL,
    HALLWAYS,
    START,
    free_cells,
    goal_distances,
    room_aggregation,
    state_of,
)

DOWN, RIGHT, UP, LEFT = range(4)


def test_layout_facts() -> None:
    cells = free_cells()
    assert len(cells) == 104
    assert state_of(START) == 0 and state_of(GOAL) == 103
    assert all(h in cells for h in HALLWAYS)
    assert FourRoomsEnv().shortest_path_length() == 20


def test_moves_and_walls() -> None:
    env = FourRoomsEnv()
    td = env.reset()
    for action, cell in [(UP, (1, 1)), (LEFT, (1, 1)), (RIGHT, (1, 2)), (DOWN, (2, 2))]:
        td["action"] = torch.tensor(action)
        td = env.step(td)["next"]
        assert tuple(td["cell"].tolist()) == cell
        assert int(td["observation"]) == state_of(cell)


def test_goal_reward_and_termination_along_a_shortest_path() -> None:
    env = FourRoomsEnv()
    td = env.reset()
    # (1,1) -> (3,5) -> hallway (3,6) -> (3,9) -> hallway (7,9) -> (11,9) -> (11,11)
    path = [DOWN] * 2 + [RIGHT] * 4 + [RIGHT] + [RIGHT] * 3 + [DOWN] * 8 + [RIGHT] * 2
    rewards = []
    for a in path:
        td["action"] = torch.tensor(a)
        out = env.step(td)["next"]
        rewards.append(float(out["reward"]))
        td = out
    assert len(path) == 20
    assert tuple(td["cell"].tolist()) == GOAL and bool(td["terminated"]) and bool(td["done"])
    assert rewards == [0.0] * 19 + [1.0]


def test_truncation_at_max_steps() -> None:
    env = FourRoomsEnv(2, max_steps=3)
    td = env.reset()
    for _ in range(3):
        td["action"] = torch.tensor([UP, UP])
        out = env.step(td)["next"]
        td = out
    assert out["truncated"].all() and out["done"].all() and not out["terminated"].any()


def test_partial_reset() -> None:
    env = FourRoomsEnv(3)
    td = env.reset()
    td["action"] = torch.tensor([RIGHT, RIGHT, DOWN])
    td = env.step(td)["next"]
    td["_reset"] = torch.tensor([[True], [False], [False]])
    out = env.reset(td)
    assert out["cell"].tolist() == [[1, 1], [1, 2], [2, 1]]
    out["action"] = torch.tensor([RIGHT, RIGHT, RIGHT])
    assert env.step(out)["next", "cell"].tolist() == [[1, 2], [1, 3], [2, 2]]


@pytest.mark.parametrize("num_envs", [None, 1, 7])
def test_specs(num_envs: int | None) -> None:
    check_env_specs(FourRoomsEnv(num_envs))


def test_room_aggregation_and_hallways() -> None:
    g = room_aggregation().mapping
    assert g[state_of((3, 6))] == 0 and g[state_of((6, 2))] == 0
    assert g[state_of((7, 9))] == 1 and g[state_of((10, 6))] == 2
    assert g[state_of((1, 1))] == 0 and g[state_of((1, 11))] == 1
    assert g[state_of((11, 1))] == 2 and g[state_of((11, 11))] == 3
    assert torch.bincount(g).tolist() == [25 + 2, 30 + 1, 25 + 1, 20]  # rooms + their hallways


def test_subgoal_checks() -> None:
    assert check_subgoal(Cell(3, 6)) is None
    assert "wall" in (check_subgoal(Cell(0, 0)) or "")
    assert "off" in (check_subgoal(Cell(-1, 3)) or "")
    assert check_subgoal(State(103)) is None and check_subgoal(State(104)) is not None


def test_bad_arguments() -> None:
    with pytest.raises(ValueError, match="num_envs"):
        FourRoomsEnv(0)
    with pytest.raises(ValueError, match="max_steps"):
        FourRoomsEnv(2, max_steps=0)


def test_goal_distances_follow_the_env_moves() -> None:
    """Every cell's distance is one more than its best move's (Bellman's equation over the env's own moves)."""
    env = FourRoomsEnv()
    distance = goal_distances()
    assert set(distance) == set(free_cells())
    cells = free_cells()
    for state, cell in enumerate(cells):
        if cell == GOAL:
            assert distance[cell] == 0
            continue
        best = min(distance[cells[s2]] for s2 in env.transitions[state].tolist())
        assert distance[cell] == best + 1, cell
