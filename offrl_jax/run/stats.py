"""The statistics every study reports, as pure functions of per-seed numbers (Agarwal et al. 2021, "Deep RL at the
edge of the statistical precipice"; the definitions are rliable's).

- `iqm`: interquartile mean, the mean of the middle 50 % of values (`scipy.stats.trim_mean(x, 0.25)`).
- `interval`: a statistic and its stratified percentile-bootstrap 95 % interval: each sample (one arm of one
  task) is resampled on its own, so samples of different sizes are fine (`scipy.stats.bootstrap`), and a fixed
  `seed` gives the same interval every time.  Fewer than two values in a sample: no interval.
- `first_reach`: per seed, the first evaluation at or above a threshold; a seed that never gets there is censored
  at the budget (counted, never dropped).  `reached_by`: the seeds that got there at or before a given update.
- `score_at`: per seed, the score of one evaluation (the BC level: the score where pre-training hands over).
- `way_from`: the score a fraction of the way from one level to another (the BC-relative thresholds).
- `speedup`: (mean updates of the reference arm) / (mean updates of the improved arm) to a threshold, censored
  seeds at the budget, with its interval; a censored reference seed makes it a lower bound.
- `probability_of_improvement`: P(X > Y) + P(X = Y) / 2 for one draw of each arm (Mann-Whitney U / (n m)).
- `trend_is_flat`: whether a curve's last evaluations are level: the interval of their change within +-5 %.
- `running_mean`, `sustained_reach`: a trailing mean over a window of evaluations, and the first update at which it
  is at or above a threshold (censored like `first_reach`).
- `performance_profile`: the fraction of runs scoring above each tau.

Scores are (S seeds, E evaluations) arrays; NaN marks a seed that diverged and stopped.
"""
from __future__ import annotations

import contextlib
import dataclasses
import math
import warnings
from collections.abc import Callable, Sequence

import numpy as np
import scipy.stats

LEVEL = 0.95
RESAMPLES = 10_000
SEED = 0  # the bootstrap's default random seed: a study's printed intervals are the same every time


@dataclasses.dataclass(frozen=True)
class Estimate:
    """A point estimate with its bootstrap interval (low/high None: too few values for one)."""
    value: float
    low: float | None = None
    high: float | None = None

    def to_json(self) -> dict:
        return {"value": _finite(self.value), "low": _finite(self.low), "high": _finite(self.high)}

    @staticmethod
    def from_json(d: dict) -> Estimate:
        nan = float("nan")
        return Estimate(nan if d.get("value") is None else d["value"], d.get("low"), d.get("high"))

    def text(self, fmt: str = ".1f", suffix: str = "") -> str:
        """'94.7 [91.2, 96.0]', or the value alone when there is no interval, 'n/a' when there is no value."""
        if not math.isfinite(self.value):
            return "n/a"
        if self.low is None or self.high is None:
            return f"{self.value:{fmt}}{suffix}"
        return f"{self.value:{fmt}}{suffix} [{self.low:{fmt}}, {self.high:{fmt}}]"


def _finite(x):
    return None if x is None or not math.isfinite(x) else float(x)


def iqm(x: np.ndarray, axis: int = -1) -> np.ndarray:
    """Interquartile mean along `axis`: trim 25 % of the values at each end (int(0.25 n) of them), average the rest."""
    return scipy.stats.trim_mean(x, 0.25, axis=axis)


def mean(x: np.ndarray, axis: int = -1) -> np.ndarray:
    return np.mean(x, axis=axis)


def interval(samples: Sequence[np.ndarray], statistic: Callable[..., np.ndarray], seed: int = SEED,
             resamples: int = RESAMPLES, level: float = LEVEL) -> Estimate:
    """`statistic(*samples, axis=-1)` and its stratified percentile-bootstrap interval: every sample is resampled
    with replacement on its own (`scipy.stats.bootstrap`, `paired=False`).  Non-finite values are left out first
    (a diverged seed); a sample then empty gives NaN, one with a single value gives the point alone."""
    samples = [np.asarray(s, dtype=float).ravel() for s in samples]
    assert all(s.ndim == 1 for s in samples), [s.shape for s in samples]
    samples = [s[np.isfinite(s)] for s in samples]
    if any(len(s) == 0 for s in samples):
        return Estimate(float("nan"))
    value = float(statistic(*samples, axis=-1))
    if any(len(s) < 2 for s in samples) or not math.isfinite(value):
        return Estimate(value)
    if all(np.all(s == s[0]) for s in samples):  # every resample is the data itself
        return Estimate(value, value, value)
    with np.errstate(divide="ignore", invalid="ignore"):
        res = scipy.stats.bootstrap(samples, statistic, n_resamples=resamples, confidence_level=level,
                                    method="percentile", vectorized=True, axis=-1, rng=np.random.default_rng(seed))
    low, high = float(res.confidence_interval.low), float(res.confidence_interval.high)
    return Estimate(value, low if math.isfinite(low) else None, high if math.isfinite(high) else None)


def fraction_of(score: float, f: float) -> float:
    """f of a score, below it for a negative score too (90 % of -10 is -11): score - (1 - f) |score|."""
    return score - (1 - f) * abs(score)


def first_reach(updates: np.ndarray, scores: np.ndarray, threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """(reach (S,), censored (S,)): per seed the first of `updates` (E,) at which `scores` (S, E) is at or above
    `threshold`; a seed that never is (or diverged first: NaN) is censored at the last update."""
    updates, scores = np.asarray(updates), np.asarray(scores, dtype=float)
    assert updates.ndim == 1 and scores.ndim == 2 and scores.shape[1] == len(updates), (updates.shape, scores.shape)
    assert len(updates), "no evaluations"
    with np.errstate(invalid="ignore"):
        hit = scores >= threshold
    censored = ~hit.any(axis=1)
    reach = np.where(censored, updates[-1], updates[np.argmax(hit, axis=1)])
    return reach, censored


def reached_by(reach: np.ndarray, censored: np.ndarray, update: int) -> np.ndarray:
    """(S,) bool: the seeds of `first_reach`'s (reach, censored) that reached the threshold at or before `update`."""
    return ~np.asarray(censored, dtype=bool) & (np.asarray(reach) <= update)


def score_at(updates: np.ndarray, scores: np.ndarray, update: int) -> np.ndarray:
    """(S,): per seed the score of `scores` (S, E) at the evaluation `update` of `updates` (E,), which must be one."""
    updates = np.asarray(updates)
    (j,) = np.flatnonzero(updates == update)
    return np.asarray(scores, dtype=float)[:, j]


def way_from(start: float, end: float, fraction: float) -> float:
    """The score `fraction` of the way from `start` to `end`: start + fraction (end - start)."""
    return start + fraction * (end - start)


def ratio_of_means(reference: np.ndarray, improved: np.ndarray, axis: int = -1) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.mean(reference, axis=axis) / np.mean(improved, axis=axis)


def speedup(reference_reach: np.ndarray, improved_reach: np.ndarray, seed: int = SEED) -> Estimate:
    """mean(reference) / mean(improved) of per-seed updates (or seconds) to a threshold, with its stratified
    bootstrap interval (the arms resampled separately: their seeds are independent runs)."""
    return interval([reference_reach, improved_reach], ratio_of_means, seed=seed)


def _poi(x: np.ndarray, y: np.ndarray, axis: int = -1) -> np.ndarray:
    gt = (x[..., :, None] > y[..., None, :]).mean(axis=(-1, -2))
    eq = (x[..., :, None] == y[..., None, :]).mean(axis=(-1, -2))
    return gt + 0.5 * eq


def probability_of_improvement(x: np.ndarray, y: np.ndarray, seed: int = SEED) -> Estimate:
    """P(X > Y) + P(X = Y) / 2 of one run of arm x against one of arm y, with its bootstrap interval."""
    return interval([x, y], _poi, seed=seed)


def aggregate_poi(pairs: Sequence[tuple[np.ndarray, np.ndarray]], seed: int = SEED) -> Estimate:
    """The probability of improvement averaged over tasks (rliable's aggregate): `pairs` holds one (x, y) per task;
    every arm of every task is its own stratum of the bootstrap."""
    flat = [a for pair in pairs for a in pair]

    def statistic(*samples, axis=-1):
        return np.mean([_poi(samples[2 * i], samples[2 * i + 1]) for i in range(len(pairs))], axis=0)

    return interval(flat, statistic, seed=seed)


def pooled(statistic: Callable[..., np.ndarray]) -> Callable[..., np.ndarray]:
    """A statistic of all runs of all tasks together (each task a stratum): `pooled(iqm)` is rliable's aggregate
    IQM over a (runs x tasks) score matrix, for any number of runs per task."""
    def of(*samples, axis=-1):
        return statistic(np.concatenate(samples, axis=-1), axis=-1)
    return of


def trend_window(evaluations: int, fraction: float = 0.2) -> int:
    """The evaluations in each of `trend_is_flat`'s two windows: `fraction` of `evaluations`, at least 1."""
    return max(1, int(round(fraction * evaluations)))


def flat_margin(scores: np.ndarray, k: int, margin: float = 0.05) -> float:
    """`trend_is_flat`'s margin for `scores` (S, E): `margin` of the level of their last `k` evaluations (per seed
    their mean, then the mean over the seeds with no NaN there, its absolute value), at least 1 point."""
    with _quiet():
        level = abs(float(np.nanmean(np.asarray(scores, dtype=float)[:, -k:].mean(axis=1))))
    return max(margin * level, 1.0)


def trend_is_flat(scores: np.ndarray, fraction: float = 0.2, margin: float = 0.05,
                  seed: int = SEED) -> tuple[Estimate | None, bool]:
    """(trend, flat): per seed, the mean of the last `fraction` of evaluations minus the mean of the `fraction`
    before; its mean over seeds with a bootstrap interval.  Flat is an equivalence test, not a failure to see a
    change: the whole interval lies within +-`margin` of the last window's level (5 %, at least 1 point:
    `flat_margin`), so a noisy curve whose wide interval holds 0 is not flat.  One seed: its change within the
    margin.  A seed with a NaN in either window (it diverged) is left out, as the final scores leave it out.  Too
    few evaluations for two windows (`trend_window`): (None, False)."""
    scores = np.asarray(scores, dtype=float)
    assert scores.ndim == 2, scores.shape
    k = trend_window(scores.shape[1], fraction)
    if scores.shape[1] < 2 * k:
        return None, False
    change = scores[:, -k:].mean(axis=1) - scores[:, -2 * k:-k].mean(axis=1)  # NaN for a diverged seed: left out
    trend = interval([change], mean, seed=seed)
    if not math.isfinite(trend.value):
        return trend, False
    tolerance = flat_margin(scores, k, margin)
    if trend.low is None:
        return trend, bool(abs(trend.value) <= tolerance)
    return trend, bool(-tolerance <= trend.low and trend.high <= tolerance)


def running_mean(scores: np.ndarray, window: int) -> np.ndarray:
    """(S, E): per seed the trailing mean of `scores` (S, E) over `window` evaluations, the one at evaluation j
    averaging evaluations j - window + 1 .. j; NaN at the first window - 1 evaluations (too few before them) and
    wherever the window holds a NaN (a seed that diverged)."""
    scores = np.asarray(scores, dtype=float)
    assert scores.ndim == 2 and window >= 1, (scores.shape, window)
    out = np.full(scores.shape, np.nan)
    if scores.shape[1] >= window:
        out[:, window - 1:] = np.lib.stride_tricks.sliding_window_view(scores, window, axis=1).mean(axis=-1)
    return out


def sustained_reach(updates: np.ndarray, scores: np.ndarray, threshold: float,
                    window: int) -> tuple[np.ndarray, np.ndarray]:
    """`first_reach` of the `running_mean` over `window` evaluations: per seed the first update at which the mean
    of its last `window` evaluations is at or above `threshold`; censored at the last update where it never is."""
    return first_reach(updates, running_mean(scores, window), threshold)


def performance_profile(scores: np.ndarray, taus: np.ndarray) -> np.ndarray:
    """The fraction of `scores` (N,) above each of `taus` (T,)."""
    scores = np.asarray(scores, dtype=float)
    assert scores.ndim == 1, scores.shape
    return (scores[None, :] > np.asarray(taus)[:, None]).mean(axis=1)


@contextlib.contextmanager
def _quiet():
    """No RuntimeWarning for the mean of an all-NaN slice (a seed that diverged): NaN is the answer there."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        yield
