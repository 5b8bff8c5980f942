"""summary.json's numbers from hand-made curves: final score, asymptote, its trend, updates/seconds to 90 %."""
import pytest

from offrl_jax.results import summarize
from offrl_jax.study import Study, Variant


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
    summary = {s["variant"]: s for s in summarize(study, rows, {"pretrained": 1000})}
    # final = mean of the last 10 % of evaluations (1 of 10) per seed, then over seeds
    assert summary["scratch"]["final_score_mean"] == 100 and summary["pretrained"]["final_score_mean"] == 90
    assert summary["pretrained"]["asymptote"] == 100
    # first evaluation whose seed-mean >= 90: pretrained at 2000 updates (mean 90), scratch at 9000
    assert summary["pretrained"]["updates_to_90pct"] == 2000 and summary["pretrained"]["seconds_to_90pct"] == 20.0
    assert summary["scratch"]["updates_to_90pct"] == 9000
    # the reference still climbs: last 20 % (95) minus the 20 % before (75)
    assert summary["scratch"]["asymptote_trend"] == pytest.approx(20.0)
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
    assert "| scratch | 30.0 ± " in out and "asymptote (from-scratch final) 30.0" in out
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


def test_diverged_seed_is_named_and_ci_uses_the_t_quantile():
    import math

    import numpy as np

    from offrl_jax.results import ci95, t975

    study = Study(name="t", dataset="hopper-medium", env="hopper", seeds=(0, 1, 2), updates=2000, eval_every=1000,
                  variants=(Variant.of("scratch", "td3bc", pretrain="none"),), reference="scratch")
    nan = float("nan")
    (s,) = summarize(study, rows_of("scratch", [[10, 20], [30, nan], [50, 60]]), {})
    assert s["seeds_diverged"] == [1] and s["final_score_mean"] == 40.0  # (20 + 60) / 2: seed 1 is left out
    # t quantiles: the table to df 10, then within 0.1 % of the exact values (df 11: 2.201, 30: 2.042, 100: 1.984)
    assert t975(3) == 3.182
    for df, exact in ((11, 2.2010), (30, 2.0423), (100, 1.9840)):
        assert abs(t975(df) - exact) / exact < 1e-3
    values = np.arange(12.0)
    assert ci95(values) == pytest.approx(t975(11) * values.std(ddof=1) / math.sqrt(12))


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
    # curves [25, 50] against 0.9 * 40 = 36: reached at 2000; [30, 60] against 0.9 * 80 = 72: never
    assert summary["pretrained alpha=1"]["updates_to_90pct"] == 2000
    assert summary["pretrained alpha=2"]["updates_to_90pct"] is None


def test_ninety_percent_of_a_negative_asymptote_lies_below_it():
    """Adroit scores can be negative: 90 % of -10 must be reached at -11, not demanded at -9 (above the asymptote)."""
    study = Study(name="t", dataset="door-human", env="door", seeds=(0,), updates=2000, eval_every=1000,
                  variants=(Variant.of("pre", "td3bc", pretrain_updates=1000),
                            Variant.of("scratch", "td3bc", pretrain="none")),
                  reference="scratch")
    rows = rows_of("pre", [[-11.0, -10.5]]) + rows_of("scratch", [[-20.0, -10.0]])
    summary = {s["variant"]: s for s in summarize(study, rows, {})}
    assert summary["scratch"]["asymptote"] == -10.0 and summary["pre"]["updates_to_90pct"] == 1000


def test_report_gives_each_swept_variant_its_own_asymptote():
    from experiments.report import table

    base = {"dataset": "hopper-medium", "seeds": [0], "updates": 2000, "final_score_ci95": 0.0,
            "updates_to_90pct": None, "seconds_to_90pct": None, "pretrain_updates": 0, "asymptote_trend": None}
    summary = [dict(base, variant="pre alpha=1", final_score_mean=50.0, asymptote=40.0),
               dict(base, variant="scratch alpha=1", final_score_mean=40.0, asymptote=40.0),
               dict(base, variant="scratch alpha=5", final_score_mean=20.0, asymptote=20.0)]
    lines = table(summary).splitlines()
    assert "per variant" in lines[0] and lines[2].endswith("asymptote (trend) |")
    assert lines[-1] == "| scratch alpha=5 | 20.0 ± 0.0 | never | never | 0 | n/a | 20.0 |"  # no peak: older file
    # one shared asymptote stays in the header, with no extra column
    assert "asymptote (from-scratch final) 40.0" in table(summary[:2]).splitlines()[0]


def test_a_seed_that_diverges_inside_the_final_window_has_no_final_score():
    import math

    study = Study(name="t", dataset="door-human", env="door", seeds=(0, 1), updates=4000, eval_every=1000,
                  variants=(Variant.of("bc", "bc"),), final_window=(2000, 4000))
    nan = float("nan")
    rows = rows_of("bc", [[1.0, 2.0, 3.0, 4.0], [1.0, 50.0, 60.0, nan]])  # seed 1 diverged after 3000 updates
    (s,) = summarize(study, rows, {})
    assert s["final_score_mean"] == 3.0 and s["seeds_diverged"] == [1]  # not (3 + 55) / 2
    assert math.isnan(s["asymptote"]) and s["updates_to_90pct"] is None  # no reference given: no asymptote


def test_summary_json_writes_null_for_nan():
    import json

    from offrl_jax.results import summary_json

    text = summary_json([{"asymptote": float("nan"), "final_score_mean": 3.0, "overrides": {"x": float("inf")}}])
    assert json.loads(text) == [{"asymptote": None, "final_score_mean": 3.0, "overrides": {"x": None}}]
    assert "NaN" not in text and "Infinity" not in text


def _run_dir(path, study, rows):
    from offrl_jax.results import write_curves

    path.mkdir()
    (path / "config.json").write_text(study.to_json())
    write_curves(path / "curves.csv", rows)
    return path


def test_merge_runs_resummarises_variants_trained_apart(tmp_path, capsys):
    import json

    from experiments import report
    from offrl_jax.results import read_curves

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
    assert "| pretrained | 90.0 ± " in capsys.readouterr().out
    summary = {s["variant"]: s for s in json.loads((tmp_path / "ab" / "summary.json").read_text())}
    # the scratch run's final (mean of 100 and 80) is now the pretrained variant's asymptote too; 90 % of 90 = 81,
    # reached by the pretrained seed-mean (85) at 3000 updates and by scratch (90) at 4000
    assert summary["pretrained"]["asymptote"] == 90 and summary["pretrained"]["updates_to_90pct"] == 3000
    assert summary["scratch"]["updates_to_90pct"] == 4000
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
    assert report.main(["--merge", str(tmp_path / "bb"), str(b), str(b)]) == 2  # the same variant twice
    assert "unique labels" in capsys.readouterr().err


def test_a_truncated_curves_csv_is_refused_not_read_short(tmp_path):
    from offrl_jax.results import read_curves

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
