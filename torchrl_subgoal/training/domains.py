"""The four-rooms and PinBall pieces the A2C recipe needs: env factory, keys, baselines' inputs, defaults.

A user's own domain is the same handful of fields (:class:`A2CDomain`): an
env factory ``make_env(num_envs)``, the observation the networks read, the one
the subgoals read, and a subgoal file.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from importlib.resources import files

import torch
from tensordict.utils import NestedKey
from torchrl.envs import EnvBase

from torchrl_subgoal.envs.four_rooms_domain import four_rooms_env
from torchrl_subgoal.envs.pinball_domain import pinball_env
from torchrl_subgoal.subgoals import Box, Cell, Circle, Predicate, StateAggregation
from torchrl_subgoal.training.a2c import A2CConfig

__all__ = ["A2CDomain", "a2c_domain", "four_rooms_env", "pinball_env"]


@dataclass(frozen=True)
class A2CDomain:
    """What the A2C recipe needs of a domain.

    Attributes:
        name: the domain's name (subgoal files' ``domain`` field).
        make_env: ``make_env(num_envs)``, an env with batch size ``[num_envs]`` (picklable).
        observation_key: what the policy and value network read.
        subgoal_key: what the subgoal predicates read.
        aggregation_key: what SARSA-RS's aggregation ``g`` reads.
        participants: the shipped subgoal file of the human patterns.
        eta: NRS's ``η`` in the learner's reward units (after ``a2c.reward_scale``).
        thresholds: episode lengths the report times.
        a2c: default settings.
        aggregation: SARSA-RS's ``g(s)`` (``None``: no SARSA-RS).
        candidates: RRS's candidate subgoals, from a seed.

    Examples:
        >>> domain = a2c_domain("four_rooms")
        >>> domain.observation_key, domain.subgoal_key, domain.make_env(2).batch_size
        ('observation', 'cell', torch.Size([2]))
    """

    name: str
    make_env: Callable[[int], EnvBase]
    observation_key: NestedKey
    subgoal_key: NestedKey
    aggregation_key: NestedKey
    participants: str
    eta: float
    thresholds: tuple[float, ...]
    a2c: A2CConfig
    aggregation: Callable[[], StateAggregation | None] = field(default=lambda: None)
    candidates: Callable[[int], list[Predicate]] = field(default=lambda seed: [])


def _four_rooms_candidates(seed: int) -> list[Predicate]:
    from torchrl_subgoal.envs.four_rooms import GOAL, START, free_cells

    return [Cell(r, c) for r, c in free_cells() if (r, c) not in (START, GOAL)]


def _four_rooms_aggregation() -> StateAggregation:
    from torchrl_subgoal.envs.four_rooms import room_aggregation

    return room_aggregation()


def _pinball_candidates(seed: int) -> list[Predicate]:
    from torchrl_subgoal.envs import PinBallEnv

    points = PinBallEnv(1, "simple").sample_free_positions(500, torch.Generator().manual_seed(seed))
    return [Circle((float(x), float(y)), 0.04) for x, y in points.tolist()]


def _pinball_aggregation() -> StateAggregation:
    return StateAggregation.from_regions([Box((c,), (1 / 6,), (0,)) for c in (1 / 6, 1 / 2, 5 / 6)], 4)


def _data(name: str) -> str:
    return str(files("torchrl_subgoal") / "data" / name)


def a2c_domain(name: str) -> A2CDomain:
    """The A2C set-up of ``"four_rooms"`` or ``"pinball"``.

    Examples:
        >>> a2c_domain("four_rooms").a2c.features
        'one_hot'
    """
    if name == "four_rooms":
        return A2CDomain(
            name, four_rooms_env, "observation", "cell", "observation", _data("four_rooms_participants.yaml"),
            eta=1.0, thresholds=(100.0, 50.0),
            a2c=A2CConfig(features="one_hot", hidden=(), lr=1e-2, total_frames=100_000),
            aggregation=_four_rooms_aggregation, candidates=_four_rooms_candidates,
        )
    if name == "pinball":
        return A2CDomain(
            name, pinball_env, "observation", "observation", "observation", _data("pinball_participants.yaml"),
            eta=1.0, thresholds=(3000.0, 2000.0, 1000.0, 500.0),
            # lr: the paper's 0.01 divided by the Fourier features' norm (‖φ‖ ≈ 11.3 for order 3 on PinBall's
            # states), as its actor-critic divides its steps; with 0.01 A2C learns, then collapses (docs/torchrl.md).
            a2c=A2CConfig(features="fourier", hidden=(), fourier_order=3, lr=1e-3, reward_scale=1e-4,
                          total_frames=2_000_000),
            aggregation=_pinball_aggregation, candidates=_pinball_candidates,
        )
    raise ValueError(f"unknown A2C domain {name!r}; known: four_rooms, pinball")
