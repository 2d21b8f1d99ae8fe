"""Taxi (gymnasium) as a batched TorchRL env, with two subgoals given as conditions: a step-cost task.

gymnasium's ``Taxi-v4``: a 5×5 grid, four coloured stands; the taxi must drive to the
passenger, pick them up, drive to the destination and drop them off. Reward −1 per step,
−10 for an illegal pick-up or drop-off, +20 for the delivery (which terminates the episode);
truncation after 200 steps. The observation is one state number of 500, packing
``((row · 5 + col) · 5 + passenger) · 4 + destination`` (``passenger = 4``: in the taxi).

The subgoal series :func:`taxi_subgoals` has two :class:`~torchrl_subgoal.Condition` subgoals
decoded from that number: the passenger is in the taxi, then the taxi is at the destination with
the passenger on board. A random policy takes hundreds of steps to deliver, so the step cost
dominates the early returns: the regime in which a potential learned from the agent's own
returns can pay it to wander (docs/shaping_defaults.md).

Needs ``gymnasium``.
"""

from __future__ import annotations

from functools import partial

import torch
from tensordict import TensorDictBase
from torchrl.envs import EnvBase

from torchrl_subgoal.envs.gym_batch import gym_batch, require_gymnasium
from torchrl_subgoal.subgoals import SubgoalSeries

__all__ = ["ENV_ID", "MAX_EPISODE_STEPS", "at_destination", "decode", "make_taxi", "passenger_in_taxi", "taxi_subgoals"]

ENV_ID = "Taxi-v4"
#: gymnasium's time limit.
MAX_EPISODE_STEPS = 200
#: ``(row, col)`` of the four stands (R, G, Y, B), indexed by the destination field.
STANDS = torch.tensor([[0, 0], [0, 4], [4, 0], [4, 3]])


def decode(state: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """``(row, col, passenger, destination)`` of Taxi state numbers (``passenger = 4``: in the taxi).

    Examples:
        >>> [int(x) for x in decode(torch.tensor(((3 * 5 + 1) * 5 + 4) * 4 + 2))]
        [3, 1, 4, 2]
    """
    s = state.long()
    return s // 100, (s // 20) % 5, (s // 4) % 5, s % 4


def passenger_in_taxi(td: TensorDictBase) -> torch.Tensor:
    """Subgoal 1: the passenger is in the taxi.

    Examples:
        >>> from tensordict import TensorDict
        >>> passenger_in_taxi(TensorDict({"observation": torch.tensor([16, 0])}, [2])).tolist()  # passenger field 4, 0
        [True, False]
    """
    return decode(td["observation"])[2] == 4


def at_destination(td: TensorDictBase) -> torch.Tensor:
    """Subgoal 2: the taxi carries the passenger and stands on the destination.

    Examples:
        >>> from tensordict import TensorDict
        >>> at_stand_b = ((4 * 5 + 3) * 5 + 4) * 4 + 3  # row 4, column 3 (stand B), passenger aboard, destination B
        >>> at_destination(TensorDict({"observation": torch.tensor([at_stand_b, at_stand_b - 1])}, [2])).tolist()
        [True, False]
    """
    row, col, passenger, destination = decode(td["observation"])
    stand = STANDS[destination]
    return (passenger == 4) & (row == stand[..., 0]) & (col == stand[..., 1])


def taxi_subgoals() -> SubgoalSeries:
    """The ordered series: pick the passenger up, then reach the destination with them.

    Examples:
        >>> [p.name for p in taxi_subgoals().predicates]
        ['passenger_in_taxi', 'at_destination']
    """
    return SubgoalSeries([passenger_in_taxi, at_destination], name="pick_up_then_drive")


def make_taxi(num_envs: int) -> EnvBase:
    """``num_envs`` Taxi envs stepped together in this process, one TorchRL env: a categorical
    ``"observation"`` of 500 states, a categorical action of six, ``max_steps = 200``.

    Examples:
        >>> env = make_taxi(2)
        >>> env.batch_size, env.observation_spec["observation"].space.n
        (torch.Size([2]), 500)
    """
    if num_envs < 1:
        raise ValueError(f"num_envs must be >= 1, got {num_envs}")
    make = partial(require_gymnasium("Taxi").make, ENV_ID)
    return gym_batch([make] * num_envs, max_steps=MAX_EPISODE_STEPS)
