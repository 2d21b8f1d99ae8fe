"""tools/four_rooms_optimal_potential.py: the optimal values it freezes, and a tiny run end to end."""

from __future__ import annotations

import subprocess
import sys

import pytest

from tests.tools import TOOLS, load_tool
from torchrl_subgoal import SubgoalSeries
from torchrl_subgoal.subgoals import Cell

TOOL = TOOLS / "four_rooms_optimal_potential.py"


def test_optimal_values_under_either_reward() -> None:
    tool = load_tool("four_rooms_optimal_potential")
    series = SubgoalSeries([Cell(4, 9), Cell(11, 10)])  # the hallway, then next to the goal
    goal = tool.optimal_values(series, "goal", 0.99)
    step = tool.optimal_values(series, "step", 0.99)
    assert goal[0] == pytest.approx(0.99**19) and goal[2] == pytest.approx(1.0)  # one step from the goal: +1 next
    assert step[2] == pytest.approx(0.0) and step[0] == pytest.approx(-(1 - 0.99**19) / 0.01)
    assert goal == sorted(goal) and step == sorted(step)  # closer to the goal along the series, higher


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["a2c", "dqn"])
def test_a_tiny_run_prints_every_condition(algo: str) -> None:
    args = ["--algo", algo, "--task", "step", "--learners", "2", "--total-frames", "3072"]
    done = subprocess.run(
        [sys.executable, str(TOOL), *args, "--conditions", "unshaped,learned,optimal,monotone"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    for condition in (
        "| unshaped |",
        "| HRS, learned |",
        "| HRS, optimal |",
        "| HRS, monotone |",
        "unshaped / HRS, optimal",
    ):
        assert condition in done.stdout
