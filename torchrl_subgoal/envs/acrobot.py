"""Acrobot-v1 (gymnasium) as a batched TorchRL env, with subgoals for a step-cost study.

gymnasium's classic swing-up task: two links hang from a pivot, and only the
joint between them is driven (torque −1, 0 or +1). The observation is
``(cos θ₁, sin θ₁, cos θ₂, sin θ₂, θ̇₁, θ̇₂)``, with ``θ₁`` the first link's
angle from hanging straight down and ``θ₂`` the second link's angle relative to
the first. Reward −1 per step; the episode terminates when the free end rises a
link's length above the pivot (``−cos θ₁ − cos(θ₁ + θ₂) > 1``) and is truncated
after 500 steps. The agent must pump energy into the swing. The batch steps in
one process (:func:`~torchrl_subgoal.envs.gym_batch.gym_batch`); starts are
gymnasium's (every state variable uniform in ``[−0.1, 0.1]``), seeded by the
collector.

The shipped subgoal file (:data:`SUBGOAL_FILE`) holds one ordered series of two
boxes over ``cos θ₁`` (entry 0), the first link's swing:

1. **swung out to 60°**: ``cos θ₁ ≤ 0.5``, the joint a quarter of a link's length
   above its lowest point;
2. **swung out to the horizontal**: ``cos θ₁ ≤ 0``, the joint level with the pivot.
   From there the free end is above the line once the second link points up.

A uniformly random policy's 500-step episodes reach the first subgoal in about 60%,
the second in about 20% and the goal in about 3% of episodes (gymnasium 1.x,
100 episodes), so each subgoal is a step further than exploration alone takes the
learner.

Needs ``gymnasium``.
"""

from __future__ import annotations

from functools import partial
from importlib.resources import files
from typing import Any

from torchrl.envs import EnvBase

from torchrl_subgoal.envs.gym_batch import gym_batch, require_gymnasium
from torchrl_subgoal.subgoals import SubgoalSeries, load_pattern

__all__ = ["ENV_ID", "MAX_EPISODE_STEPS", "SUBGOAL_FILE", "acrobot_subgoals", "make_acrobot", "tip_height"]

ENV_ID = "Acrobot-v1"
#: gymnasium's time limit.
MAX_EPISODE_STEPS = 500
SUBGOAL_FILE = str(files("torchrl_subgoal") / "domains" / "acrobot" / "acrobot_subgoals.yaml")


def _make_single() -> Any:
    return require_gymnasium("Acrobot").make(ENV_ID)


def make_acrobot(num_envs: int) -> EnvBase:
    """``num_envs`` Acrobot-v1 envs stepped together in this process, one TorchRL env.

    Observation ``"observation"`` = ``(cos θ₁, sin θ₁, cos θ₂, sin θ₂, θ̇₁, θ̇₂)`` (float32), a categorical
    action of three (torque −1, 0, +1), reward −1 per step, termination when the free end is a link's
    length above the pivot, truncation after 500 steps (``max_steps``).

    Args:
        num_envs: envs in the batch.

    Examples:
        >>> env = make_acrobot(2)
        >>> _ = env.set_seed(0)
        >>> td = env.rollout(3)
        >>> td["next", "observation"].shape, td["next", "reward"].unique().tolist(), env.max_steps
        (torch.Size([2, 3, 6]), [-1.0], 500)
    """
    if num_envs < 1:
        raise ValueError(f"num_envs must be >= 1, got {num_envs}")
    require_gymnasium("Acrobot")
    return gym_batch([partial(_make_single)] * num_envs, max_steps=MAX_EPISODE_STEPS)


def tip_height(observation: Any) -> Any:
    """The free end's height above the pivot, in link lengths (the task's goal: above 1), from observations
    ``[..., 6]`` (a tensor or an array).

    Examples:
        >>> import torch
        >>> tip_height(torch.tensor([[1.0, 0.0, 1.0, 0.0, 0.0, 0.0], [-1.0, 0.0, 1.0, 0.0, 0.0, 0.0]])).tolist()
        [-2.0, 2.0]
    """
    cos1, sin1, cos2, sin2 = (observation[..., i] for i in range(4))
    return -cos1 - (cos1 * cos2 - sin1 * sin2)  # -cos θ₁ - cos(θ₁ + θ₂)


def acrobot_subgoals() -> SubgoalSeries:
    """The shipped series: the first link swung out to 60°, then to the horizontal.

    Examples:
        >>> series = acrobot_subgoals()
        >>> len(series), [p.to_dict()["box"]["dims"] for p in series.predicates]
        (2, [[0], [0]])
    """
    return load_pattern(SUBGOAL_FILE, "swing_out")
