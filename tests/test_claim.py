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
    climbing = np.array([[10, 20, 30, 40, 50]] * 2, float)
    found = claim.plateau(np.array([50.0, 50.0]), climbing)
    assert found.level == 50.0 and found.trend.value == 10.0 and not found.flat  # 50 - 40 > max(5 % of 50, 1)
    none = claim.plateau(None, None)  # no reference arm
    assert np.isnan(none.level) and none.trend is None and not none.flat


def test_the_measure_is_read_only_at_a_flat_asymptote():
    entry = _speedup([30, 30], [10, 10])
    assert claim.paper_measure([entry | {"threshold": "90% of best"}], 2) is None  # no asymptote, no measure
    both = [entry, entry | {"threshold": "95% of asymptote"}, entry | {"threshold": "80% of asymptote"}]
    assert claim.paper_measure(both, 2) == {"speedup_above": 2.0, "verdicts": {"90% of asymptote": "holds",
                                                                              "95% of asymptote": "holds"}}


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
    # scratch ends at 100 on both seeds, 305k-400k and 405k-500k alike: flat, an asymptote of 100
    pre = summary["pretrained"]
    assert pre["asymptote"] == 100 and pre["asymptote_flat"] and pre["asymptote_trend"]["value"] == 0
    by = {r["threshold"]: r for r in pre["reach"]}
    assert by["90% of asymptote"]["score"] == 90 and by["95% of asymptote"]["score"] == 95
    assert by["90% of asymptote"]["updates"] == [50_000, 60_000] and not any(by["90% of asymptote"]["censored"])
    # scratch gets there at 200k and 300k: 250k / 55k = 4.55x; a resample's means are 200k-300k over 50k-60k, each
    # end with probability 1/4, so the interval is [200/60, 300/50]: wholly above 2, under 1/2 of the updates
    paper = pre["vs_reference"]["paper"]
    assert paper == {"speedup_above": 2.0, "verdicts": {"90% of asymptote": "holds", "95% of asymptote": "holds"}}
    ratio = {x["threshold"]: x for x in pre["vs_reference"]["speedup"]}["90% of asymptote"]["updates"]
    assert ratio["value"] == pytest.approx(250 / 55) and ratio["low"] == pytest.approx(200 / 60)
    assert ratio["high"] == pytest.approx(300 / 50)
    text = summary_table(list(summary.values()))
    assert "| 90% of asymptote | 90.0 | 4.55x [3.33, 6.00] | > 2x | yes |" in text
    assert "scratch's final 100.0, flat (trend +0.0 [+0.0, +0.0] over the last 20 % of evaluations" in text
    # the report: the study's tables, then one row of the paper's measure; the BC level is the hand-over's 70, each
    # arm ends 30 above it
    assert report.main([str(run), "--no-reference"]) == 0
    out = capsys.readouterr().out
    assert (f"| {run} | pretrained vs scratch | 2 | 100.0 (90.0, 95.0) | 4.55x [3.33, 6.00] | 4.55x [3.33, 6.00] | "
            "< 1/2 of the updates (> 2x) | yes / yes | 100.0 / 100.0 | 100.0 / 100.0 | 100.0 / 100.0 | "
            "+30.0 [+30.0, +30.0] / +30.0 [+30.0, +30.0] | 70.0 (pretrained at 10,000) |") in out
    assert "Across" not in out  # one study: no aggregate across studies


def test_a_scratch_arm_still_climbing_has_no_asymptote_and_no_measure(tmp_path, capsys):
    from experiments import report

    # seed 1 of scratch steps up at 475k: its last 20 % (405k-500k: 14 evaluations at 50, 6 at 100) averages 65
    # against 50 before, a change of 15; seed 0's is 0, so the mean is 7.5 and its interval [0, 15] reaches past
    # 5 % of the level (81.25 -> 4.1): not flat.  Its final (455k-500k): 80 and 100, a mean of 90.
    run = two_arm_run(tmp_path / "run", two_arm_rows(scratch_steps=(200_000, 475_000)))
    assert report.main([str(run), "--no-reference"]) == 0
    out = capsys.readouterr().out
    assert (f"| {run} | pretrained vs scratch | 2 | none (90.0, trend +7.5 [+0.0, +15.0]) | n/a | n/a | "
            "< 1/2 of the updates (> 2x) | n/a |") in out
    assert "not flat (trend +7.5 [+0.0, +15.0] over the last 20 % of evaluations): no asymptote." in out


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
