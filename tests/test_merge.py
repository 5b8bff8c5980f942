"""`experiments.report --merge OUT --relabel RUN...`: fine-tuning runs of different algorithms on the same data and
budget joined into one study (`offrl_jax.run.merge`), from two tiny real runs of `experiments.finetune`: TD3+BC's
scratch and pretrained arms, IQL's pretrained arm."""
import json
import shutil

import h5py
import numpy as np
import pytest

from offrl_jax.run.results import read_curves
from offrl_jax.run.study import Study
from tests.conftest import synthetic_dataset
from tests.entry import run_module

TINY = ["--env", "hopper", "--updates", "200", "--eval-every", "100", "--pretrain-updates", "100", "--seeds", "2",
        "--online-steps", "200", "--online-block", "100", "--online-eval-every", "100",
        "--hidden", "16", "16", "--eval-episodes", "1", "--parallel", "1", "--no-progress"]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """{algorithm: its finished run directory}: td3bc with scratch and pretrained, iql with pretrained, on a tiny
    hopper dataset (hopper-medium takes seconds to read)."""
    root = tmp_path_factory.mktemp("finetune")
    ds = synthetic_dataset(2000, env="hopper", episode_len=100)
    with h5py.File(root / "hopper-tiny.hdf5", "w") as f:
        for key in ("observations", "actions", "rewards", "next_observations", "terminals", "timeouts"):
            f[key] = getattr(ds, key)
    made = {}
    for algo, arms in (("td3bc", ["scratch", "pretrained"]), ("iql", ["pretrained"])):
        done = run_module("experiments.finetune", *TINY, "--dataset-path", root / "hopper-tiny.hdf5", "--algo", algo,
                          "--arms", *arms, "--out", root / algo)
        assert done.returncode == 0, done.stderr
        made[algo] = root / algo
    return made


def copy_run(run, to):
    """A run's config.json, curves.csv and summary.json in `to` (what --merge reads)."""
    to.mkdir()
    for name in ("config.json", "curves.csv", "summary.json"):
        shutil.copy(run / name, to / name)
    return to


def test_relabel_merges_two_algorithms_into_one_study_with_one_reference_and_one_online_threshold(runs, tmp_path):
    out = tmp_path / "all"
    done = run_module("experiments.report", "--merge", out, "--relabel", runs["td3bc"], runs["iql"])
    assert done.returncode == 0, done.stderr
    labels = ["td3bc-scratch", "td3bc-pretrained", "iql-pretrained"]
    study = Study.from_json((out / "config.json").read_text())
    assert [v.label for v in study.variants] == labels and [v.algo for v in study.variants] == ["td3bc", "td3bc", "iql"]
    assert study.reference == "td3bc-scratch" and study.name == "hopper-tiny-td3bc+iql"
    # every row as its run wrote it, under its new label
    rows = read_curves(out / "curves.csv")
    key = lambda r: (r["variant"], r["seed"], r["update"], r.get("env_steps"))  # noqa: E731
    before = {(f"{r['algo']}-{r['variant']}",) + key(r)[1:]: r["score"]
              for algo in ("td3bc", "iql") for r in read_curves(runs[algo] / "curves.csv")}
    assert {key(r): r["score"] for r in rows} == before
    summary = {s["variant"]: s for s in json.loads((out / "summary.json").read_text())}
    assert list(summary) == labels
    assert "vs_reference" not in summary["td3bc-scratch"]
    assert {summary[v]["vs_reference"]["reference"] for v in labels[1:]} == {"td3bc-scratch"}
    # the online phase of every arm, its env steps to 90 % of the best seed-mean online evaluation of any arm: one
    # threshold, from both runs' rows
    best = max(np.mean([r["score"] for r in rows if r["variant"] == v and r.get("env_steps") == steps])
               for v in labels for steps in (100.0, 200.0))
    (threshold,) = {(s["online"]["reach"][-1]["threshold"], s["online"]["reach"][-1]["score"])
                    for s in summary.values()}
    assert threshold == ("90% of best", pytest.approx(0.9 * best))
    assert all(len(s["online"]["final"]["per_seed"]) == 2 for s in summary.values())
    for label in labels:
        assert f"| {label} | " in done.stdout.split("Online phase (200 env steps per seed")[1]
    assert f"| 90% of best ({0.9 * best:.1f}) |" in done.stdout and (out / "online.png").stat().st_size > 0


def test_without_relabel_runs_of_two_algorithms_are_refused_as_before(runs, tmp_path):
    out = tmp_path / "m"
    done = run_module("experiments.report", "--merge", out, runs["td3bc"], runs["iql"])
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    assert "name differ (--relabel merges runs of different algorithms)" in done.stderr and not out.exists()
    alone = run_module("experiments.report", "--relabel", runs["iql"])
    assert alone.returncode == 2 and "give --merge too" in alone.stderr


def test_relabel_refuses_runs_of_other_seeds_and_an_arm_trained_twice(runs, tmp_path):
    other = copy_run(runs["iql"], tmp_path / "other-seeds")
    raw = json.loads((other / "config.json").read_text())
    (other / "config.json").write_text(json.dumps(raw | {"seeds": [1, 2]}))
    out = tmp_path / "m"
    done = run_module("experiments.report", "--merge", out, "--relabel", runs["td3bc"], other)
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    assert "seeds differ" in done.stderr and not out.exists()
    again = copy_run(runs["td3bc"], tmp_path / "again")
    done = run_module("experiments.report", "--merge", out, "--relabel", runs["td3bc"], runs["iql"], again)
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    assert f"{runs['td3bc']} and {again} both trained td3bc-scratch" in done.stderr and not out.exists()


def test_relabelled_keeps_a_swept_reference_and_the_merged_name_says_data_and_algorithms():
    from offrl_jax.run.merge import merged_name, relabelled
    from offrl_jax.run.study import Variant, reference_label

    common = dict(dataset="data/my hopper.hdf5", env="hopper", seeds=(0,), updates=200, eval_every=100)
    sweep = Study(name="a", reference="scratch", variants=tuple(
        Variant.of(f"{arm} alpha={alpha}", "td3bc", pretrain=pretrain, pretrain_updates=100, alpha=alpha)
        for arm, pretrain in (("scratch", "none"), ("pretrained", "actor+critic")) for alpha in (1.0, 2.0)), **common)
    moved = relabelled(sweep)
    assert [v.label for v in moved.variants][:2] == ["td3bc-scratch alpha=1.0", "td3bc-scratch alpha=2.0"]
    assert moved.reference == "td3bc-scratch"
    assert reference_label(moved, "td3bc-pretrained alpha=2.0") == "td3bc-scratch alpha=2.0"
    iql = Study(name="b", variants=(Variant.of("pretrained", "iql", pretrain_updates=100),), **common)
    assert merged_name([sweep, iql]) == "my-hopper-td3bc+iql" and merged_name([sweep, sweep]) == "a"
