"""Regression guards for the shaping conventions (docs/shaping_defaults.md).

Four-rooms, the paper's SARSA (released preset, Q over the cell only), 20
learners (two per participant's series), 600 episodes, fused engine, fixed
seeds: each run takes a second or two. Measured values at the time of
writing are in the comments; the last test checks that the guards tell the
conventions apart (the old library default fails the asymptote guard, the
start-anchored potential fails the step-cost guard).
"""

from __future__ import annotations

from importlib.resources import files
from typing import Any

import pytest
import torch
from torchrl.envs import TransformedEnv

from torchrl_subgoal import load_patterns
from torchrl_subgoal.envs import FourRoomsEnv
from torchrl_subgoal.envs.four_rooms import room_aggregation
from torchrl_subgoal.fused import SARSA_PRESETS, SoftmaxSarsa, run_episodes
from torchrl_subgoal.methods import paper_methods, shaping_transform

PATTERNS = list(
    load_patterns(str(files("torchrl_subgoal") / "domains" / "four_rooms" / "four_rooms_participants.yaml")).values()
)
#: the conventions below are guarded under the paper's mean target and its potential (zero at the start, learned
#: freely), as docs/shaping_defaults.md measures them
PAPER_TARGET: dict[str, Any] = {
    "expectile": 0.5,
    "bootstrap_truncated": True,
    "progress_scale": 0.0,
    "monotone_potential": False,
}
AUTHORS: dict[str, Any] = {"zero_terminal_potential": False, "start_potential": "value", **PAPER_TARGET}  # the recipes'
LIBRARY: dict[str, Any] = {}  # the library's defaults: its conventions and its target
LIBRARY_CONVENTIONS: dict[str, Any] = dict(PAPER_TARGET)
OLD_LIBRARY: dict[str, Any] = {"zero_terminal_potential": True, "start_potential": "value", **PAPER_TARGET}
START_ANCHORED: dict[str, Any] = {"zero_terminal_potential": True, "start_potential": "zero", **PAPER_TARGET}
N, EPISODES = 20, 600


def learn(method: str, reward: str, conventions: dict[str, Any]) -> torch.Tensor:
    """Steps per episode ``[N, EPISODES]`` of ``method`` with goal reward (+1) or step cost (−1 per step)."""
    cfg = SARSA_PRESETS["released"]
    goal_reward, step_reward = (1.0, 0.0) if reward == "goal" else (0.0, -1.0)
    env = FourRoomsEnv(N, goal_reward=goal_reward, step_reward=step_reward)
    shaping = shaping_transform(
        paper_methods("SARSA")[method],
        env.batch_size,
        gamma=cfg.gamma,
        value_lr=cfg.value_lr,
        patterns=PATTERNS,
        pattern_index=torch.arange(N) % len(PATTERNS),
        aggregation=room_aggregation(),
        observation_key="cell",
        **conventions,
    )
    learning_env = TransformedEnv(env, shaping) if shaping is not None else env
    agent = SoftmaxSarsa(N, env.num_states, 4, cfg, seed=0)
    return run_episodes(learning_env, agent, EPISODES, engine="fused").steps.double()


def time_to_50(steps: torch.Tensor) -> float:
    """Mean first episode (1-based) with fewer than 50 steps."""
    below = steps < 50
    return float(torch.where(below.any(1), below.float().argmax(1) + 1, EPISODES).double().mean())


def asymptote(steps: torch.Tensor) -> float:
    """Mean steps over the last 10 episodes."""
    return float(steps[:, -10:].mean())


@pytest.mark.parametrize("conventions", [LIBRARY_CONVENTIONS, AUTHORS], ids=["library", "authors"])
def test_goal_reward_hrs_reaches_the_optimum_and_beats_sarsa(conventions: dict[str, Any]) -> None:
    hrs = learn("HRS", "goal", conventions)
    assert asymptote(hrs) <= 20 + 1  # 20.10 (library), 20.20 (authors); 25.8 with Φ_T = 0 and Φ = V
    assert time_to_50(hrs) < time_to_50(learn("SARSA", "goal", {}))  # 37.8, 36.2 vs 42.9


def test_goal_reward_hrs_with_the_library_defaults_reaches_the_optimum_no_later_than_sarsa() -> None:
    """The 0.9-expectile target under the goal reward: the optimum, and no slower than SARSA (20 learners
    leave the two within noise: 43.1 vs 42.9; at 200 learners 42.9 vs 52.7, docs/shaping_defaults.md)."""
    hrs = learn("HRS", "goal", LIBRARY)
    assert asymptote(hrs) <= 20 + 1
    assert time_to_50(hrs) <= 1.1 * time_to_50(learn("SARSA", "goal", {}))


def test_step_cost_hrs_reaches_50_steps_no_later_than_sarsa() -> None:
    hrs = learn("HRS", "step-cost", LIBRARY)  # the library's defaults
    assert time_to_50(hrs) <= time_to_50(learn("SARSA", "step-cost", {}))  # 22.6 vs 46.0
    assert asymptote(hrs) <= 20 + 1  # 20.00; 21.7 with the authors' convention


def test_the_guards_tell_the_conventions_apart() -> None:
    assert asymptote(learn("HRS", "goal", OLD_LIBRARY)) > 20 + 1  # 25.8: Q ≈ Q* − V(z) leaves no action gap
    assert asymptote(learn("HRS", "step-cost", AUTHORS)) > 20 + 1  # 21.7: γ^T V(z_T) < 0 pays for long episodes
    sarsa = time_to_50(learn("SARSA", "step-cost", {}))
    assert (
        time_to_50(learn("HRS", "step-cost", START_ANCHORED)) > sarsa
    )  # 92.8 vs 46.0: the goal pays V(z_T) − V(0) back
