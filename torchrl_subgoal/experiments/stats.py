"""Statistics over learning curves: the paper's, and robust ones beyond it.

Curves are arrays ``[n_learners, n_episodes]`` of one metric (e.g. steps per
episode). Everything is vectorised over learners and episodes.

The paper (Okudo & Yamada 2021) reports, per method: time to threshold (episodes
until the metric, smoothed by a moving average for PinBall, first crosses a
threshold), asymptotic performance (mean over the final episodes), a one-way
ANOVA across methods, pairwise follow-up tests with Holm-Bonferroni correction, and
learning curves with standard-error bands.

Beyond the paper, following Agarwal et al. (2021), "Deep Reinforcement Learning at
the Edge of the Statistical Precipice" (NeurIPS): the interquartile mean (IQM)
with stratified-bootstrap confidence intervals, and the probability of improvement.
"""

from __future__ import annotations

import gc
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from itertools import combinations

import numpy as np
import numpy.typing as npt
from scipy import stats as sps
from statsmodels.stats.multitest import multipletests

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


def mean_and_sem(curves: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Mean across learners (axis 0) and its standard error (0 with a single learner).

    Examples:
        >>> mean, sem = mean_and_sem([[1.0, 2.0], [3.0, 2.0]])
        >>> mean.tolist(), sem.tolist()
        ([2.0, 2.0], [1.0, 0.0])
    """
    x = np.asarray(curves, dtype=np.float64)
    mean = x.mean(axis=0)
    if x.shape[0] < 2:
        return mean, np.zeros_like(mean)
    return mean, x.std(axis=0, ddof=1) / np.sqrt(x.shape[0])


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


def iqm(scores: ArrayLike, axis: int = -1) -> FloatArray:
    """Interquartile mean: the mean of the middle 50% of scores.

    ``floor(n / 4)`` scores are dropped from each end, as
    ``scipy.stats.trim_mean(scores, 0.25)`` does (sorting is faster on bootstrap batches).

    Examples:
        >>> float(iqm([1, 2, 3, 4, 5, 6, 7, 100]))
        4.5
    """
    x = np.sort(np.asarray(scores, dtype=np.float64), axis=axis)
    n = x.shape[axis]
    if n == 0:
        raise ValueError("iqm of no scores")
    cut = n // 4
    return np.asarray(np.take(x, np.arange(cut, n - cut), axis=axis).mean(axis=axis))


def stratified_bootstrap_ci(
    scores: ArrayLike,
    strata: ArrayLike | None = None,
    *,
    statistic: Callable[..., FloatArray] = iqm,
    n_boot: int = 2000,
    confidence: float = 0.95,
    seed: int = 0,
) -> tuple[float, float]:
    """Percentile confidence interval of ``statistic`` by a stratified bootstrap.

    Each bootstrap sample draws, within every stratum independently and with
    replacement, as many scores as the stratum holds, so the strata keep their
    sizes (as Agarwal et al. 2021 resample runs within each task). A stratum of
    one run cannot vary when resampled within itself, so strata of one run are
    pooled into one stratum (one learner per subgoal pattern would otherwise
    give an interval of zero width).

    Args:
        scores: one score per run, shape ``[n]``.
        strata: a label per run (e.g. its subgoal pattern); None = a single stratum.
        statistic: called as ``statistic(samples, axis=-1)`` on ``[n_boot, n]``.
        n_boot: bootstrap samples.
        confidence: coverage of the interval.
        seed: seed of the resampling; the interval is reproducible given it.

    Examples:
        >>> low, high = stratified_bootstrap_ci(np.arange(100.0), seed=1)
        >>> bool(low < float(iqm(np.arange(100.0))) < high)
        True
    """
    x = np.asarray(scores, dtype=np.float64).ravel()
    if x.size == 0:
        return float("nan"), float("nan")
    labels = np.zeros(x.size, dtype=np.int64) if strata is None else np.asarray(strata).ravel()
    if labels.size != x.size:
        raise ValueError(f"{labels.size} strata labels for {x.size} scores")
    rng = np.random.default_rng(seed)
    _, codes, counts = np.unique(labels, return_inverse=True, return_counts=True)
    codes = np.where(counts[codes] == 1, -1, codes)  # strata of one run: pooled into stratum -1
    parts = []
    for label in np.unique(codes):
        members = np.flatnonzero(codes == label)
        parts.append(members[rng.integers(0, members.size, size=(n_boot, members.size))])
    samples = x[np.concatenate(parts, axis=1)]
    values = np.asarray(statistic(samples, axis=-1), dtype=np.float64)
    tail = 100 * (1 - confidence) / 2
    low, high = np.percentile(values, [tail, 100 - tail])
    return float(low), float(high)


def probability_of_improvement(x: ArrayLike, y: ArrayLike, *, lower_is_better: bool = False) -> float:
    """P(X improves on Y) for a random run of each, counting ties as one half.

    From the definition of Agarwal et al. (2021) for one task:
    ``(1 / (n m)) * sum_i sum_j S(x_i, y_j)`` with ``S = 1`` if ``x_i`` is better than
    ``y_j``, ``1/2`` if equal, ``0`` otherwise. Computed from mid-ranks of the pooled
    sample (the Mann-Whitney U statistic), in ``O((n + m) log(n + m))``.

    Examples:
        >>> probability_of_improvement([3, 4], [1, 2])
        1.0
        >>> probability_of_improvement([1, 2], [1, 2])
        0.5
    """
    a = np.asarray(x, dtype=np.float64).ravel()
    b = np.asarray(y, dtype=np.float64).ravel()
    if a.size == 0 or b.size == 0:
        return float("nan")
    ranks = sps.rankdata(np.concatenate([a, b]))
    greater = ranks[: a.size].sum() - a.size * (a.size + 1) / 2  # pairs x > y, ties halved
    p_greater = greater / (a.size * b.size)
    return float(1 - p_greater if lower_is_better else p_greater)
