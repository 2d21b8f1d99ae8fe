"""What the A2C recipe needs of a domain: env factory, keys, baselines' inputs, defaults.

A domain gives its set-up as a part of its registration (an :class:`A2CDomain` in
:attr:`torchrl_subgoal.domains.Domain.parts`; the four-rooms and PinBall plugins
do), found with ``torchrl_subgoal.domains.part(name, A2CDomain)``. A user's own
domain is the same handful of fields: an env factory ``make_env(num_envs)``, the
observation the networks read, the one the subgoals read, and a subgoal file.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from tensordict.utils import NestedKey
from torchrl.envs import EnvBase

from torchrl_subgoal.subgoals import Predicate, StateAggregation
from torchrl_subgoal.training.a2c import A2CConfig

__all__ = ["A2CDomain"]


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
        >>> from torchrl_subgoal import domains
        >>> domain = domains.part("four_rooms", A2CDomain)
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
