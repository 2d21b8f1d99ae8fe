"""MountainCar-v0 (gymnasium) as a batched TorchRL env, with subgoals for a step-cost study.

gymnasium's classic task: a car in a valley, observation ``(position,
velocity)``, three actions (push left, none, push right); reward −1 per step;
the episode terminates when the position reaches 0.5 (the flag on the right
hill) and is truncated after 200 steps. The engine is too weak to climb
straight up: the car must first swing back up the left hill. The batch steps
in one process (:func:`~torchrl_subgoal.envs.gym_batch.gym_batch`); starts are
gymnasium's (position uniform in ``[−0.6, −0.4]``, at rest), seeded by the
collector.

The shipped subgoal file (:data:`SUBGOAL_FILE`) holds one ordered series of
two boxes over ``(position, velocity)``:

1. **swung back up the left hill**: position ≤ −0.85. From rest at −0.85,
   pushing right all the way reaches the flag (at −0.8 it does not): the car
   has gained the height a single run needs.
2. **past the valley with speed**: position ≥ −0.3 and velocity ≥ 0.035
   (towards the flag). Pushing right from −0.3 reaches the flag from a speed
   of about 0.038 upwards; a car swung up from −0.85 passes −0.3 at 0.0385,
   from −0.9 at 0.0425.

Both thresholds come from the task's dynamics (``v ← v + 0.001 (a − 1) −
0.0025 cos 3p``, ``p ← p + v``); a uniformly random policy reaches the first
subgoal in under 1% of its episodes, so the shaped learner meets it through
exploration, as the unshaped one meets the flag.

Needs ``gymnasium``.
"""

from __future__ import annotations

from functools import partial
from importlib.resources import files
from typing import Any

from torchrl.envs import EnvBase

from torchrl_subgoal.envs.gym_batch import gym_batch, require_gymnasium
from torchrl_subgoal.subgoals import SubgoalSeries, load_pattern

__all__ = ["ENV_ID", "MAX_EPISODE_STEPS", "SUBGOAL_FILE", "make_mountain_car", "mountain_car_subgoals"]

ENV_ID = "MountainCar-v0"
#: gymnasium's time limit.
MAX_EPISODE_STEPS = 200
SUBGOAL_FILE = str(files("torchrl_subgoal") / "domains" / "mountain_car" / "mountain_car_subgoals.yaml")


def _make_single() -> Any:
    return require_gymnasium("MountainCar").make(ENV_ID)


def make_mountain_car(num_envs: int) -> EnvBase:
    """``num_envs`` MountainCar-v0 envs stepped together in this process, one TorchRL env.

    Observation ``"observation"`` = ``(position, velocity)`` (float32), a categorical action of
    three, reward −1 per step, termination at the flag, truncation after 200 steps (``max_steps``).

    Args:
        num_envs: envs in the batch.

    Examples:
        >>> env = make_mountain_car(2)
        >>> _ = env.set_seed(0)
        >>> td = env.rollout(3)
        >>> td["next", "observation"].shape, td["next", "reward"].unique().tolist(), env.max_steps
        (torch.Size([2, 3, 2]), [-1.0], 200)
    """
    if num_envs < 1:
        raise ValueError(f"num_envs must be >= 1, got {num_envs}")
    require_gymnasium("MountainCar")
    return gym_batch([partial(_make_single)] * num_envs, max_steps=MAX_EPISODE_STEPS)


def mountain_car_subgoals() -> SubgoalSeries:
    """The shipped series: swung back up the left hill, then past the valley with speed.

    Examples:
        >>> series = mountain_car_subgoals()
        >>> len(series), [p.to_dict()["box"]["dims"] for p in series.predicates]
        (2, [[0], [0, 1]])
    """
    return load_pattern(SUBGOAL_FILE, "swing_then_speed")
