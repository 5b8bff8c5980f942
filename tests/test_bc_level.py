"""The BC level of a study (offrl_jax.run.bc_level) from hand-made curves: the pre-trained actor at the hand-over or a
BC arm's final score, the improvement over it per seed, the BC-relative thresholds, and the seeds that reached a
threshold by the BC actor, in summary.json, the study's table and the claims table."""
import numpy as np
import pytest

from offrl_jax.run import stats
from offrl_jax.run.aggregate import claims_table
from offrl_jax.run.bc_level import figure_lines
from offrl_jax.run.results import pretrain_ends_of
from offrl_jax.run.study import Study, Variant
from offrl_jax.run.summary import summarize, summary_table


def rows_of(label, curve_per_seed, phases, every=1000):
    return [{"variant": label, "seed": seed, "phase": phases[j], "update": (j + 1) * every, "seconds": 10.0 * (j + 1),
             "score": score} for seed, curve in enumerate(curve_per_seed) for j, score in enumerate(curve)]


PRE, RL = ["pretrain"] * 2, ["offline_rl"] * 3
STUDY = Study(name="t", dataset="hopper-medium", env="hopper", seeds=(0, 1), updates=5000, eval_every=1000,
              variants=(Variant.of("pretrained", "td3bc", pretrain_updates=2000),
                        Variant.of("scratch", "td3bc", pretrain="none"),
                        Variant.of("critic-only", "td3bc", pretrain="critic", pretrain_updates=2000)),
              reference="scratch")
ROWS = (rows_of("pretrained", [[20, 40, 60, 80, 90], [30, 60, 50, 70, 70]], PRE + RL)
        + rows_of("scratch", [[0, 10, 30, 50, 60], [0, 20, 40, 60, 80]], RL + RL[:2])
        + rows_of("critic-only", [[5, 5, 30, 60, 75], [5, 5, 40, 50, 65]], PRE + RL))


def summary_by_hand():
    return summarize(STUDY, ROWS, pretrain_ends_of(ROWS), behaviour=35.0)


def test_the_bc_level_the_improvement_and_the_bc_relative_thresholds_by_hand():
    summary = {s["variant"]: s for s in summary_by_hand()}
    pre, scratch, critic = summary["pretrained"], summary["scratch"], summary["critic-only"]
    # the hand-over: pretrained's last evaluation before offline RL, at 2000: 40 and 60, mean 50; its finals (the last
    # evaluation: 10 % of 5 rounds to 1) are 90 and 70, so it improves on BC by 50 and 10, IQM of two = their mean
    assert pre["bc_level"]["source"] == "pretrained" and pre["bc_level"]["update"] == 2000
    assert pre["bc_level"]["scores"] == [40, 60] and pre["bc_level"]["mean"] == 50
    assert pre["improvement_over_bc"] == [50, 10]
    assert pre["improvement_iqm"] == {"value": 30.0, "low": 10.0, "high": 50.0}  # two values: their ends
    # scratch and critic-only (whose actor is not pre-trained) are measured from pretrained's level, seed i against
    # seed i: 60 - 40, 80 - 60 and 75 - 40, 65 - 60
    for s in (scratch, critic):
        assert s["bc_level"] == pre["bc_level"] and s["comparison_bc_level"] == pre["bc_level"]
    assert scratch["improvement_over_bc"] == [20, 20] and critic["improvement_over_bc"] == [35, 5]
    # the best seed-mean evaluation is pretrained's 80 at 5000: BC + 50 % of the way from 50 to 80 is 65, + 90 % 77
    assert pre["best_score"] == 80
    by = {r["threshold"]: r for r in pre["reach"]}
    assert by["BC + 50% to best"]["score"] == 65 and by["BC + 90% to best"]["score"] == pytest.approx(77)
    assert [r["threshold"] for r in scratch["reach"]] == [r["threshold"] for r in pre["reach"]]
    # pretrained reaches 65 at 4000 on both seeds (seed 1: 60, 50, then 70), 77 at 4000 and never (censored at 5000)
    assert by["BC + 50% to best"]["updates"] == [4000, 4000] and by["BC + 50% to best"]["by_bc_actor"] == [False] * 2
    assert by["BC + 90% to best"]["updates"] == [4000, 5000] and by["BC + 90% to best"]["censored"] == [False, True]
    # the behaviour data's 35: seed 0 at 2000 (40), seed 1 at 2000 (60): both at the hand-over, by the BC actor
    assert by["behaviour data"]["updates"] == [2000, 2000] and by["behaviour data"]["by_bc_actor"] == [True, True]
    # only a variant with a hand-over of its own has a BC actor
    assert all("by_bc_actor" not in r for r in scratch["reach"] + critic["reach"])
    # speed-ups: scratch reaches 65 never and at 5000: 5000 / 4000, every resample the same; 35 at 4000 and 3000
    sp = {x["threshold"]: x for x in pre["vs_reference"]["speedup"]}
    assert sp["BC + 50% to best"]["updates"] == {"value": 1.25, "low": 1.25, "high": 1.25}
    assert sp["BC + 50% to best"]["by_bc_actor"] == 0 and sp["BC + 50% to best"]["reference_censored"] == 1
    assert sp["behaviour data"]["updates"]["value"] == 1.75 and sp["behaviour data"]["by_bc_actor"] == 2
    assert sp["behaviour data"]["seeds"] == 2


def test_the_tables_show_the_bc_level_and_flag_what_the_bc_actor_reached():
    summary = summary_by_hand()
    text = summary_table(summary)
    assert ("| pretrained | 50.0 [40.0, 60.0] | 40 60 | its actor at the hand-over, update 2,000 | 30.0 [10.0, 50.0] "
            "| 50 10 |") in text
    assert ("| scratch | 50.0 [40.0, 60.0] | 40 60 | pretrained's actor at the hand-over, update 2,000 | "
            "20.0 [20.0, 20.0] | 20 20 |") in text
    assert "| behaviour data | 35.0 | 2k 2k (2 of 2 by the BC actor) | 4k 3k |" in text
    assert "| BC + 50% to best | 65.0 | 4k 4k | >5k 5k (1 censored) | ≥ 1.25x [1.25, 1.25] |" in text
    assert ("BC + x % to best: x % of the way from the BC level (50.0, pretrained's actor at the hand-over, update "
            "2,000) to the best seed-mean evaluation (80.0); 'by the BC actor': reached at or before") in text
    claims = claims_table([summary], ["toy"]).splitlines()
    # the comparison's level (mean 50, pretrained's at 2000) and the speed-ups to 65 and 77; 77: scratch [>5k, 5k]
    # against pretrained [4k, >5k], the latter's resample means 4000, 4500, 5000, each end with probability 1/4;
    # both arms have a censored seed there, so that ratio bounds nothing
    row = next(line for line in claims if line.startswith("| toy | pretrained vs scratch |"))
    assert row.endswith("| 50.0 (pretrained at 2,000) | ≥ 1.25x [1.25, 1.25] | 1.11x [1.00, 1.25] (both censored) |")
    assert "| toy | critic-only vs scratch |" in claims_table([summary], ["toy"])
    # the figures' line: one per comparison, at the level's seed mean
    assert figure_lines(summary) == [(50.0, "BC level: pretrained at 2,000 (50.0)")]


def test_a_bc_arm_is_the_level_of_a_study_without_a_hand_over():
    study = Study(name="t", dataset="door-human", env="door", seeds=(0, 1), updates=2000, eval_every=1000,
                  variants=(Variant.of("BC", "bc"), Variant.of("TD3+BC", "td3bc", pretrain="none")))
    rows = (rows_of("BC", [[3, 5], [4, 9]], ["actor_pretrain"] * 2)
            + rows_of("TD3+BC", [[1, 2], [10, 12]], RL[:2]))
    summary = {s["variant"]: s for s in summarize(study, rows, pretrain_ends_of(rows))}
    bc, td3bc = summary["BC"], summary["TD3+BC"]
    # the BC arm's level is its final score (the last evaluation); it has no improvement over itself
    assert bc["bc_level"]["scores"] == [5, 9] and bc["bc_level"]["update"] is None
    assert bc["improvement_over_bc"] is None and bc["improvement_iqm"] is None
    assert td3bc["bc_level"]["source"] == "BC" and td3bc["improvement_over_bc"] == [-3, 3]
    assert "by_bc_actor" not in str(bc["reach"])  # a BC arm never hands over to RL
    text = summary_table(list(summary.values()))
    assert "| BC | 7.0 [5.0, 9.0] | 5 9 | its final score (a BC arm) | n/a (BC) |  |" in text
    assert "| TD3+BC | 7.0 [5.0, 9.0] | 5 9 | BC's final score (a BC arm) | 0.0 [-3.0, 3.0] | -3 3 |" in text
    assert figure_lines(list(summary.values())) == [(7.0, "BC level: BC final, a BC arm (7.0)")]
    # 7 + 50 % of the way to the best seed-mean evaluation (7 at 2000, BC's): no way to go, no such threshold
    assert not any(r["threshold"].startswith("BC +") for r in td3bc["reach"])


def test_a_study_without_pre_training_or_bc_prints_nothing_new():
    study = Study(name="t", dataset="hopper-medium", env="hopper", seeds=(0, 1), updates=2000, eval_every=1000,
                  variants=(Variant.of("a", "td3bc", pretrain="none"), Variant.of("b", "td3bc", pretrain="none")),
                  reference="a")
    rows = rows_of("a", [[1, 2], [3, 4]], RL[:2]) + rows_of("b", [[1, 5], [3, 6]], RL[:2])
    summary = summarize(study, rows, pretrain_ends_of(rows))
    assert all(s["bc_level"] is None and s["improvement_over_bc"] is None for s in summary)
    assert not any(r["threshold"].startswith("BC +") for s in summary for r in s["reach"])
    assert "BC" not in summary_table(summary) and figure_lines(summary) == []
    row = next(line for line in claims_table([summary], ["x"]).splitlines() if line.startswith("| x |"))
    assert row.endswith("| n/a | n/a | n/a |")


def test_curves_without_phases_have_no_hand_over():
    """curves.csv of runs made before phases were recorded: no hand-over is known, so no BC level."""
    rows = [{k: v for k, v in r.items() if k != "phase"} for r in ROWS]
    assert all(s["bc_level"] is None for s in summarize(STUDY, rows, pretrain_ends_of(rows)))


def test_the_bc_level_statistics_by_hand():
    updates = np.array([1000, 2000, 3000])
    scores = np.array([[10.0, 40, 80], [20, 60, 70]])
    assert stats.score_at(updates, scores, 2000).tolist() == [40, 60]
    with pytest.raises(ValueError):
        stats.score_at(updates, scores, 2500)  # not an evaluation
    assert stats.way_from(50.0, 80.0, 0.5) == 65 and stats.way_from(-10.0, 10.0, 0.9) == 8
    reach, censored = np.array([2000, 3000, 3000]), np.array([False, False, True])
    assert stats.reached_by(reach, censored, 2000).tolist() == [True, False, False]
    assert stats.reached_by(reach, censored, 3000).tolist() == [True, True, False]  # censored: never reached


def test_a_committed_run_is_reported_with_its_bc_level(capsys):
    """A run committed before BC levels were recorded gets them from its curves.csv: the pre-trained arm's scores at
    its last pre-training evaluation, read here straight from the file."""
    import csv
    from pathlib import Path

    from experiments import report

    run = Path(__file__).resolve().parents[1] / "results" / "mujoco_medium" / "default-5seeds"
    if not (run / "curves.csv").is_file():
        pytest.skip("the committed run is not in this checkout")
    with open(run / "curves.csv", newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["variant"] == "pretrained" and r["phase"] != "offline_rl"]
    end = max(int(r["update"]) for r in rows)
    at_end = [float(r["score"]) for r in sorted(rows, key=lambda r: int(r["seed"])) if int(r["update"]) == end]
    assert report.main([str(run), "--no-reference"]) == 0
    out = capsys.readouterr().out
    cells = " ".join(f"{x:.0f}" for x in at_end)
    assert f"| pretrained | {stats.interval([np.array(at_end)], stats.iqm).text()} | {cells} | its actor at the " \
           f"hand-over, update {end:,} |" in out
    assert f"| scratch | {stats.interval([np.array(at_end)], stats.iqm).text()} | {cells} | pretrained's actor" in out
