"""The numbers Okudo & Yamada (2021) publish, to set beside a reproduction's.

Source: T. Okudo and S. Yamada, "Reward Shaping with Dynamic Trajectory
Aggregation", International Joint Conference on Neural Networks (IJCNN), 2021.
Method names follow the paper's columns: "HRS" (human subgoals), "RRS" (random
subgoals), the plain agent ("SARSA", "AC" or "DDPG") and "NRS" (naive shaping).
The paper has no SARSA-RS column in these tables.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from torchrl_subgoal import registry

CITATION = (
    'Okudo, T. & Yamada, S. (2021). "Reward Shaping with Dynamic Trajectory Aggregation". '
    "International Joint Conference on Neural Networks (IJCNN)."
)


@dataclass(frozen=True)
class PaperStat:
    """A mean and its standard deviation across learnings, as printed in the paper.

    Examples:
        >>> PaperStat(mean=12.5, sd=3.0)
        PaperStat(mean=12.5, sd=3.0)
    """

    mean: float
    sd: float


@dataclass(frozen=True)
class PaperResults:
    """What the paper reports for one domain.

    Attributes:
        domain: ``"four_rooms"``, ``"pinball"`` or ``"fetch"``.
        metric: the per-episode metric the thresholds apply to.
        window: moving-average window of the time-to-threshold measure (1 = none).
        time_to_threshold: threshold -> method -> episodes to reach it.
        asymptotic: method -> mean over ``asymptotic_window`` (empty if not tabulated).
        asymptotic_window: 1-based inclusive range of episodes (or epochs) the paper names.
        learnings: independent learnings per method behind the numbers, when the paper says.
        notes: findings the paper states in words.
        source: the citation.

    Examples:
        >>> paper = PaperResults("four_rooms", "steps", 1, {100.0: {"HRS": PaperStat(10.0, 2.0)}})
        >>> paper.time_to_threshold[100.0]["HRS"].mean, paper.asymptotic
        (10.0, {})
    """

    domain: str
    metric: str
    window: int
    time_to_threshold: Mapping[float, Mapping[str, PaperStat]]
    asymptotic: Mapping[str, float] = field(default_factory=dict)
    asymptotic_window: tuple[int, int] | None = None
    learnings: int | None = None
    notes: tuple[str, ...] = ()
    source: str = CITATION


def paper_table(
    methods: tuple[str, ...], rows: Mapping[float, tuple[tuple[float, float], ...]]
) -> dict[float, dict[str, PaperStat]]:
    """A time-to-threshold table as printed: threshold -> one ``(mean, sd)`` per method, in ``methods``' order.

    Examples:
        >>> paper_table(("HRS", "SARSA"), {50: ((33.0, 10.2), (51.8, 16.2))})[50]["SARSA"]
        PaperStat(mean=51.8, sd=16.2)
    """
    return {
        threshold: {m: PaperStat(mean, sd) for m, (mean, sd) in zip(methods, cells, strict=True)}
        for threshold, cells in rows.items()
    }


def paper_results(domain: str) -> PaperResults | None:
    """The paper's results for ``domain`` (the :class:`PaperResults` part of its registration), or None if
    the paper has none for it.

    Examples:
        >>> paper_results("four_rooms").time_to_threshold[500]["HRS"]
        PaperStat(mean=2.68, sd=1.86)
        >>> paper_results("toy") is None
        True
    """
    registered = registry.find(domain)
    return registered.part(PaperResults) if registered is not None else None
