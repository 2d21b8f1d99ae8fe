"""The paper's methods as configurations of one shaping transform.

=========  ==================================================  ===============
method     shaping                                              subgoals
=========  ==================================================  ===============
HRS        learned potential over the subgoal series (ours)     people's
RRS        the same, with random subgoals                       random
NRS        fixed potential ``η`` on achieving a subgoal          people's
SARSA-RS   learned potential over a hand-given ``z = g(s)``     — (aggregation)
baseline   none (SARSA, actor-critic, DDPG)                     —
=========  ==================================================  ===============

Recipes call :func:`shaping_transform` with the domain's pieces and append the
result to their env; nothing else differs between methods.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import torch
from tensordict.utils import NestedKey

from torchrl_subgoal.potentials import NaivePotential, TabularPotential
from torchrl_subgoal.subgoals import Predicate, StateAggregation, SubgoalSeries
from torchrl_subgoal.transform import SubgoalPotentialTransform

__all__ = ["Method", "paper_methods", "random_patterns", "shaping_transform"]

Shaping = Literal["none", "subgoals", "naive", "aggregation"]


@dataclass(frozen=True)
class Method:
    """One compared method.

    Attributes:
        name: as in the paper's tables (``"HRS"``, ``"RRS"``, ``"NRS"``, ``"SARSA-RS"``, …).
        shaping: ``"subgoals"`` (learned potential over a subgoal series),
            ``"naive"`` (fixed ``η``), ``"aggregation"`` (learned over ``g(s)``)
            or ``"none"``.
        subgoals: which patterns it uses: ``"human"``, ``"random"`` or ``"none"``.
    """

    name: str
    shaping: Shaping
    subgoals: Literal["human", "random", "none"]


def paper_methods(baseline: str) -> dict[str, Method]:
    """The five methods of the paper, with ``baseline`` the unshaped agent's name."""
    methods = [
        Method("HRS", "subgoals", "human"),
        Method("RRS", "subgoals", "random"),
        Method(baseline, "none", "none"),
        Method("NRS", "naive", "human"),
        Method("SARSA-RS", "aggregation", "none"),
    ]
    return {m.name: m for m in methods}


def random_patterns(
    candidates: Sequence[Predicate], num_patterns: int, num_subgoals: int, seed: int
) -> list[SubgoalSeries]:
    """``num_patterns`` random chains (RRS), reproducible from ``seed``."""
    generator = torch.Generator().manual_seed(seed)
    return [
        SubgoalSeries.random(candidates, num_subgoals, generator, name=f"random_{i + 1}")
        for i in range(num_patterns)
    ]


def shaping_transform(
    method: Method,
    batch_shape: torch.Size,
    *,
    gamma: float,
    value_lr: float,
    patterns: Sequence[SubgoalSeries] | None = None,
    pattern_index: torch.Tensor | None = None,
    aggregation: StateAggregation | None = None,
    eta: float = 1.0,
    observation_key: NestedKey = "observation",
    aggregation_key: NestedKey = "observation",
    zero_terminal_potential: bool = True,
) -> SubgoalPotentialTransform | None:
    """The shaping transform of ``method`` for a batch of learners, or ``None`` for the baseline.

    Args:
        method: the method.
        batch_shape: the env batch (one learner per env; each gets its own table).
        gamma: the agent's discount.
        value_lr: ``α_v`` of the learned potentials (updated online).
        patterns: the subgoal series (HRS, RRS, NRS).
        pattern_index: pattern of each learner, shape ``batch_shape``.
        aggregation: ``g(s)`` for SARSA-RS.
        eta: the naive potential's ``η`` (NRS).
        observation_key: what subgoal predicates read.
        aggregation_key: what ``g`` reads.
        zero_terminal_potential: see :class:`SubgoalPotentialTransform`.
    """
    if method.shaping == "none":
        return None
    if method.shaping == "aggregation":
        if aggregation is None:
            raise ValueError(f"{method.name} needs an aggregation g(s)")
        table = TabularPotential(aggregation.num_states, batch_shape)
        return SubgoalPotentialTransform(
            aggregation, table, gamma=gamma, observation_key=aggregation_key, value_lr=value_lr,
            zero_terminal_potential=zero_terminal_potential,
        )
    if not patterns:
        raise ValueError(f"{method.name} needs subgoal patterns")
    if method.shaping == "naive":
        return SubgoalPotentialTransform(
            list(patterns), NaivePotential(eta), gamma=gamma, observation_key=observation_key,
            pattern_index=pattern_index, zero_terminal_potential=zero_terminal_potential,
        )
    num_states = max(len(p) for p in patterns) + 1
    return SubgoalPotentialTransform(
        list(patterns), TabularPotential(num_states, batch_shape), gamma=gamma,
        observation_key=observation_key, pattern_index=pattern_index, value_lr=value_lr,
        zero_terminal_potential=zero_terminal_potential,
    )
