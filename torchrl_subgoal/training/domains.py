"""What the A2C recipe needs of a domain: env factory, keys, baselines' inputs, defaults.

A domain gives its set-up through its registration
(:attr:`torchrl_subgoal.domains.Domain.a2c`, a function returning an
:class:`A2CDomain`; four-rooms and PinBall do, in their ``envs/*_domain.py``).
A user's own domain is the same handful of fields: an env factory
``make_env(num_envs)``, the observation the networks read, the one the
subgoals read, and a subgoal file.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from tensordict.utils import NestedKey
from torchrl.envs import EnvBase

from torchrl_subgoal import domains
from torchrl_subgoal.subgoals import Predicate, StateAggregation
from torchrl_subgoal.training.a2c import A2CConfig

__all__ = ["A2CDomain", "a2c_domain"]


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


def a2c_domain(name: str) -> A2CDomain:
    """The A2C set-up of a registered domain (its :attr:`~torchrl_subgoal.domains.Domain.a2c`).

    Raises:
        ValueError: the domain is unknown or has no A2C set-up; the message lists those that have one.

    Examples:
        >>> a2c_domain("four_rooms").a2c.features
        'one_hot'
        >>> a2c_domain("pick_and_place")
        Traceback (most recent call last):
        ...
        ValueError: no A2C set-up (Domain.a2c) for domain 'pick_and_place'; these have one: four_rooms, pinball
    """
    domain = domains.find(name)
    if domain is None or domain.a2c is None:
        problem = "unknown A2C domain" if domain is None else "no A2C set-up (Domain.a2c) for domain"
        raise ValueError(f"{problem} {name!r}; these have one: {', '.join(domains.having('a2c'))}")
    return domain.a2c()
