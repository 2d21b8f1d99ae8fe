"""MountainCar-v0: the batched env, and the two subgoals on hand-made observations and the dynamics."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from tensordict.nn import TensorDictModule

from torchrl_subgoal.envs.gym_batch import require_gymnasium
from torchrl_subgoal.envs.mountain_car import (
    ENV_ID,
    MAX_EPISODE_STEPS,
    make_mountain_car,
    mountain_car_subgoals,
)

from .trajectory import subgoal_path


def test_env_steps_with_a_step_cost_and_truncates_at_200() -> None:
    env = make_mountain_car(3)
    env.set_seed(0)
    td = env.reset()
    assert td["observation"].shape == (3, 2) and bool((td["observation"][:, 1] == 0).all())
    assert bool(((td["observation"][:, 0] >= -0.6) & (td["observation"][:, 0] <= -0.4)).all())
    no_push = TensorDictModule(
        lambda obs: torch.ones(obs.shape[:-1], dtype=torch.long), in_keys=["observation"], out_keys=["action"]
    )  # never gets there
    rollout = env.rollout(250, no_push, break_when_any_done=False)
    assert bool((rollout["next", "reward"] == -1).all())
    done = rollout["next", "done"].squeeze(-1)
    assert done[:, MAX_EPISODE_STEPS - 1].all() and done.sum() == 3
    assert not rollout["next", "terminated"].any() and env.max_steps == 200


def _z(points: list[tuple[float, float]]) -> list[int]:
    """z along hand-made (position, velocity) observations."""
    return subgoal_path(mountain_car_subgoals(), torch.tensor(points))


def test_subgoals_on_hand_made_observations() -> None:
    start = (-0.5, 0.0)
    assert _z([start, (-0.9, 0.0), (-0.2, 0.04)]) == [1, 2]  # swung up the left hill, then fast past the valley
    assert _z([start, (-0.84, -0.01), (-1.19, 0.0)]) == [0, 1]  # -0.84 is not high enough
    assert _z([start, (-0.2, 0.04), (-0.9, 0.0)]) == [0, 1]  # fast past the valley first: nothing
    assert _z([start, (-0.9, 0.0), (-0.2, 0.03), (-0.35, 0.05), (0.1, 0.036)]) == [1, 1, 1, 2]  # too slow, too early
    assert _z([start, (-0.9, 0.0), (0.4, -0.04)]) == [1, 1]  # speed towards the flag only


def _pushing_right_from_rest(position: float) -> bool:
    """Whether pushing right from rest at ``position`` reaches the flag in one run (gymnasium's dynamics)."""
    env = require_gymnasium("MountainCar").make(ENV_ID).unwrapped
    env.reset(seed=0)
    env.state = np.array([position, 0.0])
    for _ in range(MAX_EPISODE_STEPS):
        (_, velocity), _, terminated, _, _ = env.step(2)
        if terminated:
            return True
        if velocity < 0:  # rolled back: the run failed
            return False
    return False


def test_the_left_hill_threshold_is_the_height_one_run_needs() -> None:
    """The first subgoal's threshold, -0.85: from rest there, pushing right reaches the flag; from -0.8,
    it does not."""
    assert _pushing_right_from_rest(-0.85) and _pushing_right_from_rest(-1.0)
    assert not _pushing_right_from_rest(-0.8)


def test_bad_input() -> None:
    with pytest.raises(ValueError, match="num_envs must be >= 1"):
        make_mountain_car(0)
