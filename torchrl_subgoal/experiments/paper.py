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


def _table(methods: tuple[str, ...], rows: Mapping[float, tuple[tuple[float, float], ...]]) -> dict[float, dict[str, PaperStat]]:
    return {
        threshold: {m: PaperStat(mean, sd) for m, (mean, sd) in zip(methods, cells, strict=True)}
        for threshold, cells in rows.items()
    }


PAPER_RESULTS: dict[str, PaperResults] = {
    "four_rooms": PaperResults(
        domain="four_rooms",
        metric="steps",
        window=1,
        time_to_threshold=_table(
            ("HRS", "RRS", "SARSA", "NRS"),
            {
                500: ((2.68, 1.86), (2.91, 2.10), (3.93, 3.07), (5.78, 6.39)),
                300: ((5.06, 3.05), (5.60, 3.61), (6.68, 4.29), (10.4, 9.17)),
                100: ((17.3, 7.92), (18.6, 7.89), (26.4, 11.0), (38.3, 47.1)),
                50: ((33.0, 10.2), (36.3, 11.0), (51.8, 16.2), (59.6, 45.8)),
            },
        ),
        asymptotic_window=(990, 1000),
        notes=(
            "100 learnings per subgoal pattern, 1,000 episodes each.",
            "Asymptotic performance (steps, episodes 990-1000): no significant difference between methods.",
        ),
    ),
    "pinball": PaperResults(
        domain="pinball",
        metric="steps",
        window=10,
        time_to_threshold=_table(
            ("HRS", "RRS", "AC", "NRS"),
            {
                3000: ((21.2, 39.8), (34.6, 48.4), (51.7, 67.1), (40.0, 50.7)),
                2000: ((26.8, 40.4), (48.7, 54.2), (70.2, 77.8), (59.0, 59.0)),
                1000: ((56.7, 58.5), (89.1, 67.9), (101.0, 71.4), (93.0, 70.1)),
                500: ((115.3, 66.4), (147.3, 64.7), (163.0, 54.8), (157.0, 61.6)),
            },
        ),
        learnings=100,
    ),
    "fetch": PaperResults(
        domain="fetch",
        metric="success",
        window=1,
        time_to_threshold={},
        asymptotic={"HRS": 0.67, "DDPG": 0.63, "NRS": 0.49, "RRS": 0.43},
        asymptotic_window=(190, 200),
        learnings=5,
        notes=("Success rate 0.6 reached 30 epochs earlier with HRS than with DDPG.",),
    ),
}


def paper_results(domain: str) -> PaperResults | None:
    """The paper's results for ``domain``, or None if the paper has none for it.

    Examples:
        >>> paper_results("four_rooms").time_to_threshold[500]["HRS"]
        PaperStat(mean=2.68, sd=1.86)
        >>> paper_results("toy") is None
        True
    """
    return PAPER_RESULTS.get(domain)
