"""Statistics: time to threshold, asymptotic window, tests, IQM, bootstrap, P(improvement)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats as sps
from statsmodels.stats.multitest import multipletests

from torchrl_subgoal.experiments import stats


def test_moving_average_matches_convolution() -> None:
    x = np.random.default_rng(0).normal(size=(3, 20))
    expected = np.stack([np.convolve(row, np.ones(4) / 4, mode="valid") for row in x])
    np.testing.assert_allclose(stats.moving_average(x, 4), expected)
    np.testing.assert_array_equal(stats.moving_average(x, 1), x)
    with pytest.raises(ValueError, match="longer"):
        stats.moving_average(x, 21)


def test_time_to_threshold_on_hand_made_curves() -> None:
    curves = np.array(
        [
            [900, 600, 450, 200, 40, 30],  # below 500 at episode 3, below 50 at 5
            [900, 900, 500, 499, 45, 20],  # exactly 500 is not below: episode 4
            [900, 900, 900, 900, 900, 900],  # never
        ]
    )
    t500 = stats.time_to_threshold(curves, 500)
    assert t500.episodes.tolist() == [3, 4, 6] and t500.reached.tolist() == [True, True, False]
    assert t500.n_not_reached == 1 and t500.n_episodes == 6
    assert stats.time_to_threshold(curves, 50).episodes.tolist() == [5, 5, 6]


def test_time_to_threshold_with_moving_average() -> None:
    curves = np.array([[10.0, 8, 6, 4, 2, 0], [10, 0, 10, 0, 10, 0]])
    # window 2: [9, 7, 5, 3, 1] and [5, 5, 5, 5, 5]; "< 5" first for the window of
    # episodes 4-5, so at episode 5; the second learner's average never falls below 5
    times = stats.time_to_threshold(curves, 5, window=2)
    assert times.episodes.tolist() == [5, 6] and times.reached.tolist() == [True, False]
    # without smoothing the oscillating learner crosses at once
    assert stats.time_to_threshold(curves, 5).episodes.tolist() == [4, 2]


def test_time_to_threshold_when_higher_is_better() -> None:
    success = np.array([[0.1, 0.5, 0.7, 0.9], [0.6, 0.6, 0.6, 0.6]])
    times = stats.time_to_threshold(success, 0.6, lower_is_better=False)
    assert times.episodes.tolist() == [3, 4] and times.reached.tolist() == [True, False]


def test_asymptotic_window_is_a_slice_of_zero_based_episodes() -> None:
    curves = np.arange(20.0).reshape(2, 10)
    np.testing.assert_allclose(stats.asymptotic_performance(curves, (7, 10)), [8.0, 18.0])
    with pytest.raises(ValueError, match="does not fit"):
        stats.asymptotic_performance(curves, (5, 11))


def test_anova_matches_scipy_and_a_hand_computed_f() -> None:
    groups = {"a": [1.0, 2, 3], "b": [4.0, 5, 6], "c": [7.0, 8, 9.5]}
    result = stats.anova(groups)
    direct = sps.f_oneway(*groups.values())
    assert result.statistic == pytest.approx(direct.statistic)
    assert result.pvalue == pytest.approx(direct.pvalue)
    # by hand: between-groups SS 13.5 on 1 d.f., within-groups SS 4 on 4 d.f., F = 13.5
    assert stats.anova({"a": [1.0, 2, 3], "b": [4.0, 5, 6]}).statistic == pytest.approx(13.5)
    assert np.isnan(stats.anova({"a": [1.0, 1], "b": [1.0, 1]}).statistic)


def test_pairwise_tests_apply_holm_like_statsmodels() -> None:
    rng = np.random.default_rng(1)
    groups = {name: rng.normal(mu, 1.0, size=30) for name, mu in (("A", 0.0), ("B", 0.3), ("C", 1.5))}
    results = stats.pairwise_tests(groups)
    assert [(r.first, r.second) for r in results] == [("A", "B"), ("A", "C"), ("B", "C")]
    raw = [sps.ttest_ind(groups[r.first], groups[r.second], equal_var=False).pvalue for r in results]
    reject, adjusted, _, _ = multipletests(raw, alpha=0.05, method="holm")
    np.testing.assert_allclose([r.pvalue for r in results], raw)
    np.testing.assert_allclose([r.pvalue_adjusted for r in results], adjusted)
    assert [r.reject for r in results] == reject.tolist()
    # Holm by hand: sorted p times (m, m-1, ...), running maximum, capped at 1
    order = np.argsort(raw)
    by_hand = np.minimum(1, np.maximum.accumulate(np.sort(raw) * np.arange(3, 0, -1)))
    np.testing.assert_allclose(np.asarray([r.pvalue_adjusted for r in results])[order], by_hand)
    assert results[1].reject  # A vs C differ by 1.5 s.d.


def test_iqm_on_known_data_and_against_scipy() -> None:
    assert stats.iqm([1, 2, 3, 4, 5, 6, 7, 100]) == 4.5  # mean of 3, 4, 5, 6
    assert stats.iqm(np.arange(1, 10)) == 5.0  # drops 2 each end: mean of 3..7
    x = np.random.default_rng(2).normal(size=33)
    assert stats.iqm(x) == pytest.approx(sps.trim_mean(x, 0.25))


def test_runs_by_task_arranges_learners_by_pattern() -> None:
    scores, strata = np.arange(6.0), np.array(["b", "a", "b", "a", "b", "a"])
    np.testing.assert_array_equal(stats.runs_by_task(scores, strata), [[1, 0], [3, 2], [5, 4]])
    assert stats.runs_by_task(scores, None).shape == (6, 1)
    assert stats.runs_by_task(scores, np.arange(6)).shape == (6, 1)  # one learner per pattern: one stratum
    assert stats.runs_by_task(scores, np.array(list("aabbbb"))).shape == (6, 1)  # uneven: one stratum
    with pytest.raises(ValueError, match="5 strata labels for 6 runs"):
        stats.runs_by_task(scores, strata[:5])


def test_bootstrap_ci_contains_estimate_and_is_reproducible() -> None:
    scores = np.random.default_rng(3).normal(10, 2, size=200)
    strata = np.repeat(["p1", "p2", "p3", "p4"], 50)
    state = np.random.get_state()
    low, high = stats.stratified_bootstrap_ci(scores, strata, seed=5)
    assert np.random.get_state()[1].tolist() == state[1].tolist()  # the global state is given back
    assert low < stats.iqm(scores) < high
    assert (low, high) == stats.stratified_bootstrap_ci(scores, strata, seed=5)
    assert (low, high) != stats.stratified_bootstrap_ci(scores, strata, seed=6)
    wider = stats.stratified_bootstrap_ci(scores, strata, seed=5, confidence=0.99)
    assert wider[0] < low and wider[1] > high


def test_bootstrap_resamples_within_each_pattern() -> None:
    # each pattern constant: a stratified resample always holds two 0s and two 10s
    matrix = stats.runs_by_task(np.array([0.0, 10.0, 0.0, 10.0]), np.array(["a", "b", "a", "b"]))
    np.testing.assert_array_equal(stats.bootstrap_ci(matrix, lambda m: np.array([m.mean()])), [[5.0], [5.0]])
    low, high = stats.bootstrap_ci(stats.runs_by_task(np.array([0.0, 10.0, 0.0, 10.0])), lambda m: np.array([m.mean()]))
    assert low[0] < 5.0 < high[0]  # unstratified, the mix varies


def test_curve_band_brackets_the_mean() -> None:
    curves = np.random.default_rng(5).normal(size=(12, 300)).cumsum(axis=1)
    columns, mean, band = stats.curve_band(curves, np.repeat(["a", "b", "c"], 4), points=50, n_boot=200)
    assert columns[0] == 0 and columns[-1] == 299 and len(columns) == 50
    np.testing.assert_allclose(mean, curves[:, columns].mean(axis=0))
    assert np.all(band[0] <= mean + 1e-12) and np.all(mean <= band[1] + 1e-12) and np.any(band[0] < band[1])


def test_performance_profile_counts_learners_beyond_each_tau() -> None:
    profile, band = stats.performance_profile({"A": [1.0, 2.0, 3.0, 4.0]}, {}, [0.0, 2.5, 5.0], n_boot=100)["A"]
    np.testing.assert_array_equal(profile, [1.0, 0.5, 0.0])
    low = stats.performance_profile({"A": [1.0, 2.0, 3.0, 4.0]}, {}, [0.0, 2.5, 5.0], lower_is_better=True)["A"][0]
    np.testing.assert_array_equal(low, [0.0, 0.5, 1.0])
    assert band.shape == (2, 3) and band[0, 1] <= 0.5 <= band[1, 1]


def test_probability_of_improvement() -> None:
    assert stats.probability_of_improvement([5, 6, 7], [1, 2, 3]) == 1.0
    assert stats.probability_of_improvement([1, 2, 3], [5, 6, 7]) == 0.0
    assert stats.probability_of_improvement([1, 2, 3], [1, 2, 3]) == 0.5
    assert stats.probability_of_improvement([1, 2, 3], [5, 6, 7], lower_is_better=True) == 1.0
    rng = np.random.default_rng(4)
    x, y = rng.integers(0, 5, 40), rng.integers(0, 5, 30)  # many ties
    pairs = (x[:, None] > y[None, :]) + 0.5 * (x[:, None] == y[None, :])
    assert stats.probability_of_improvement(x, y) == pytest.approx(pairs.mean())
    assert stats.probability_of_improvement(x, y, lower_is_better=True) == pytest.approx(1 - pairs.mean())
