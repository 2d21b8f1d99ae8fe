"""Acrobot-v1: the batched env, the tip height against gymnasium's goal test, and the two subgoals."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from tensordict.nn import TensorDictModule

from torchrl_subgoal.envs.acrobot import ENV_ID, MAX_EPISODE_STEPS, acrobot_subgoals, make_acrobot, tip_height
from torchrl_subgoal.envs.gym_batch import require_gymnasium

from .trajectory import subgoal_path


def test_env_steps_with_a_step_cost_and_truncates_at_500() -> None:
    env = make_acrobot(2)
    env.set_seed(0)
    td = env.reset()
    assert td["observation"].shape == (2, 6) and bool((td["observation"][:, 0] > 0.99).all())  # hanging down
    no_torque = TensorDictModule(
        lambda obs: torch.ones(obs.shape[:-1], dtype=torch.long), in_keys=["observation"], out_keys=["action"]
    )  # swings a little, never up
    rollout = env.rollout(MAX_EPISODE_STEPS + 10, no_torque, break_when_any_done=False)
    assert bool((rollout["next", "reward"] == -1).all())
    done = rollout["next", "done"].squeeze(-1)
    assert done[:, MAX_EPISODE_STEPS - 1].all() and done.sum() == 2
    assert not rollout["next", "terminated"].any() and env.max_steps == 500


def test_tip_height_is_gymnasiums_goal_test() -> None:
    env = require_gymnasium("Acrobot").make(ENV_ID).unwrapped
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(200):
        env.state = np.concatenate([rng.uniform(-math.pi, math.pi, 2), np.zeros(2)])
        assert bool(tip_height(env._get_ob()) > 1.0) == bool(env._terminal())


def _z(angles: list[float]) -> list[int]:
    """z along hand-made observations with the first link at ``angles`` (degrees from hanging down), the
    second in line with it, at rest."""
    theta = torch.tensor(angles) * math.pi / 180
    zero = torch.zeros_like(theta)
    return subgoal_path(acrobot_subgoals(), torch.stack([theta.cos(), theta.sin(), zero + 1, zero, zero, zero], -1))


def test_subgoals_on_hand_made_observations() -> None:
    assert _z([0, 50, 65, 80, 95]) == [0, 1, 1, 2]  # 60 degrees out, then past the horizontal
    assert _z([0, -65, -95]) == [1, 2]  # either side
    assert _z([0, 55, 30, 0]) == [0, 0, 0]  # not far enough out


def test_each_subgoal_is_further_than_random_exploration_goes() -> None:
    """A uniformly random policy reaches the first subgoal more often than the second, the second more often
    than the goal (the module's description gives the rates)."""
    env = require_gymnasium("Acrobot").make(ENV_ID)
    rng = np.random.default_rng(0)
    reached = np.zeros(3, dtype=int)
    for episode in range(30):
        obs, _ = env.reset(seed=episode)
        lowest, goal = 1.0, False
        for _ in range(MAX_EPISODE_STEPS):
            obs, _, goal, _, _ = env.step(int(rng.integers(3)))
            lowest = min(lowest, float(obs[0]))
            if goal:
                break
        reached += [lowest <= 0.5, lowest <= 0.0, goal]
    assert reached[0] > reached[1] > reached[2], reached


def test_bad_input() -> None:
    with pytest.raises(ValueError, match="num_envs must be >= 1"):
        make_acrobot(0)
