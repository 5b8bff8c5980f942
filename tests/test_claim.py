"""The paper's measure (`offrl_jax.run.claim`) by hand: the from-scratch plateau, the verdict against "less than 1/2
of the training steps" (a speed-up above 2x), and the report of a synthetic two-arm run at the paper's budget (500k
updates, an evaluation every 5k), drawn on its whole update axis."""
import json

import numpy as np
import pytest

from offrl_jax.run import claim, stats
from offrl_jax.run.study import Study, Variant
from offrl_jax.run.summary import summarize, summary_table
from tests.test_summary import _run_dir, rows_of


def _speedup(reference_reach, reach, censored=0, reference_censored=0) -> dict:
    """A `summary.compare` speed-up entry from per-seed updates to a threshold."""
    ratio = stats.speedup(np.array(reference_reach, float), np.array(reach, float))
    return {"threshold": "90% of asymptote", "score": 90.0, "updates": ratio.to_json(), "censored": censored,
            "reference_censored": reference_censored, "seeds": len(reach)}


def test_the_paper_s_bar_is_a_speed_up_above_two():
    # 30k / 10k on every seed: 3x, every resample the same: above 2, the claim holds
    assert claim.verdict(_speedup([30, 30], [10, 10]), 2, claim.PAPER_SPEEDUP) == "holds"
    # 1.5x: fewer updates (above 1), but not under 1/2 of them (at or below 2)
    fewer = _speedup([30, 30], [20, 20])
    assert claim.verdict(fewer, 2) == "holds" and claim.verdict(fewer, 2, claim.PAPER_SPEEDUP) == "does not hold"
    # scratch [2, 6] against [2, 2]: a resample's mean is 2, 4 or 6 (probabilities 1/4, 1/2, 1/4) over 2, so the
    # ratio is 1, 2 or 3 and its 95 % interval [1, 3] around 2: neither side of the bar
    straddles = _speedup([2, 6], [2, 2])
    assert straddles["updates"] == {"value": 2.0, "low": 1.0, "high": 3.0}
    assert claim.verdict(straddles, 2, claim.PAPER_SPEEDUP) == "undecided: the interval holds 2"
    # a censored pre-trained seed makes 3x an upper bound: it may be below 2, so no "holds"
    assert claim.verdict(_speedup([30, 30], [10, 10], censored=1), 2, claim.PAPER_SPEEDUP) == (
        "undecided: censored seeds bound the ratio from one side only")
    # a censored scratch seed makes 1.5x a lower bound: it may be above 2, so no "does not hold"
    assert claim.verdict(_speedup([30, 30], [20, 20], reference_censored=1), 2, claim.PAPER_SPEEDUP) == (
        "undecided: censored seeds bound the ratio from one side only")


def test_the_plateau_is_the_mean_final_and_counts_only_where_flat():
    nan = float("nan")
    flat = np.array([[80, 80, 90, 90, 90], [80, 80, 100, 100, 100]], float)
    # one evaluation per window (20 % of 5): 90 - 90 and 100 - 100, a change of 0 on both seeds
    found = claim.plateau(np.array([90.0, 100.0, nan]), flat)
    assert (found.level, found.trend, found.flat) == (95.0, stats.Estimate(0.0, 0.0, 0.0), True)  # NaN: left out
    # flat, but on 1 evaluation a side: too few for the paper's measure; its margin is 5 % of (90 + 100) / 2
    assert found.per_side == 1 and found.margin == pytest.approx(4.75) and not found.paper
    climbing = np.array([[10, 20, 30, 40, 50]] * 2, float)
    found = claim.plateau(np.array([50.0, 50.0]), climbing)
    assert found.level == 50.0 and found.trend.value == 10.0 and not found.flat  # 50 - 40 > max(5 % of 50, 1)
    none = claim.plateau(None, None)  # no reference arm
    assert np.isnan(none.level) and none.trend is None and not none.flat and not none.paper


def test_a_seed_that_diverged_is_left_out_of_the_plateau_test_as_of_the_level():
    nan = float("nan")
    level = np.full((3, 50), 100.0)
    level[0, 40:] = [90.0] * 5 + [nan] * 5  # fell 10 points, then diverged inside the last window
    found = claim.plateau(np.array([nan, 100.0, 100.0]), level)
    # seed 0 has no final and no change: the others' change is 0, the margin 5 % of their level
    assert found.trend.value == 0.0 and found.margin == pytest.approx(5.0) and found.flat and found.paper
    level[1:, 44:] = nan  # every seed diverged: no level, so no asymptote for the measure to read
    found = claim.plateau(np.full(3, nan), level)
    assert np.isnan(found.level) and not found.flat and not found.paper


def test_the_paper_s_measure_needs_ten_evaluations_a_side_to_call_a_plateau_flat():
    # 48 evaluations: round(0.2 * 48) = 10 a side, the fewest that count; 47: round(9.4) = 9
    for evaluations, counts in ((47, False), (48, True)):
        level = np.full((2, evaluations), 60.0)
        found = claim.plateau(level[:, -1], level)
        assert found.flat and found.per_side == (10 if counts else 9) and found.paper == counts
        assert found.margin == 3.0  # 5 % of 60
    # a curve of 4 evaluations (ReBRAC walker2d's committed run): 1 a side, "too few evaluations" with the change
    found = claim.plateau(np.array([70.0, 74.0]), np.array([[60, 70, 70, 70], [60, 74, 74, 74]], float))
    assert found.flat and not found.paper
    variant = {"asymptote": found.level, "asymptote_trend": found.trend.to_json(), "asymptote_flat": found.flat,
               "asymptote_per_side": found.per_side, "asymptote_margin": found.margin, "paper_asymptote": found.paper}
    # the last evaluation against the one before: 0 and 0, margin 5 % of 72 = 3.6
    assert claim.plateau_test(variant) == "too few evaluations: 1 a side, 10 needed (+0.0 [+0.0, +0.0], ±3.6)"
    assert claim._plateau_cell(variant) == "none (72.0)"
    assert claim.plateau_text(variant, "scratch") == (
        "scratch's final 72.0; too few evaluations: 1 a side, 10 needed (+0.0 [+0.0, +0.0], ±3.6): no asymptote")


def _reach(updates, censored=None, window=3) -> list[dict]:
    """A variant's sustained reach of 90 % and 95 % of an asymptote of 100, the same updates at both."""
    censored = censored or [False] * len(updates)
    return [{"threshold": claim.threshold_name(f), "score": 100 * f, "window": window, "updates": updates,
             "censored": censored} for f in claim.PAPER_FRACTIONS]


def test_the_measure_is_read_only_at_an_asymptote_from_the_sustained_reach():
    assert claim.paper_measure([], _reach([30, 30]), 2) is None  # no asymptote, no measure
    # scratch 30k and 30k, pre-trained 10k and 10k: 3x on every resample, above 2
    found = claim.paper_measure(_reach([10, 10]), _reach([30, 30]), 2)
    assert found["window"] == 3 and found["verdicts"] == {"90% of asymptote": "holds", "95% of asymptote": "holds"}
    assert found["speedup"][0]["updates"] == {"value": 3.0, "low": 3.0, "high": 3.0}
    # a scratch seed censored at the budget (20): 17.5 / 10 = 1.75x, its interval [15 / 10, 20 / 10] at or below 2,
    # but a lower bound: the true ratio may be above 2, so no "does not hold"
    found = claim.paper_measure(_reach([10, 10]), _reach([15, 20], [False, True]), 2)
    assert found["speedup"][0]["reference_censored"] == 1
    assert found["speedup"][0]["updates"] == {"value": 1.75, "low": 1.5, "high": 2.0}
    assert found["verdicts"]["90% of asymptote"] == "undecided: censored seeds bound the ratio from one side only"


EVERY, BUDGET = 5000, 500_000  # the paper's budget for TD3+BC on hopper and walker2d, an evaluation every 5k


def step_curve(low: float, high: float, at: int) -> list[float]:
    """A curve at `low` until update `at`, at `high` from there (100 evaluations, every 5k)."""
    return [high if (j + 1) * EVERY >= at else low for j in range(BUDGET // EVERY)]


def two_arm_rows(scratch_steps=(200_000, 300_000)) -> list[dict]:
    """Pre-trained: the BC actor scores 70 at the 5k and 10k evaluations (pre-training, hand-over at 10k), 100 from
    50k (seed 0) and 60k (seed 1); from scratch: 50, then 100 from `scratch_steps`."""
    pretrained = [step_curve(70, 100, 50_000), step_curve(70, 100, 60_000)]
    scratch = [step_curve(50, 100, at) for at in scratch_steps]
    phase = lambda r: "actor_pretrain" if r["update"] <= 10_000 else "offline_rl"  # noqa: E731
    return ([r | {"algo": "td3bc", "phase": phase(r)} for r in rows_of("pretrained", pretrained, every=EVERY)]
            + [r | {"algo": "td3bc", "phase": "offline_rl"} for r in rows_of("scratch", scratch, every=EVERY)])


def two_arm_run(path, rows):
    """A run directory as a finished run leaves it: config.json, curves.csv and summary.json."""
    run = _run_dir(path, STUDY, rows)
    (run / "summary.json").write_text(json.dumps(summarize(STUDY, rows, {"pretrained": 10_000})))
    return run


STUDY = Study(name="t", dataset="hopper-medium", env="hopper", seeds=(0, 1), updates=BUDGET, eval_every=EVERY,
              variants=(Variant.of("pretrained", "td3bc", pretrain_updates=10_000),
                        Variant.of("scratch", "td3bc", pretrain="none")), reference="scratch")


def test_a_two_arm_run_at_the_paper_s_budget_by_hand(tmp_path, capsys):
    from experiments import report

    run = two_arm_run(tmp_path / "run", two_arm_rows())
    summary = {s["variant"]: s for s in summarize(STUDY, two_arm_rows(), {"pretrained": 10_000})}
    # scratch ends at 100 on both seeds, 305k-400k and 405k-500k alike (20 evaluations a side): flat, an asymptote
    # of 100 for the paper's measure too
    pre = summary["pretrained"]
    assert pre["asymptote"] == 100 and pre["asymptote_flat"] and pre["asymptote_trend"]["value"] == 0
    assert pre["asymptote_per_side"] == 20 and pre["asymptote_margin"] == 5.0 and pre["paper_asymptote"]
    # the study tables' reach (first evaluation at the threshold) is unchanged: 50k and 60k, 250k / 55k = 4.55x
    by = {r["threshold"]: r for r in pre["reach"]}
    assert by["90% of asymptote"]["score"] == 90 and by["95% of asymptote"]["score"] == 95
    assert by["90% of asymptote"]["updates"] == [50_000, 60_000] and not any(by["90% of asymptote"]["censored"])
    ratio = {x["threshold"]: x for x in pre["vs_reference"]["speedup"]}["90% of asymptote"]["updates"]
    assert ratio["value"] == pytest.approx(250 / 55)
    # the paper's measure: sustained reach, the mean of the last 10 evaluations (as many as the level averages).
    # Pre-trained seed 0 is at 70 until 45k, 100 from 50k: a window ending k evaluations into the 100s averages
    # 70 + 3 k, at or above 90 from k = 7 (91), at 80k, and at or above 95 from k = 9 (97), at 90k; seed 1, 10k
    # later.  Scratch, 50 then 100: 50 + 5 k, 90 at k = 8 and 95 at k = 9: 235k / 240k (seed 0), 335k / 340k.
    sustained = {r["threshold"]: r["updates"] for r in pre["sustained_reach"]}
    assert sustained == {"90% of asymptote": [80_000, 90_000], "95% of asymptote": [90_000, 100_000]}
    scratch = {r["threshold"]: r["updates"] for r in summary["scratch"]["sustained_reach"]}
    assert scratch == {"90% of asymptote": [235_000, 335_000], "95% of asymptote": [240_000, 340_000]}
    # 285k / 85k = 3.35x at 90 %; a resample's means run from 235k to 335k over 80k to 90k, each end with
    # probability 1/4, so its interval is [235/90, 335/80]: wholly above 2, under 1/2 of the updates
    paper = pre["vs_reference"]["paper"]
    assert paper["window"] == 10 and paper["verdicts"] == {"90% of asymptote": "holds", "95% of asymptote": "holds"}
    ratio = paper["speedup"][0]["updates"]
    assert ratio["value"] == pytest.approx(285 / 85) and ratio["low"] == pytest.approx(235 / 90)
    assert ratio["high"] == pytest.approx(335 / 80)
    text = summary_table(list(summary.values()))
    assert "| 90% of asymptote | 90.0 | 80k 90k | 235k 335k | 3.35x [2.61, 4.19] | > 2x | yes |" in text
    assert "| 95% of asymptote | 95.0 | 90k 100k | 240k 340k | 3.05x [2.40, 3.78] | > 2x | yes |" in text
    assert "scratch's final 100.0; flat: +0.0 [+0.0, +0.0] within ±5.0 (20 a side): an asymptote." in text
    assert "the first update (pre-training included) at which the mean of its last 10 evaluations" in text
    # the report: the study's tables, then one row of the paper's measure; the BC level is the hand-over's 70, each
    # arm ends 30 above it
    assert report.main([str(run), "--no-reference"]) == 0
    out = capsys.readouterr().out
    assert (f"| {run} | pretrained vs scratch | 2 | 100.0 (90.0, 95.0) | flat: +0.0 [+0.0, +0.0] within ±5.0 "
            "(20 a side) | 3.35x [2.61, 4.19] | 3.05x [2.40, 3.78] | < 1/2 of the updates (> 2x) | yes / yes | "
            "100.0 / 100.0 | 100.0 / 100.0 | 100.0 / 100.0 | +30.0 [+30.0, +30.0] / +30.0 [+30.0, +30.0] | "
            "70.0 (pretrained at 10,000) |") in out
    assert "Across" not in out  # one study: no aggregate across studies


def test_a_scratch_arm_still_climbing_has_no_asymptote_and_no_measure(tmp_path, capsys):
    from experiments import report

    # seed 1 of scratch steps up at 475k: its last 20 % (405k-500k: 14 evaluations at 50, 6 at 100) averages 65
    # against 50 before, a change of 15; seed 0's is 0, so the mean is 7.5 and its interval [0, 15] reaches past
    # the margin, 5 % of (100 + 65) / 2 = 4.125: not flat.  Its final (455k-500k): 80 and 100, a mean of 90.
    run = two_arm_run(tmp_path / "run", two_arm_rows(scratch_steps=(200_000, 475_000)))
    assert report.main([str(run), "--no-reference"]) == 0
    out = capsys.readouterr().out
    assert (f"| {run} | pretrained vs scratch | 2 | none (90.0) | not flat: +7.5 [+0.0, +15.0], not within ±4.1 "
            "(20 a side) | n/a | n/a | < 1/2 of the updates (> 2x) | n/a |") in out
    assert "scratch's final 90.0; not flat: +7.5 [+0.0, +15.0], not within ±4.1 (20 a side): no asymptote." in out


def test_a_500k_run_is_drawn_on_its_whole_update_axis(tmp_path, monkeypatch):
    """Figure 2's panels take their x range from the run's evaluations: nothing clips a 500k run to the CPU
    budgets (30-40k) of the runs drawn before it."""
    from offrl_jax.run import figures

    run = two_arm_run(tmp_path / "run", two_arm_rows())
    drawn = {}
    original = figures.write_figure

    def record(fig, path, **kw):
        (ax,) = fig.axes
        label = ax.xaxis.get_major_formatter()
        drawn.update(xlim=ax.get_xlim(), title=ax.get_title(), ticks=[label(x, None) for x in ax.get_xticks()])
        return original(fig, path, **kw)

    monkeypatch.setattr(figures, "write_figure", record)
    figures.plot_studies([run], tmp_path / "fig.png", reference=False)
    low, high = drawn["xlim"]
    assert low <= EVERY and high >= BUDGET, drawn["xlim"]
    assert "500k updates" in drawn["title"] and "500k" in drawn["ticks"], drawn
