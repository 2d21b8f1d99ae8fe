"""Statistics over learning curves: the paper's, and robust ones beyond it.

Curves are arrays ``[n_learners, n_episodes]`` of one metric (e.g. steps per
episode). Everything is vectorised over learners and episodes.

The paper (Okudo & Yamada 2021) reports, per method: time to threshold (episodes
until the metric, smoothed by a moving average for PinBall, first crosses a
threshold), asymptotic performance (mean over the final episodes), a one-way
ANOVA across methods, pairwise follow-up tests with Holm-Bonferroni correction, and
learning curves with standard-error bands (ours: stratified-bootstrap bands).

Beyond the paper, following Agarwal et al. (2021), "Deep Reinforcement Learning at
the Edge of the Statistical Precipice" (NeurIPS), computed by their library, rliable:
the interquartile mean (IQM) with stratified-bootstrap confidence intervals, the
probability of improvement and performance profiles. This module arranges the
learners for it (:func:`runs_by_task`) and seeds its bootstrap.
"""

from __future__ import annotations

import gc
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from itertools import combinations
from typing import Any

import numpy as np
import numpy.typing as npt
from rliable import library, metrics
from scipy import stats as sps
from statsmodels.stats.multitest import multipletests

__all__ = [
    "PairwiseResult",
    "TestResult",
    "ThresholdTimes",
    "anova",
    "asymptotic_performance",
    "bootstrap_ci",
    "curve_band",
    "iqm",
    "moving_average",
    "pairwise_tests",
    "performance_profile",
    "probability_of_improvement",
    "runs_by_task",
    "stratified_bootstrap_ci",
    "time_to_threshold",
]

FloatArray = npt.NDArray[np.float64]
ArrayLike = npt.ArrayLike


def moving_average(curves: ArrayLike, window: int) -> FloatArray:
    """Trailing moving average over full windows along the last axis.

    Entry ``j`` of the result is the mean of episodes ``j .. j + window - 1`` (0-based),
    so a curve of ``E`` episodes gives ``E - window + 1`` values; ``window=1`` returns the
    curve unchanged.

    Examples:
        >>> moving_average([[1, 2, 3, 4]], 2).tolist()
        [[1.5, 2.5, 3.5]]
    """
    x = np.asarray(curves, dtype=np.float64)
    if window < 1:
        raise ValueError("window must be >= 1")
    if window > x.shape[-1]:
        raise ValueError(f"window {window} is longer than the {x.shape[-1]} episodes")
    if window == 1:
        return x
    cumulative = np.cumsum(x, axis=-1)
    zero = np.zeros((*x.shape[:-1], 1))
    cumulative = np.concatenate([zero, cumulative], axis=-1)
    return (cumulative[..., window:] - cumulative[..., :-window]) / window


@dataclass(frozen=True)
class ThresholdTimes:
    """Result of :func:`time_to_threshold`.

    Attributes:
        episodes: per learner, the 1-based episode at which the threshold was first
            crossed (with a moving average, the last episode of the first window that
            crosses it); learners that never cross it get ``n_episodes``.
        reached: per learner, whether the threshold was crossed at all.
        n_episodes: episodes per learner.

    Examples:
        >>> times = time_to_threshold([[9, 7, 4, 2], [9, 9, 9, 9]], 5)
        >>> times.n_episodes, times.n_not_reached
        (4, 1)
    """

    episodes: npt.NDArray[np.int64]
    reached: npt.NDArray[np.bool_]
    n_episodes: int

    @property
    def n_not_reached(self) -> int:
        """How many learners never crossed the threshold (counted as ``n_episodes``)."""
        return int((~self.reached).sum())


def time_to_threshold(
    curves: ArrayLike, threshold: float, *, window: int = 1, lower_is_better: bool = True
) -> ThresholdTimes:
    """Episode at which each learner's (smoothed) metric first crosses ``threshold``.

    "Crosses" is strict: falls below the threshold when lower is better, rises above it
    otherwise.

    Args:
        curves: ``[n_learners, n_episodes]``.
        threshold: the level to cross.
        window: moving-average window (1 = raw curve; the paper uses 10 for PinBall).
        lower_is_better: direction of improvement of the metric.

    Examples:
        >>> t = time_to_threshold([[9, 7, 4, 2], [9, 9, 9, 9]], 5)
        >>> t.episodes.tolist(), t.reached.tolist()
        ([3, 4], [True, False])
    """
    x = np.asarray(curves, dtype=np.float64)
    if x.ndim != 2:
        raise ValueError(f"curves must be [n_learners, n_episodes], got shape {x.shape}")
    smoothed = moving_average(x, window)
    crossed = smoothed < threshold if lower_is_better else smoothed > threshold
    reached = np.asarray(crossed.any(axis=1), dtype=bool)
    first = crossed.argmax(axis=1) + window  # 1-based episode closing the first window
    n_episodes = x.shape[1]
    episodes = np.where(reached, first, n_episodes).astype(np.int64)
    return ThresholdTimes(episodes, reached, n_episodes)


def asymptotic_performance(curves: ArrayLike, window: Sequence[int]) -> FloatArray:
    """Per-learner mean of the metric over the final window of episodes.

    Args:
        curves: ``[n_learners, n_episodes]``.
        window: ``(start, stop)`` as a Python slice of 0-based episode indices, i.e.
            1-based episodes ``start + 1 .. stop``: ``(990, 1000)`` is the last 10 of 1000.

    Examples:
        >>> asymptotic_performance([[5, 4, 3, 1]], (2, 4)).tolist()
        [2.0]
    """
    x = np.asarray(curves, dtype=np.float64)
    start, stop = (int(v) for v in window)
    if not 0 <= start < stop <= x.shape[-1]:
        raise ValueError(f"asymptotic window {[start, stop]} does not fit {x.shape[-1]} episodes")
    return x[..., start:stop].mean(axis=-1)


@dataclass(frozen=True)
class TestResult:
    """A test statistic and its p-value (NaN when the test is undefined, e.g. constant data).

    Examples:
        >>> result = anova({"a": [1, 2, 3], "b": [7, 8, 9]})
        >>> isinstance(result, TestResult), result.pvalue < 0.01
        (True, True)
    """

    statistic: float
    pvalue: float


@dataclass(frozen=True)
class PairwiseResult:
    """One pairwise comparison of :func:`pairwise_tests`.

    Examples:
        >>> pair = pairwise_tests({"a": [1, 2, 3, 4], "b": [9, 8, 9, 8]})[0]
        >>> pair.first, pair.second, bool(pair.pvalue_adjusted >= pair.pvalue)
        ('a', 'b', True)
    """

    first: str
    second: str
    statistic: float
    pvalue: float
    pvalue_adjusted: float
    reject: bool


def anova(groups: Mapping[str, ArrayLike]) -> TestResult:
    """One-way ANOVA across groups (:func:`scipy.stats.f_oneway`).

    Examples:
        >>> round(anova({"a": [1, 2, 3], "b": [4, 5, 6]}).statistic, 2)
        13.5
    """
    samples = [np.asarray(v, dtype=np.float64) for v in groups.values()]
    if len(samples) < 2 or any(s.size < 2 for s in samples):
        return TestResult(float("nan"), float("nan"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # constant input: the result is NaN and says so
        result = sps.f_oneway(*samples)
    return TestResult(float(result.statistic), float(result.pvalue))


def pairwise_tests(
    groups: Mapping[str, ArrayLike], *, alpha: float = 0.05, correction: str = "holm"
) -> list[PairwiseResult]:
    """Welch's t-test for every pair of groups, p-values corrected for multiplicity.

    Args:
        groups: name -> sample.
        alpha: family-wise error rate for the ``reject`` flags.
        correction: any method of :func:`statsmodels.stats.multitest.multipletests`;
            ``"holm"`` (Holm-Bonferroni) as in the paper.

    Examples:
        >>> [r.reject for r in pairwise_tests({"a": [1, 2, 3, 4], "b": [9, 8, 9, 8]})]
        [True]
    """
    names = list(groups)
    samples = {k: np.asarray(v, dtype=np.float64) for k, v in groups.items()}
    pairs = list(combinations(names, 2))
    stats_, pvalues = [], []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for a, b in pairs:
            result = sps.ttest_ind(samples[a], samples[b], equal_var=False)
            stats_.append(float(result.statistic))
            pvalues.append(float(result.pvalue))
    p = np.asarray(pvalues)
    finite = np.isfinite(p)
    adjusted = np.full_like(p, np.nan)
    reject = np.zeros(p.shape, dtype=bool)
    if finite.any():
        # statsmodels' Holm step calls gc.collect(); with torch loaded a full collection takes
        # a quarter of a second, so keep the objects alive now out of its way.
        gc.freeze()
        try:
            reject[finite], adjusted[finite], _, _ = multipletests(p[finite], alpha=alpha, method=correction)
        finally:
            gc.unfreeze()
    return [
        PairwiseResult(a, b, s, pv, float(adj), bool(rej))
        for (a, b), s, pv, adj, rej in zip(pairs, stats_, p, adjusted, reject, strict=True)
    ]


def runs_by_task(scores: ArrayLike, strata: ArrayLike | None = None) -> FloatArray:
    """Scores of runs (``[n, ...]``: one per run, or a curve per run) as rliable's ``[runs, tasks, ...]``: a
    column per stratum (the runs' subgoal patterns) when every stratum holds the same number (at least 2)
    of runs, else one column.

    rliable's stratified bootstrap resamples the runs of each task (column) on their own, as Agarwal et
    al. (2021) resample runs within each task. A stratum of one run could not vary when resampled within
    itself (one learner per pattern would give an interval of zero width), and rliable needs as many runs
    in every column: in those cases the runs form one stratum.

    Examples:
        >>> runs_by_task([1.0, 2.0, 3.0, 4.0], ["a", "b", "a", "b"]).tolist()
        [[1.0, 2.0], [3.0, 4.0]]
        >>> runs_by_task([1.0, 2.0, 3.0], ["a", "b", "c"]).tolist()  # one run per pattern: one stratum
        [[1.0], [2.0], [3.0]]
        >>> runs_by_task(np.zeros((4, 7)), ["a", "b", "a", "b"]).shape  # curves: [runs, tasks, points]
        (2, 2, 7)
    """
    x = np.asarray(scores, dtype=np.float64)
    if x.ndim == 0:
        x = x.reshape(1)
    if strata is None:
        return x[:, None]
    labels = np.asarray(strata).ravel()
    if labels.size != x.shape[0]:
        raise ValueError(f"{labels.size} strata labels for {x.shape[0]} runs")
    names, counts = np.unique(labels, return_counts=True)
    if counts.min() < 2 or counts.min() != counts.max():
        return x[:, None]
    return np.stack([x[labels == name] for name in names], axis=1)


def iqm(scores: ArrayLike) -> float:
    """Interquartile mean: the mean of the middle 50% of scores (rliable's ``aggregate_iqm``: ``floor(n / 4)``
    scores dropped from each end).

    Examples:
        >>> iqm([1, 2, 3, 4, 5, 6, 7, 100])
        4.5
    """
    x = np.asarray(scores, dtype=np.float64)
    if x.size == 0:
        raise ValueError("iqm of no scores")
    return float(metrics.aggregate_iqm(x))


def _iqm_of_replicate(matrix: FloatArray) -> FloatArray:
    """rliable's ``aggregate_iqm`` (scipy's ``trim_mean`` at 25%, over every entry) as one sort and a mean:
    the same trimmed set, so the same number (to the last bits of the sum), for the bootstrap's thousands
    of replicates, where ``trim_mean``'s own overhead would dominate.

    Examples:
        >>> m = np.random.default_rng(0).normal(size=(9, 3))
        >>> bool(np.isclose(_iqm_of_replicate(m)[0], metrics.aggregate_iqm(m)))
        True
    """
    x = np.sort(matrix, axis=None)
    cut = int(0.25 * x.size)
    return np.array([x[cut : x.size - cut].mean()])


@contextmanager
def _seeded(seed: int) -> Iterator[None]:
    """numpy's global random state seeded for the block, then restored: rliable's stratified bootstrap draws
    its resampling indices from it (``np.random.choice``)."""
    state = np.random.get_state()
    np.random.seed(seed % 2**32)
    try:
        yield
    finally:
        np.random.set_state(state)


def bootstrap_ci(
    matrix: FloatArray,
    statistic: Callable[[FloatArray], Any],
    *,
    n_boot: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
) -> FloatArray:
    """Percentile confidence interval of ``statistic`` by rliable's stratified bootstrap (runs resampled
    within each task), reproducible given ``seed``: ``[2, ...]``, the lower then the upper bounds.

    Args:
        matrix: ``[runs, tasks, ...]`` scores (:func:`runs_by_task`; a trailing axis of curve points).
        statistic: ``statistic(matrix) -> array``, e.g. rliable's ``aggregate_iqm``.
        n_boot: bootstrap samples.
        confidence: coverage of the interval.
        seed: seed of the resampling.

    Examples:
        >>> low, high = bootstrap_ci(runs_by_task(np.arange(100.0)), lambda m: np.array([iqm(m)]), seed=1)
        >>> bool(low[0] < iqm(np.arange(100.0)) < high[0])
        True
    """
    with _seeded(seed), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # constant resamples: scipy warns, the interval is a point
        _, intervals = library.get_interval_estimates(
            {"x": matrix}, statistic, reps=n_boot, confidence_interval_size=confidence
        )
    return np.asarray(intervals["x"], dtype=np.float64)


def stratified_bootstrap_ci(
    scores: ArrayLike,
    strata: ArrayLike | None = None,
    *,
    n_boot: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
) -> tuple[float, float]:
    """Percentile confidence interval of the IQM of ``scores``, by rliable's stratified bootstrap over the
    strata of :func:`runs_by_task` (the learners' subgoal patterns).

    Args:
        scores: one score per run, shape ``[n]``.
        strata: a label per run (e.g. its subgoal pattern); None = a single stratum.
        n_boot: bootstrap samples.
        confidence: coverage of the interval.
        seed: seed of the resampling; the interval is reproducible given it.

    Examples:
        >>> low, high = stratified_bootstrap_ci(np.arange(100.0), seed=1)
        >>> bool(low < iqm(np.arange(100.0)) < high)
        True
    """
    x = np.asarray(scores, dtype=np.float64).ravel()
    if x.size == 0:
        return float("nan"), float("nan")
    interval = bootstrap_ci(
        runs_by_task(x, strata),
        _iqm_of_replicate,
        n_boot=n_boot,
        confidence=confidence,
        seed=seed,
    )
    return float(interval[0, 0]), float(interval[1, 0])


def probability_of_improvement(x: ArrayLike, y: ArrayLike, *, lower_is_better: bool = False) -> float:
    """P(X improves on Y) for a random run of each, ties counting one half: rliable's
    ``probability_of_improvement`` on one task (the Mann-Whitney U statistic over ``n m`` pairs).

    Examples:
        >>> probability_of_improvement([3, 4], [1, 2])
        1.0
        >>> probability_of_improvement([1, 2], [1, 2])
        0.5
        >>> probability_of_improvement([1, 2], [3, 4], lower_is_better=True)
        1.0
    """
    a = np.asarray(x, dtype=np.float64).ravel()
    b = np.asarray(y, dtype=np.float64).ravel()
    if a.size == 0 or b.size == 0:
        return float("nan")
    sign = -1.0 if lower_is_better else 1.0
    return float(metrics.probability_of_improvement(sign * a[:, None], sign * b[:, None]))


def performance_profile(
    scores: Mapping[str, ArrayLike],
    strata: Mapping[str, ArrayLike],
    taus: ArrayLike,
    *,
    lower_is_better: bool = False,
    n_boot: int = 500,
    confidence: float = 0.95,
    seed: int = 0,
) -> dict[str, tuple[FloatArray, FloatArray]]:
    """rliable's performance profiles (score distributions): for each method, the fraction of runs whose
    score is better than each ``tau`` (above it, or below it when lower is better), with its stratified
    bootstrap interval (``[2, len(taus)]``).

    Examples:
        >>> profile, band = performance_profile({"A": [1.0, 2.0, 3.0, 4.0]}, {"A": None}, [0.5, 2.5])["A"]
        >>> profile.tolist(), band.shape
        ([1.0, 0.5], (2, 2))
    """
    tau = np.asarray(taus, dtype=np.float64)

    def fraction(matrix: FloatArray) -> FloatArray:
        values = matrix.reshape(-1, 1)
        return np.mean(values < tau if lower_is_better else values > tau, axis=0)

    out = {}
    for k, (name, x) in enumerate(scores.items()):
        matrix = runs_by_task(x, strata.get(name))
        band = bootstrap_ci(matrix, fraction, n_boot=n_boot, confidence=confidence, seed=seed + k)
        out[name] = (fraction(matrix), band)
    return out


def curve_band(
    curves: ArrayLike,
    strata: ArrayLike | None = None,
    *,
    points: int = 100,
    n_boot: int = 500,
    confidence: float = 0.95,
    seed: int = 0,
) -> tuple[npt.NDArray[np.int64], FloatArray, FloatArray]:
    """The mean learning curve across learners and its stratified-bootstrap band (rliable, runs resampled
    within each subgoal pattern at each point), at ``points`` evenly spaced columns at most.

    Args:
        curves: ``[n_learners, n_columns]``.
        strata: each learner's stratum (its subgoal pattern), as in :func:`runs_by_task`.
        points: the most columns the band is computed at (the bootstrap costs ``n_boot`` x points).
        n_boot: bootstrap samples.
        confidence: coverage of the band.
        seed: seed of the resampling.

    Returns:
        The columns (0-based), the mean there, and the band ``[2, columns]`` (lower, upper).

    Examples:
        >>> columns, mean, band = curve_band(np.arange(12.0).reshape(4, 3), points=2, n_boot=100)
        >>> columns.tolist(), mean.tolist(), band.shape
        ([0, 2], [4.5, 6.5], (2, 2))
    """
    x = np.asarray(curves, dtype=np.float64)
    columns = np.unique(np.linspace(0, x.shape[1] - 1, min(points, x.shape[1])).round().astype(np.int64))
    matrix = runs_by_task(x[:, columns], strata)
    mean = matrix.mean(axis=(0, 1))
    if x.shape[0] < 2:
        return columns, mean, np.stack([mean, mean])
    band = bootstrap_ci(matrix, lambda m: m.mean(axis=(0, 1)), n_boot=n_boot, confidence=confidence, seed=seed)
    return columns, mean, band
