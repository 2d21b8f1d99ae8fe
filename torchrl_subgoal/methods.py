"""The paper's methods as configurations of one shaping transform.

=========  ==================================================  ===============
method     shaping                                              subgoals
=========  ==================================================  ===============
HRS        learned potential over the subgoal series (ours)     people's
RRS        the same, with random subgoals                       random
NRS        fixed potential ``η`` on achieving a subgoal          people's
SRS        fixed potential rising with each subgoal achieved     people's
HRS-D      HRS, also rising towards the next subgoal's region    people's
SARSA-RS   learned potential over a hand-given ``z = g(s)``     — (aggregation)
baseline   none (SARSA, actor-critic, DDPG)                     —
=========  ==================================================  ===============

SRS is Okudo & Yamada's follow-up ("Subgoal-based Reward Shaping to Improve Efficiency in
Reinforcement Learning", 2021): ``Φ(z) = η·z``. Here its scale is the progress prior's
(:meth:`~torchrl_subgoal.SubgoalSeries.progress`): each subgoal adds ``scale / (n + 1)``.

Recipes call :func:`shaping_transform` with the domain's pieces and append the
result to their env; nothing else differs between methods.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import torch
from tensordict.utils import NestedKey

from torchrl_subgoal.loss import SubgoalValueLoss, ValueUpdate
from torchrl_subgoal.potentials import NaivePotential, Potential, TabularPotential
from torchrl_subgoal.subgoals import Predicate, StateAggregation, SubgoalSeries
from torchrl_subgoal.transform import StartPotential, SubgoalPotentialTransform

__all__ = [
    "HRS_D",
    "SRS",
    "Method",
    "all_methods",
    "paper_methods",
    "random_patterns",
    "shaping_parts",
    "shaping_transform",
]

Shaping = Literal["none", "subgoals", "naive", "progress", "aggregation"]


@dataclass(frozen=True)
class Method:
    """One compared method.

    Attributes:
        name: as in the paper's tables (``"HRS"``, ``"RRS"``, ``"NRS"``, ``"SARSA-RS"``, …).
        shaping: ``"subgoals"`` (learned potential over a subgoal series),
            ``"naive"`` (fixed ``η``), ``"progress"`` (fixed, rising with each subgoal),
            ``"aggregation"`` (learned over ``g(s)``) or ``"none"``.
        subgoals: which patterns it uses: ``"human"``, ``"random"`` or ``"none"``.
        interpolate: its table also rises within each segment as the observation nears the next subgoal
            (``TabularPotential(interpolate=True)``; subgoals that are regions).

    Examples:
        >>> method = Method("HRS", "subgoals", "human")
        >>> method.shaping, method.subgoals
        ('subgoals', 'human')
    """

    name: str
    shaping: Shaping
    subgoals: Literal["human", "random", "none"]
    interpolate: bool = False


def paper_methods(baseline: str) -> dict[str, Method]:
    """The five methods of the paper, with ``baseline`` the unshaped agent's name.

    Examples:
        >>> list(paper_methods("SARSA"))
        ['HRS', 'RRS', 'SARSA', 'NRS', 'SARSA-RS']
    """
    methods = [
        Method("HRS", "subgoals", "human"),
        Method("RRS", "subgoals", "random"),
        Method(baseline, "none", "none"),
        Method("NRS", "naive", "human"),
        Method("SARSA-RS", "aggregation", "none"),
    ]
    return {m.name: m for m in methods}


#: subgoal-based reward shaping with a fixed potential (Okudo & Yamada's SRS)
SRS = Method("SRS", "progress", "human")
#: the library's default potential (``TabularPotential.for_subgoals``): HRS with the within-segment term, which also
#: rises as the next subgoal's region comes nearer
HRS_D = Method("HRS-D", "subgoals", "human", interpolate=True)


def all_methods(baseline: str) -> dict[str, Method]:
    """The paper's methods, SRS and HRS-D (the library's default potential).

    Examples:
        >>> list(all_methods("PPO"))
        ['HRS', 'RRS', 'PPO', 'NRS', 'SARSA-RS', 'SRS', 'HRS-D']
    """
    return {**paper_methods(baseline), SRS.name: SRS, HRS_D.name: HRS_D}


def random_patterns(
    candidates: Sequence[Predicate], num_patterns: int, num_subgoals: int, seed: int
) -> list[SubgoalSeries]:
    """``num_patterns`` random chains (RRS), reproducible from ``seed``.

    Examples:
        >>> from torchrl_subgoal.subgoals import Cell
        >>> patterns = random_patterns([Cell(1, 1), Cell(2, 2), Cell(3, 3)], num_patterns=2, num_subgoals=2, seed=0)
        >>> [p.name for p in patterns], [len(p) for p in patterns]
        (['random_1', 'random_2'], [2, 2])
        >>> [p.to_dict() for p in patterns] == [p.to_dict() for p in random_patterns(
        ...     [Cell(1, 1), Cell(2, 2), Cell(3, 3)], num_patterns=2, num_subgoals=2, seed=0)]
        True
    """
    generator = torch.Generator().manual_seed(seed)
    return [
        SubgoalSeries.random(candidates, num_subgoals, generator, name=f"random_{i + 1}") for i in range(num_patterns)
    ]


def shaping_parts(
    method: Method,
    batch_shape: torch.Size | tuple[int, ...],
    *,
    patterns: Sequence[SubgoalSeries] | None = None,
    pattern_index: torch.Tensor | None = None,
    aggregation: StateAggregation | None = None,
    eta: float = 1.0,
    observation_key: NestedKey = "observation",
    aggregation_key: NestedKey = "observation",
    zero_terminal_potential: bool = True,
    start_potential: StartPotential = "nonpositive",
    monotone_potential: bool = True,
    progress_scale: float = 1.0,
) -> tuple[SubgoalSeries | list[SubgoalSeries] | StateAggregation, Potential, dict[str, Any]] | None:
    """What :class:`SubgoalPotentialTransform` needs for ``method``: the subgoals (or aggregation),
    the potential and the other keyword arguments; ``None`` for the unshaped baseline.

    With ``pattern_index`` (the pattern of every env), the subgoals are one series per env.

    ``batch_shape`` is the potential's: the env batch for one table per env (one
    learner per env, as the SARSA recipes), ``()`` for one table shared by every
    env (one learner stepping many envs, as A2C).

    The learned tables over subgoal series (HRS, RRS) start at each series' progress prior
    (:meth:`~torchrl_subgoal.SubgoalSeries.progress` of ``progress_scale``, in reward units: what
    reaching the goal is worth; 0 starts them at 0, as the paper) and, with ``monotone_potential``,
    shape non-decreasing along the series (``TabularPotential(monotone=True)``). SRS's fixed tables
    are the prior itself. A method that interpolates (HRS-D) also rises within each segment as the
    observation nears the next subgoal (``TabularPotential(interpolate=True)``). The naive potential
    and an aggregation's table are shaped as they are.

    Examples:
        >>> from torchrl_subgoal.subgoals import Cell
        >>> print(shaping_parts(Method("SARSA", "none", "none"), (2,)))
        None
        >>> series = SubgoalSeries([Cell(4, 9)], name="alice")
        >>> subgoals, potential, options = shaping_parts(Method("HRS", "subgoals", "human"), (2,), patterns=[series])
        >>> [s.name for s in subgoals], type(potential).__name__, sorted(options)
        (['alice'], 'TabularPotential', ['observation_key', 'start_potential', 'zero_terminal_potential'])
    """
    if method.shaping == "none":
        return None
    options: dict[str, Any] = {"zero_terminal_potential": zero_terminal_potential, "start_potential": start_potential}
    if method.shaping == "aggregation":
        if aggregation is None:
            raise ValueError(f"{method.name} needs an aggregation g(s)")
        return (
            aggregation,
            TabularPotential(aggregation.num_states, batch_shape),
            {**options, "observation_key": aggregation_key},
        )
    if not patterns:
        raise ValueError(f"{method.name} needs subgoal patterns")
    options["observation_key"] = observation_key
    per_env = list(patterns) if pattern_index is None else [patterns[i] for i in pattern_index.reshape(-1).tolist()]
    if method.shaping == "naive":
        return per_env, NaivePotential(eta), options
    if method.shaping == "progress" and progress_scale <= 0:
        raise ValueError(
            f"{method.name} shapes with the progress prior: progress_scale must be > 0, got {progress_scale}"
        )
    shape = torch.Size(batch_shape)
    series = per_env if shape.numel() == len(per_env) else per_env[:1]  # a table per env's series, or shared
    potential = TabularPotential.for_subgoals(
        series,
        progress_scale,
        shape,
        monotone=monotone_potential and method.shaping == "subgoals",
        interpolate=method.interpolate,
    )
    if method.shaping == "progress":
        potential.table.requires_grad_(False)  # SRS: the prior itself, fixed
    return per_env, potential, options


#: the keyword arguments of :func:`shaping_transform` that configure the learned potential's loss
TARGET_OPTIONS = ("expectile", "bootstrap_truncated", "achievement_reward")


def shaping_transform(
    method: Method,
    batch_shape: torch.Size,
    *,
    gamma: float,
    value_lr: float | None,
    patterns: Sequence[SubgoalSeries] | None = None,
    pattern_index: torch.Tensor | None = None,
    aggregation: StateAggregation | None = None,
    eta: float = 1.0,
    observation_key: NestedKey = "observation",
    aggregation_key: NestedKey = "observation",
    **conventions: Any,
) -> SubgoalPotentialTransform | None:
    """The shaping transform of ``method`` for a batch of learners, or ``None`` for the baseline.

    Args:
        method: the method.
        batch_shape: the env batch (one learner per env; each gets its own table).
        gamma: the agent's discount.
        value_lr: ``α_v`` of the learned potentials, updated online; ``None`` to train
            them yourself from the SMDP transitions of the collected data.
        patterns: the subgoal series (HRS, RRS, NRS).
        pattern_index: pattern of each learner, shape ``batch_shape``.
        aggregation: ``g(s)`` for SARSA-RS.
        eta: the naive potential's ``η`` (NRS).
        observation_key: what subgoal predicates read.
        aggregation_key: what ``g`` reads.
        **conventions: ``zero_terminal_potential`` and ``start_potential`` (the transform's, see
            :class:`SubgoalPotentialTransform`), ``monotone_potential`` (:func:`shaping_parts`),
            ``expectile``, ``bootstrap_truncated`` and ``achievement_reward`` (the learned potential's
            target, see :class:`SubgoalValueLoss`), ``prior_weight`` (its online update, see
            :class:`ValueUpdate`); the library's defaults otherwise.

    Examples:
        >>> import torch
        >>> from torchrl_subgoal.envs.four_rooms import room_aggregation
        >>> methods = paper_methods("SARSA")
        >>> t = shaping_transform(methods["SARSA-RS"], torch.Size([4]), gamma=0.99, value_lr=0.25,
        ...                       aggregation=room_aggregation())
        >>> type(t.potential).__name__, t.potential.batch_shape
        ('TabularPotential', torch.Size([4]))
    """
    parts = shaping_parts(
        method,
        batch_shape,
        patterns=patterns,
        pattern_index=pattern_index,
        aggregation=aggregation,
        eta=eta,
        observation_key=observation_key,
        aggregation_key=aggregation_key,
        **{k: v for k, v in conventions.items() if k not in (*TARGET_OPTIONS, "prior_weight")},
    )
    if parts is None:
        return None
    subgoals, potential, options = parts
    update = None
    if value_lr is not None and isinstance(potential, TabularPotential):
        loss = SubgoalValueLoss(potential, **{k: v for k, v in conventions.items() if k in TARGET_OPTIONS})
        weight = float(conventions.get("prior_weight", 0.0))
        update = ValueUpdate(value_lr, loss.make_value_estimator(gamma=gamma), prior_weight=weight)
    return SubgoalPotentialTransform(subgoals, potential, gamma=gamma, value_update=update, **options)
