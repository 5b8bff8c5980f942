"""summary.json's numbers from hand-made curves: per-seed final, last and mean scores, the asymptote and its trend,
every seed's updates and seconds to each threshold, the speed-up and the verdict."""
import json

import numpy as np
import pytest

from offrl_jax.run.study import Study, Variant
from offrl_jax.run.summary import summarize


def rows_of(label, curve_per_seed, every=1000):
    return [{"variant": label, "seed": seed, "update": (j + 1) * every, "seconds": 10.0 * (j + 1), "score": score}
            for seed, curve in enumerate(curve_per_seed) for j, score in enumerate(curve)]


def test_summary_numbers_by_hand():
    study = Study(name="t", dataset="hopper-medium", env="hopper", seeds=(0, 1), updates=10_000, eval_every=1000,
                  variants=(Variant.of("pretrained", "td3bc"), Variant.of("scratch", "td3bc", pretrain="none")),
                  reference="scratch")
    scratch = [[10, 20, 30, 40, 50, 60, 70, 80, 90, 100], [10, 20, 30, 40, 50, 60, 70, 80, 90, 100]]
    pretrained = [[50, 95, 90, 90, 90, 90, 90, 90, 90, 80], [50, 85, 90, 90, 90, 90, 90, 90, 90, 100]]
    rows = rows_of("pretrained", pretrained) + rows_of("scratch", scratch)
    summary = {s["variant"]: s for s in summarize(study, rows, {"pretrained": 1000}, behaviour=50.0)}
    pre, scr = summary["pretrained"], summary["scratch"]
    # final = mean of the last 10 % of evaluations (1 of 10) per seed; last = the last evaluation; auc = the mean
    assert scr["final_scores"] == [100, 100] and pre["final_scores"] == [80, 100] and pre["last_scores"] == [80, 100]
    assert pre["auc_scores"] == [85.5, 86.5] and scr["auc_scores"] == [55, 55]
    assert scr["final_score_mean"] == 100 and pre["final_score_mean"] == 90 and pre["asymptote"] == 100
    assert pre["final_iqm"]["value"] == 90 and (pre["final_iqm"]["low"], pre["final_iqm"]["high"]) == (80, 100)
    # the reference still climbs: last 20 % (95) minus the 20 % before (75): no asymptote, so no threshold of it
    assert scr["asymptote_trend"]["value"] == pytest.approx(20.0) and not scr["asymptote_flat"]
    # and the BC-relative ones: the BC level at the hand-over (1000) is 50 on both seeds, the best 100
    assert [r["threshold"] for r in pre["reach"]] == ["behaviour data", "80% of best", "90% of best", "95% of best",
                                                      "BC + 50% to best", "BC + 90% to best"]
    # best seed-mean evaluation of any variant: scratch's 100 at 10k (pretrained's best mean is 90)
    assert pre["best_score"] == 100
    by = {r["threshold"]: r for r in pre["reach"]}
    assert by["behaviour data"]["updates"] == [1000, 1000] and by["behaviour data"]["seconds"] == [10.0, 10.0]
    assert by["90% of best"]["updates"] == [2000, 3000]  # seed 1 is at 85 < 90 at 2000, at 90 from 3000
    assert {r["threshold"]: r for r in scr["reach"]}["95% of best"]["updates"] == [10_000, 10_000]
    vs = pre["vs_reference"]
    assert vs["reference"] == "scratch" and vs["headline"] == "90% of best" and "vs_reference" not in scr
    sp = {x["threshold"]: x for x in vs["speedup"]}
    # scratch reaches 50 at 5000 on both seeds, pretrained at 1000: 5x, every resample the same
    assert sp["behaviour data"]["updates"] == {"value": 5.0, "low": 5.0, "high": 5.0}
    assert vs["verdict"] == "holds"
    # finals 80, 100 against 100, 100: two pairs lost (0), two tied (1/2): 1/4
    assert vs["poi_final"]["value"] == pytest.approx(0.25)
    assert summary["pretrained"]["pretrain_updates"] == 1000 and summary["scratch"]["pretrain"] == "none"
    # peak of the seed-mean curve (95 and 85 -> 90 at 2000) ... pretrained: (95 + 85) / 2 = 90 at 2000, later 90s tie
    # and the first is kept; the final (90) is 0 below it.  scratch peaks at its end.
    assert summary["pretrained"]["peak_score_mean"] == 90 and summary["pretrained"]["peak_update"] == 2000
    assert summary["pretrained"]["fall_from_peak"] == 0
    assert summary["scratch"]["peak_update"] == 10_000 and summary["scratch"]["fall_from_peak"] == 0


def test_fall_from_peak_by_hand():
    study = Study(name="t", dataset="hopper-medium", env="hopper", seeds=(0, 1), updates=10_000, eval_every=1000,
                  variants=(Variant.of("scratch", "td3bc", pretrain="none"),), reference="scratch")
    curves = [[10, 90, 80, 70, 60, 50, 40, 40, 40, 40], [30, 70, 60, 50, 40, 30, 20, 20, 20, 20]]
    (s,) = summarize(study, rows_of("scratch", curves), {})
    assert s["peak_score_mean"] == 80 and s["peak_update"] == 2000 and s["fall_from_peak"] == 50  # final 30


def test_report_renders_summary_and_rejects_missing_dir(tmp_path, capsys):
    import json

    from experiments import report

    study = Study(name="t", dataset="hopper-medium", env="hopper", seeds=(0, 1), updates=2000, eval_every=1000,
                  variants=(Variant.of("scratch", "td3bc", pretrain="none"),), reference="scratch")
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "summary.json").write_text(json.dumps(summarize(study, rows_of("scratch", [[10, 20], [30, 40]]),
                                                                         {})))
    assert report.main([str(tmp_path / "run")]) == 0
    out = capsys.readouterr().out
    assert "| scratch | 30.0 [20.0, 40.0] | 30.0 [20.0, 40.0] | 25.0 [15.0, 35.0] | 20 40 | 0 |" in out
    assert report.main([str(tmp_path / "missing")]) == 2
    assert capsys.readouterr().err.startswith("error: ")


def test_report_curve_table_is_the_seed_mean_per_evaluation(tmp_path):
    from experiments.report import curve_table

    rows = ["variant,seed,update,score", "a,0,1000,10", "a,1,1000,20", "a,0,2000,30", "a,1,2000,50", "b,0,2000,7",
            "b,0,2500,"]  # an empty score (a row without evaluation) is skipped
    (tmp_path / "curves.csv").write_text("\n".join(rows) + "\n")
    lines = curve_table(tmp_path / "curves.csv").splitlines()
    assert lines[0] == "| updates | 1k | 2k |"
    assert lines[2] == "| a | 15.0 | 40.0 |" and lines[3] == "| b |  | 7.0 |"


def test_a_diverged_seed_is_named_and_left_out_of_the_aggregates():
    study = Study(name="t", dataset="hopper-medium", env="hopper", seeds=(0, 1, 2), updates=2000, eval_every=1000,
                  variants=(Variant.of("scratch", "td3bc", pretrain="none"),), reference="scratch")
    nan = float("nan")
    (s,) = summarize(study, rows_of("scratch", [[10, 20], [30, nan], [50, 60]]), {})
    assert s["seeds_diverged"] == [1] and s["final_score_mean"] == 40.0  # (20 + 60) / 2: seed 1 is left out
    assert s["final_mean"] == {"value": 40.0, "low": 20.0, "high": 60.0}  # the bootstrap of the two others
    # a seed that diverged before a threshold never reached it: censored, not dropped
    by = {r["threshold"]: r for r in s["reach"]}
    assert by["90% of best"]["censored"] == [True, True, False]  # 0.9 * 60 = 54: only seed 2 (at 2000)
    # nor has it a mean over the run: 30, its one evaluation before diverging, would count as if it had held it
    assert np.isnan(s["auc_scores"][1]) and s["auc_iqm"]["value"] == 35.0  # (15 + 55) / 2


def test_per_seed_lists_follow_the_study_seed_order():
    study = Study(name="t", dataset="hopper-medium", env="hopper", seeds=(2, 0, 1), updates=2000, eval_every=1000,
                  variants=(Variant.of("scratch", "td3bc", pretrain="none"),), reference="scratch")
    nan = float("nan")
    rows = [r | {"seed": {0: 2, 1: 0, 2: 1}[r["seed"]]} for r in rows_of("scratch", [[10, nan], [30, 40], [50, 60]])]
    (s,) = summarize(study, rows, {})
    assert s["seeds"] == [2, 0, 1] and s["seeds_diverged"] == [2]  # seed 2's curve is the first, and diverged
    assert s["final_scores"][1:] == [40.0, 60.0]


def test_unknown_reference_label_is_refused():
    with pytest.raises(ValueError, match="reference = 'scrach' is not a variant label"):
        Study(name="t", dataset="hopper-medium", env="hopper", seeds=(0,), updates=10, eval_every=5,
              variants=(Variant.of("scratch", "td3bc", pretrain="none"),), reference="scrach")


def test_sweep_variants_are_measured_against_the_scratch_run_with_the_same_value():
    labels = ["pretrained alpha=1", "pretrained alpha=2", "scratch alpha=1", "scratch alpha=2"]
    study = Study(name="t", dataset="hopper-medium", env="hopper", seeds=(0,), updates=2000, eval_every=1000,
                  variants=tuple(Variant.of(label, "td3bc", alpha=float(label[-1]),
                                            pretrain="none" if label.startswith("scratch") else "actor+critic",
                                            pretrain_updates=1000)
                                 for label in labels), reference="scratch")
    finals = {"pretrained alpha=1": 50, "pretrained alpha=2": 60, "scratch alpha=1": 40, "scratch alpha=2": 80}
    rows = [r for label, final in finals.items() for r in rows_of(label, [[final / 2, final]])]
    summary = {s["variant"]: s for s in summarize(study, rows, {})}
    assert summary["pretrained alpha=1"]["asymptote"] == 40 and summary["pretrained alpha=2"]["asymptote"] == 80
    assert summary["pretrained alpha=1"]["vs_reference"]["reference"] == "scratch alpha=1"
    assert summary["pretrained alpha=2"]["vs_reference"]["reference"] == "scratch alpha=2"
    # one seed: no interval, so no verdict
    assert summary["pretrained alpha=1"]["vs_reference"]["verdict"] == "undecided: one seed, no interval"


def test_ninety_percent_of_a_negative_asymptote_lies_below_it():
    """Adroit scores can be negative: 90 % of -10 must be reached at -11, not demanded at -9 (above the asymptote)."""
    study = Study(name="t", dataset="door-human", env="door", seeds=(0,), updates=3000, eval_every=1000,
                  variants=(Variant.of("pre", "td3bc", pretrain_updates=1000),
                            Variant.of("scratch", "td3bc", pretrain="none")),
                  reference="scratch")
    from offrl_jax.run.stats import fraction_of

    assert fraction_of(-10.0, 0.9) == -11.0 and fraction_of(10.0, 0.9) == 9.0
    rows = rows_of("pre", [[-11.0, -10.5, -10.5]]) + rows_of("scratch", [[-20.0, -10.0, -10.0]])
    summary = {s["variant"]: s for s in summarize(study, rows, {})}
    assert summary["scratch"]["asymptote"] == -10.0 and summary["scratch"]["asymptote_flat"]
    by = {r["threshold"]: r for r in summary["pre"]["reach"]}
    assert by["90% of asymptote"]["score"] == -11.0 and by["90% of asymptote"]["updates"] == [1000]


@pytest.mark.parametrize("censored, reference_censored, low, high, text, verdict_", [
    (0, 0, 1.5, 3.0, "2.00x [1.50, 3.00]", "holds"),
    (0, 2, 1.5, 3.0, "≥ 2.00x [1.50, 3.00]", "holds"),  # the reference's true updates are more: only larger
    (0, 2, 0.5, 0.9, "≥ 2.00x [0.50, 0.90]", "undecided: censored seeds bound the ratio from one side only"),
    (2, 0, 1.5, 3.0, "≤ 2.00x [1.50, 3.00]", "undecided: censored seeds bound the ratio from one side only"),
    (2, 0, 0.5, 0.9, "≤ 2.00x [0.50, 0.90]", "does not hold"),  # only smaller than an interval below 1
    (2, 3, 1.5, 3.0, "2.00x [1.50, 3.00] (both censored)", "undecided: both arms have censored seeds"),
    (5, 5, 1.0, 1.0, "2.00x [1.00, 1.00] (both censored)", "undecided: neither arm reaches the threshold"),
])
def test_a_speedup_with_censored_seeds_is_a_bound_only_where_one_arm_has_them(censored, reference_censored, low,
                                                                              high, text, verdict_):
    from offrl_jax.run.bc_level import ratio_text
    from offrl_jax.run.claim import verdict

    estimate = {"value": 2.0, "low": low, "high": high}
    assert ratio_text(estimate, censored, reference_censored) == text
    speedup = {"updates": estimate, "censored": censored, "reference_censored": reference_censored}
    assert verdict(speedup, seeds=5) == verdict_


def test_the_table_shows_every_seed_and_marks_censored_seeds_and_lower_bounds():
    from offrl_jax.run.summary import summary_table

    study = Study(name="t", dataset="hopper-medium", env="hopper", seeds=(0, 1), updates=3000, eval_every=1000,
                  variants=(Variant.of("pretrained", "td3bc", pretrain_updates=1000),
                            Variant.of("scratch", "td3bc", pretrain="none")), reference="scratch")
    rows = rows_of("pretrained", [[90, 95, 95], [60, 95, 96]]) + rows_of("scratch", [[10, 20, 30], [10, 96, 90]])
    text = summary_table(summarize(study, rows, {"pretrained": 1000}))
    # 90 % of the best seed-mean evaluation (95.5) is 85.95: pretrained at 1k and 2k, scratch never (censored at
    # the 3k budget) and at 2k: 2.5k / 1.5k, a lower bound; the arms' resample means span 1-2k and 2-3k, each end
    # with probability 1/4, so the 95 % interval is [2k/2k, 3k/1k]; seed 0 got there at the hand-over (1k), as the
    # BC actor
    assert ("| 90% of best (headline) | 86.0 | 1k 2k (1 of 2 by the BC actor) | >3k 2k (1 censored) | "
            "≥ 1.67x [1.00, 3.00] |") in text
    assert ("pretrained needs fewer updates than scratch to reach 90% of best: undecided: the interval holds 1.\n"
            in text)
    # scratch still climbs (+2.0 over its last evaluation): no asymptote, so the paper's measure says why it has none
    # (its one evaluation a side, too few for the paper's measure to call it flat anyway; margin 5 % of 60)
    assert text.endswith("scratch's final 60.0; too few evaluations: 1 a side, 10 needed (+2.0 [-6.0, +10.0], "
                         "±3.0): no asymptote.")
    assert "| scratch | 60.0 [30.0, 90.0] |" in text and "final per seed" in text


def test_a_seed_that_diverges_inside_the_final_window_has_no_final_score():
    import math

    study = Study(name="t", dataset="door-human", env="door", seeds=(0, 1), updates=4000, eval_every=1000,
                  variants=(Variant.of("bc", "bc"),), final_window=(2000, 4000))
    nan = float("nan")
    rows = rows_of("bc", [[1.0, 2.0, 3.0, 4.0], [1.0, 50.0, 60.0, nan]])  # seed 1 diverged after 3000 updates
    (s,) = summarize(study, rows, {})
    assert s["final_score_mean"] == 3.0 and s["seeds_diverged"] == [1]  # not (3 + 55) / 2
    assert math.isnan(s["asymptote"]) and "vs_reference" not in s  # no reference given: no asymptote, no speed-up


def test_summary_json_writes_null_for_nan():
    import json

    from offrl_jax.run.summary import summary_json

    text = summary_json([{"asymptote": float("nan"), "final_score_mean": 3.0, "overrides": {"x": float("inf")}}])
    assert json.loads(text) == [{"asymptote": None, "final_score_mean": 3.0, "overrides": {"x": None}}]
    assert "NaN" not in text and "Infinity" not in text


def _run_dir(path, study, rows):
    from offrl_jax.run.results import write_curves

    path.mkdir()
    (path / "config.json").write_text(study.to_json())
    write_curves(path / "curves.csv", rows)
    return path


def test_merge_runs_resummarises_variants_trained_apart(tmp_path, capsys):
    import json

    from experiments import report
    from offrl_jax.run.results import read_curves

    common = dict(name="t", dataset="hopper-medium", env="hopper", seeds=(0, 1), updates=4000, eval_every=1000)
    pre = Study(variants=(Variant.of("pretrained", "td3bc", pretrain_updates=2000),), **common)
    scratch = Study(variants=(Variant.of("scratch", "td3bc", pretrain="none"),), reference="scratch", **common)
    phases = ["actor_pretrain", "critic_pretrain", "offline_rl", "offline_rl"]
    pre_rows = [r | {"phase": phases[r["update"] // 1000 - 1], "bc_mse": 0.5}
                for r in rows_of("pretrained", [[50, 70, 90, 95], [50, 70, 80, 85]])]
    scratch_rows = [r | {"phase": "offline_rl"} for r in rows_of("scratch", [[10, 40, 80, 100], [10, 40, 60, 80]])]
    a = _run_dir(tmp_path / "a", pre, pre_rows)
    b = _run_dir(tmp_path / "b", scratch, scratch_rows)
    assert report.main(["--merge", str(tmp_path / "ab"), str(a), str(b)]) == 0
    out, err = capsys.readouterr()
    assert "| pretrained | 90.0 [85.0, 95.0] |" in out and "warning" not in err  # they differ in pre-training only
    summary = {s["variant"]: s for s in json.loads((tmp_path / "ab" / "summary.json").read_text())}
    # the scratch run's final (mean of 100 and 80) is now the pretrained variant's asymptote too, and scratch its
    # reference; 90 % of the best (seed-mean 90, both at 4000) is 81: pretrained at 3000 and 4000 updates, scratch
    # at 4000 and never (80)
    assert summary["pretrained"]["asymptote"] == 90 and summary["pretrained"]["vs_reference"]["reference"] == "scratch"
    reach = {r["threshold"]: r for r in summary["pretrained"]["reach"]}["90% of best"]
    assert reach["updates"] == [3000, 4000] and reach["censored"] == [False, False]
    reach = {r["threshold"]: r for r in summary["scratch"]["reach"]}["90% of best"]
    assert reach["updates"] == [4000, 4000] and reach["censored"] == [False, True]
    # pre-training ends at the last evaluation before offline RL
    assert summary["pretrained"]["pretrain_updates"] == 2000 and summary["scratch"]["pretrain_updates"] == 0
    merged = Study.from_json((tmp_path / "ab" / "config.json").read_text())
    assert [v.label for v in merged.variants] == ["pretrained", "scratch"] and merged.reference == "scratch"
    rows = read_curves(tmp_path / "ab" / "curves.csv")
    assert len(rows) == 16 and rows[0]["bc_mse"] == 0.5 and "bc_mse" not in rows[-1] and rows[-1]["seed"] == 1
    # nothing is overwritten, and runs of different studies do not merge
    before = (tmp_path / "ab" / "summary.json").read_text()
    assert report.main(["--merge", str(tmp_path / "ab"), str(a), str(b)]) == 2
    assert "already holds a run" in capsys.readouterr().err
    assert (tmp_path / "ab" / "summary.json").read_text() == before
    other = _run_dir(tmp_path / "c", Study(variants=scratch.variants, reference="scratch",
                                           **(common | {"dataset": "hopper-medium-replay"})), scratch_rows)
    assert report.main(["--merge", str(tmp_path / "ac"), str(a), str(other)]) == 2
    assert "dataset differ" in capsys.readouterr().err and not (tmp_path / "ac").exists()
    assert report.main(["--merge", str(tmp_path / "bb"), str(b), str(b)]) == 2  # the same run twice
    assert "is given twice" in capsys.readouterr().err and not (tmp_path / "bb").exists()
    # the same study on other data (another version of the dataset): its config.json recorded another SHA-256
    from offrl_jax.run.provenance import run_record
    from tests.conftest import synthetic_dataset

    for run, seed in ((a, 0), (b, 1)):
        raw = json.loads((run / "config.json").read_text())
        (run / "config.json").write_text(json.dumps(raw | {"runs": [run_record(synthetic_dataset(seed=seed))]}))
    assert report.main(["--merge", str(tmp_path / "ab2"), str(a), str(b)]) == 2
    assert "trained on different data" in capsys.readouterr().err and not (tmp_path / "ab2").exists()


def test_a_truncated_curves_csv_is_refused_not_read_short(tmp_path):
    from offrl_jax.run.results import read_curves

    path = tmp_path / "curves.csv"
    path.write_text("variant,seed,update,score,critic_loss\na,0,100,1.5,2.0\na,0,200,1.7,\nb,0,100,0.4")
    with pytest.raises(ValueError, match="line 4 has 4 cells for 5 columns"):
        read_curves(path)
    path.write_text("variant,seed,update,score,critic_loss\na,0,100,1.5,2.0\na,0,200,1.7,\n")
    assert [r.get("critic_loss") for r in read_curves(path)] == [2.0, None]  # an empty cell is a metric not logged
    path.write_text("variant,seed,update,score\na,0,100,1.5\na,1,100,1.6\na,0,200,1.7\n")  # cut at a line
    with pytest.raises(ValueError, match="a at update 200 has no row for seed"):
        read_curves(path)


def test_merge_refuses_a_run_whose_curves_end_early(tmp_path, capsys):
    from experiments import report

    common = dict(name="t", dataset="hopper-medium", env="hopper", seeds=(0,), updates=200, eval_every=100)
    scratch = (Variant.of("scratch", "td3bc", pretrain="none"),)
    run = _run_dir(tmp_path / "a", Study(variants=scratch, reference="scratch", **common),
                   [{"variant": "scratch", "algo": "td3bc", "seed": 0, "phase": "offline_rl", "update": 100,
                     "seconds": 1.0, "score": 1.0}])
    assert report.main(["--merge", str(tmp_path / "m"), str(run)]) == 2
    assert "ends before the run's 200 updates (scratch at 100)" in capsys.readouterr().err


def test_merge_refuses_a_run_whose_curves_hold_other_seeds(tmp_path, capsys):
    from experiments import report

    common = dict(name="t", dataset="hopper-medium", env="hopper", seeds=(0, 1), updates=100, eval_every=100)
    scratch = (Variant.of("scratch", "td3bc", pretrain="none"),)
    rows = [{"variant": "scratch", "algo": "td3bc", "seed": seed, "phase": "offline_rl", "update": 100,
             "seconds": 1.0, "score": 1.0} for seed in (0, 7)]  # seed 1 relabelled 7
    run = _run_dir(tmp_path / "a", Study(variants=scratch, reference="scratch", **common), rows)
    assert report.main(["--merge", str(tmp_path / "m"), str(run)]) == 2
    assert "scratch has seeds 0, 7 where its run has 0, 1" in capsys.readouterr().err
    assert not (tmp_path / "m").exists()


def test_merge_says_when_the_variants_differ_in_more_than_their_pre_training(tmp_path, capsys):
    from experiments import report

    common = dict(name="t", dataset="hopper-medium", env="hopper", seeds=(0,), updates=200, eval_every=100)
    runs = []
    for label, pretrain, alpha in (("pretrained", "actor+critic", 2.5), ("scratch", "none", 10.0)):
        study = Study(variants=(Variant.of(label, "td3bc", pretrain=pretrain, pretrain_updates=100, alpha=alpha),),
                      **common)
        runs.append(_run_dir(tmp_path / label, study, rows_of(label, [[1.0, 2.0]], every=100)))
    assert report.main(["--merge", str(tmp_path / "m"), *map(str, runs)]) == 0
    err = capsys.readouterr().err
    assert "warning: the merged variants differ in more than their pre-training: alpha (pretrained: 2.5, " \
           "scratch: 10.0)\n" in err, err


@pytest.mark.parametrize("recorded, expected", [("same", True), ("other", False), (None, False)])
def test_a_run_without_its_behaviour_score_gets_the_cached_data_s_only_where_it_is_the_data_it_trained_on(
        tmp_path, monkeypatch, recorded, expected):
    import json

    from experiments import report_runs
    from offrl_jax.run.provenance import fingerprint, run_record
    from offrl_jax.run.summary import behaviour_score
    from tests.conftest import synthetic_dataset

    cached = synthetic_dataset()
    from offrl_jax.data import catalogue

    monkeypatch.setattr(catalogue, "is_cached", lambda name: name == "hopper-medium")
    monkeypatch.setattr(catalogue, "load", lambda name: cached)
    runs = [] if recorded is None else [run_record(cached if recorded == "same" else synthetic_dataset(seed=1),
                                                   "hopper-medium")]
    (tmp_path / "config.json").write_text(json.dumps({"runs": runs}))
    score = report_runs.recorded_behaviour(tmp_path, "hopper-medium")
    assert score == (behaviour_score(cached) if expected else None) and (score is not None) == expected
    assert fingerprint(cached) != fingerprint(synthetic_dataset(seed=1))


def test_arms_of_other_algorithms_or_the_same_runs_are_not_pooled_across_studies():
    from offrl_jax.run.aggregate import not_poolable

    def study(algo, finals):
        return [{"variant": "scratch", "algo": algo, "final_scores": finals, "auc_scores": finals}]

    a, b = study("td3bc", [1.0, 2.0]), study("td3bc", [3.0, 4.0])
    assert not_poolable([a, b], ["a", "b"]) is None
    assert not_poolable([a, study("edac", [3.0, 4.0])], ["a", "e"]) == "'scratch' is edac, td3bc in different studies"
    merged = study("td3bc", [1.0, 2.0])  # a's runs again
    assert not_poolable([a, b, merged], ["a", "b", "m"]) == "a and m hold the same runs of 'scratch'"
    tuned = [dict(a[0], final_scores=[5.0, 6.0], online={"final": {}})]  # the same arm, fine-tuned online
    assert not_poolable([a, tuned], ["a", "t"]).startswith("'scratch' is fine-tuned online in t and not in a")
    # a --from run beside the run it started from, or two fine-tunings of one run: the same seeds' offline phases
    assert not_poolable([tuned, tuned], ["t", "a"], ["a", None]) == \
        "t fine-tunes the runs of a (the same seeds' offline phases)"
    assert not_poolable([tuned, tuned], ["t", "u"], ["/runs/x", "/runs/x"]) == \
        "t and u both fine-tune the runs of /runs/x (the same seeds' offline phases)"


def test_report_names_the_run_a_study_fine_tuned_as_it_was_given(tmp_path):
    from experiments.report import fine_tuned

    source, tuned, plain = tmp_path / "mm", tmp_path / "ft", tmp_path / "plain"
    for d in (source, tuned, plain):
        d.mkdir()
    (tuned / "config.json").write_text(json.dumps({"start_from": str(source.resolve())}))
    (plain / "config.json").write_text(json.dumps({"start_from": None}))
    assert fine_tuned([source, tuned, plain]) == [None, str(source), None]
