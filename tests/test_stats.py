"""The statistics of offrl_jax.run.stats against hand-computed cases: IQM, censored updates-to-threshold, the speed-up
and its bootstrap interval, the probability of improvement, the flat-trend test, performance profiles."""
import numpy as np
import pytest

from offrl_jax.run import stats


def test_iqm_trims_a_quarter_at_each_end():
    assert stats.iqm(np.array([1.0, 2, 3, 4])) == 2.5  # int(0.25 * 4) = 1 trimmed each side: (2 + 3) / 2
    assert stats.iqm(np.array([0.0, 10, 20, 30, 1000])) == 20  # the outlier and 0 go: (10 + 20 + 30) / 3
    assert stats.iqm(np.array([3.0, 1, 2])) == 2  # int(0.75) = 0 trimmed: the mean
    assert stats.iqm(np.array([[1.0, 2, 3, 4], [5, 5, 5, 5]]), axis=-1).tolist() == [2.5, 5.0]


def test_first_reach_counts_a_seed_that_never_gets_there_at_the_budget():
    updates = np.array([1000, 2000, 3000, 4000])
    scores = np.array([[10, 50, 40, 60],  # first at or above 50: 2000 (it dips later; the first crossing counts)
                       [10, 20, 30, 40],  # never: censored at 4000
                       [55, 0, 0, 0],  # at the first evaluation
                       [10, np.nan, np.nan, np.nan]])  # diverged before reaching it: censored
    reach, censored = stats.first_reach(updates, scores, 50.0)
    assert reach.tolist() == [2000, 4000, 1000, 4000]
    assert censored.tolist() == [False, True, False, True]


def test_speedup_is_the_ratio_of_mean_updates_with_a_stratified_interval():
    scratch = np.array([60_000, 70_000, 50_000.0])
    pretrained = np.array([10_000, 20_000, 10_000.0])
    e = stats.speedup(scratch, pretrained)
    assert e.value == pytest.approx(60_000 / (40_000 / 3))  # 4.5
    # the percentile interval lies within the ratios the resamples can make: min(scratch) / max(pretrained) ...
    assert 50_000 / 20_000 <= e.low <= e.value <= e.high <= 70_000 / 10_000
    assert stats.speedup(scratch, pretrained) == e  # a fixed seed: the same interval every time
    # by hand for a case whose resample distribution is small enough to enumerate: arms [a, b] and [c]
    # (one value: no interval), and a degenerate one (every resample equal: the point itself)
    assert stats.speedup(np.array([4.0, 8.0]), np.array([2.0])) == stats.Estimate(3.0)
    assert stats.speedup(np.array([4.0, 4.0]), np.array([2.0, 2.0])) == stats.Estimate(2.0, 2.0, 2.0)


def test_the_bootstrap_interval_of_a_mean_matches_the_enumerated_resamples():
    """Two values a, b: a resample mean is a, (a+b)/2 or b with probabilities 1/4, 1/2, 1/4, so the 2.5 and 97.5
    percentiles of 10,000 resamples are a and b."""
    e = stats.interval([np.array([2.0, 6.0])], stats.mean)
    assert (e.value, e.low, e.high) == (4.0, 2.0, 6.0)
    # and a sample of size 3: with values 0, 0, 3 the mean is 0 with probability (2/3)^3 = 0.30, so the 2.5 %
    # percentile is 0; it is 3 only with probability 1/27 = 0.037 (> 2.5 %), so the 97.5 % percentile is 3
    e = stats.interval([np.array([0.0, 0.0, 3.0])], stats.mean)
    assert (e.low, e.high) == (0.0, 3.0)


def test_non_finite_values_are_left_out_and_too_few_give_no_interval():
    e = stats.interval([np.array([1.0, np.nan, 3.0])], stats.mean)
    assert e.value == 2.0 and e.low is not None
    assert stats.interval([np.array([5.0])], stats.mean) == stats.Estimate(5.0)  # one seed: the value alone
    assert np.isnan(stats.interval([np.array([np.nan, np.nan])], stats.mean).value)
    assert stats.Estimate(5.0).text() == "5.0" and stats.Estimate(5.0, 4.0, 6.5).text() == "5.0 [4.0, 6.5]"
    assert stats.Estimate(float("nan")).text() == "n/a"


def test_probability_of_improvement_by_hand():
    x, y = np.array([3.0, 5.0]), np.array([1.0, 3.0, 6.0])
    # pairs (3,1) > ; (3,3) tie ; (3,6) < ; (5,1) > ; (5,3) > ; (5,6) < : (3 + 0.5) / 6
    assert stats.probability_of_improvement(x, y).value == pytest.approx(3.5 / 6)
    assert stats.probability_of_improvement(np.array([9.0, 8]), np.array([1.0, 2])) == stats.Estimate(1.0, 1.0, 1.0)
    # over tasks: the mean of each task's probability
    pairs = [(x, y), (np.array([1.0, 1]), np.array([2.0, 2]))]
    assert stats.aggregate_poi(pairs).value == pytest.approx((3.5 / 6 + 0.0) / 2)


def test_pooled_iqm_takes_every_run_of_every_task():
    a, b = np.array([1.0, 2, 3]), np.array([5.0, 6, 7, 8])
    # all seven runs: 1 2 3 5 6 7 8, int(1.75) = 1 trimmed each side: (2 + 3 + 5 + 6 + 7) / 5
    e = stats.interval([a, b], stats.pooled(stats.iqm))
    assert e.value == pytest.approx(4.6) and 1 <= e.low <= e.value <= e.high <= 8


def test_a_flat_trend_must_be_flat_within_five_percent_not_merely_noisy():
    flat = np.array([[90, 91, 90, 89, 90, 91, 90, 90, 91, 90]] * 3, dtype=float) + np.arange(3)[:, None]
    trend, is_flat = stats.trend_is_flat(flat)
    # k = 2 evaluations per window: the last (91, 90) minus the two before (90, 90) = 0.5 for every seed, inside
    # the margin max(5 % of ~91, 1)
    assert (trend.value, trend.low, trend.high) == (0.5, 0.5, 0.5) and is_flat
    climbing = np.tile(np.linspace(10, 100, 10), (3, 1))
    trend, is_flat = stats.trend_is_flat(climbing)
    assert trend.value == pytest.approx(20.0) and not is_flat  # (90 + 100) / 2 - (70 + 80) / 2
    # noisy seeds whose interval holds 0 but is wide are not flat: a change of -30 or +30 averages to 0
    noisy = np.array([[50, 50, 50, 50, 50, 50, 50, 50, 80, 80], [50, 50, 50, 50, 50, 50, 50, 50, 20, 20]], float)
    trend, is_flat = stats.trend_is_flat(noisy)
    assert trend.value == 0 and trend.low < 0 < trend.high and not is_flat
    assert stats.trend_is_flat(np.ones((2, 1))) == (None, False)  # too few evaluations for two windows


def test_a_running_mean_is_trailing_and_has_none_before_a_full_window():
    scores = np.array([[1, 2, 3, 4, 5], [0, 0, 9, 0, 0]], dtype=float)
    means = stats.running_mean(scores, 3)  # evaluation j averages evaluations j - 2 .. j
    assert np.isnan(means[:, :2]).all()  # the first two have fewer than 3 before them
    assert means[0, 2:].tolist() == [2.0, 3.0, 4.0] and means[1, 2:].tolist() == [3.0, 3.0, 3.0]
    # a NaN (a seed that diverged) spoils the windows that hold it, and only those
    gap = stats.running_mean(np.array([[1, np.nan, 3, 4, 6]]), 2)
    assert np.isnan(gap[0, :3]).all() and gap[0, 3:].tolist() == [3.5, 5.0]
    assert np.isnan(stats.running_mean(scores, 6)).all()  # a window longer than the curve: no mean anywhere
    assert stats.running_mean(scores, 1).tolist() == scores.tolist()


def test_a_sustained_reach_needs_the_running_mean_there_not_one_lucky_evaluation():
    updates = np.array([10, 20, 30, 40, 50, 60])
    scores = np.array([[0, 100, 0, 0, 0, 0],      # one lucky evaluation at 20, then nothing
                       [0, 0, 90, 90, 90, 90]], dtype=float)
    at, censored = stats.first_reach(updates, scores, 90)
    assert at.tolist() == [20, 30] and not censored.any()  # the first evaluation at 90: the lucky one counts
    # window 3: seed 0's means 33.3, 33.3, 0, 0 never reach 90 (censored at the last update, 60); seed 1's are
    # (0 + 0 + 90) / 3 = 30 at 30, 60 at 40, 90 at 50: there at 50, when its last three evaluations average 90
    at, censored = stats.sustained_reach(updates, scores, 90, 3)
    assert at.tolist() == [60, 50] and censored.tolist() == [True, False]


def test_performance_profile_is_the_fraction_above_each_tau():
    profile = stats.performance_profile(np.array([10.0, 50, 90, 90]), np.array([0.0, 50, 89, 90]))
    assert profile.tolist() == [1.0, 0.5, 0.5, 0.0]
