"""What the learner recipes need of a domain: env factory, keys, baselines' inputs, each learner's defaults.

A domain gives its set-up as a part of its registration (a :class:`LearnerDomain` in
:attr:`torchrl_subgoal.domains.Domain.parts`; the four-rooms, PinBall, PointMaze and
MountainCar plugins do), found with ``torchrl_subgoal.domains.part(name, LearnerDomain)``.
A user's own domain is the same handful of fields: an env factory ``make_env(num_envs)``,
the observation the networks read, the one the subgoals read, a subgoal file, and the
settings of the learners it suits.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from tensordict.utils import NestedKey
from torchrl.envs import EnvBase

from torchrl_subgoal.subgoals import Predicate, StateAggregation
from torchrl_subgoal.training.recording import SuccessSignal

__all__ = ["A2CDomain", "LearnerDomain"]


@dataclass(frozen=True)
class LearnerDomain:
    """What the learner recipes (``torchrl-subgoal train``, ``recipes/a2c.py``) need of a domain.

    Attributes:
        name: the domain's name (subgoal files' ``domain`` field).
        make_env: ``make_env(num_envs)``, an env with batch size ``[num_envs]`` (picklable).
        observation_key: what the networks read.
        subgoal_key: what the subgoal predicates read.
        aggregation_key: what SARSA-RS's aggregation ``g`` reads.
        participants: the shipped subgoal file of the human patterns.
        eta: NRS's ``η`` in the learner's reward units (after the learner's ``reward_scale``).
        thresholds: episode lengths the report times.
        defaults: each learner's default settings, by learner name (``"a2c"``, ``"ppo"``, ``"dqn"``,
            ``"ddpg"``: an :class:`~torchrl_subgoal.training.A2CConfig`, …); a learner not named
            here starts from its settings class's defaults.
        aggregation: SARSA-RS's ``g(s)`` (``None``: no SARSA-RS).
        candidates: RRS's candidate subgoals, from a seed.
        pattern_env: for a domain whose subgoal patterns each belong to their own task (PointMaze:
            one pattern per direction of its route), ``pattern_env(pattern, seed)`` is the env factory
            of a learner following ``pattern``; ``None``: ``make_env`` for every learner.
        success: what counts as a successful episode where the env writes no success entry (a return
            threshold); ``None``: the env's ``"is_success"``/``"success"`` entry, else not recorded.

    Examples:
        >>> from torchrl_subgoal import domains
        >>> domain = domains.part("four_rooms", LearnerDomain)
        >>> domain.observation_key, domain.subgoal_key, domain.make_env(2).batch_size
        ('observation', 'cell', torch.Size([2]))
        >>> domain.a2c.features, sorted(domain.defaults)
        ('one_hot', ['a2c', 'dqn', 'ppo'])
    """

    name: str
    make_env: Callable[[int], EnvBase]
    observation_key: NestedKey
    subgoal_key: NestedKey
    aggregation_key: NestedKey
    participants: str
    eta: float
    thresholds: tuple[float, ...]
    defaults: Mapping[str, Any] = field(default_factory=dict)
    aggregation: Callable[[], StateAggregation | None] = field(default=lambda: None)
    candidates: Callable[[int], list[Predicate]] = field(default=lambda seed: [])
    pattern_env: Callable[[str, int], Callable[[int], EnvBase]] | None = None
    success: SuccessSignal | None = None

    @property
    def a2c(self) -> Any:
        """The A2C defaults (``defaults["a2c"]``)."""
        return self.defaults["a2c"]

    def env_for(self, pattern: str, seed: int) -> Callable[[int], EnvBase]:
        """The env factory of a learner following ``pattern`` (a human pattern's name) with ``seed``."""
        return self.pattern_env(pattern, seed) if self.pattern_env is not None else self.make_env


#: The earlier name of :class:`LearnerDomain` (when only the A2C recipe read it).
A2CDomain = LearnerDomain
