"""A trained policy in three lines (`offrl_jax.policy`), its export, and watching it (`offrl_jax.rollout`)."""
from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from offrl_jax.policy import load_exported, load_policy
from offrl_jax.rollout import rollout
from offrl_jax.run.runner import run_study
from offrl_jax.run.study import Study, Variant
from tests.entry import run_module

from .conftest import synthetic_dataset

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("policy") / "run"
    study = Study(name="t", dataset="synthetic", env="hopper", seeds=(0, 1), updates=400, eval_every=100,
                  eval_episodes=2, batch_size=32, keep_checkpoints=2,
                  variants=(Variant.of("scratch", "td3bc", pretrain="none", hidden=(32, 32)),
                            Variant.of("edac", "edac", pretrain="none", hidden=(32, 32), num_critics=2)))
    run_study(study, out, synthetic_dataset(), progress=False)
    return out


def last_score(run: Path, variant: str, seed: int) -> float:
    rows = [r for r in csv.DictReader((run / "curves.csv").open()) if r["variant"] == variant and
            int(r["seed"]) == seed]
    return float(max(rows, key=lambda r: int(r["update"]))["score"])


@pytest.mark.parametrize("variant", ["scratch", "edac"])
def test_the_loaded_policy_scores_what_the_run_evaluated(run, variant):
    from offrl_jax.envs.registry import normalized_score

    policy = load_policy(run, variant, seed=1)
    assert (policy.env, policy.variant, policy.seed, policy.update) == ("hopper", variant, 1, 400)
    score = float(np.mean(normalized_score("hopper", rollout(policy, episodes=2))))
    assert score == pytest.approx(last_score(run, variant, 1), abs=1e-3)


def test_a_checkpoint_path_that_is_a_directory_is_named_as_one(run, tmp_path):
    import shutil

    copy = Path(shutil.copytree(run, tmp_path / "copy"))
    target = copy / "checkpoints" / "scratch.msgpack"
    target.unlink()
    target.mkdir()
    with pytest.raises(ValueError, match="not a checkpoint file \\(a directory\\)"):
        load_policy(copy, "scratch")


def test_the_best_checkpoint_is_the_best_evaluation(run):
    rows = [r for r in csv.DictReader((run / "curves.csv").open()) if r["variant"] == "scratch"]
    means = {}
    for r in rows:
        means.setdefault(int(r["update"]), []).append(float(r["score"]))
    best_update = max(means, key=lambda u: np.mean(means[u]))
    policy = load_policy(run, "scratch", seed=0, checkpoint="best")
    assert policy.update == best_update
    from flax import serialization

    payload = serialization.msgpack_restore((run / "checkpoints" / "scratch.best.msgpack").read_bytes())
    assert payload["best_score"] == pytest.approx(np.mean(means[best_update]))
    assert payload["members"] == [["scratch", 0], ["scratch", 1]]


def test_keep_n_keeps_the_newest_periodic_checkpoints(run):
    from offrl_jax.envs.registry import normalized_score

    kept = sorted(p.name for p in (run / "checkpoints").glob("*.*00.msgpack"))
    assert kept == ["edac.300.msgpack", "edac.400.msgpack", "scratch.300.msgpack", "scratch.400.msgpack"]
    policy = load_policy(run, "scratch", seed=1, checkpoint=300)
    assert policy.update == 300
    rows = [r for r in csv.DictReader((run / "curves.csv").open())
            if r["variant"] == "scratch" and int(r["seed"]) == 1 and int(r["update"]) == 300]
    score = float(np.mean(normalized_score("hopper", rollout(policy, episodes=2))))
    assert score == pytest.approx(float(rows[0]["score"]), abs=1e-3)
    with pytest.raises(ValueError, match="kept updates: 300, 400"):
        load_policy(run, "scratch", checkpoint=100)


def test_one_observation_or_a_batch(run):
    policy = load_policy(run)
    obs = np.random.default_rng(0).normal(size=(5, 11)).astype(np.float32)
    batch = policy(obs)
    assert batch.shape == (5, 3) and np.all(np.abs(batch) <= 1)
    np.testing.assert_allclose(policy(obs[2]), batch[2], rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("obs, message", [
    (np.full(11, np.nan), "observation 0 has a non-finite value"),
    (np.stack([np.zeros(11), np.r_[np.zeros(10), np.inf]]), "observation 1 has a non-finite value"),
    (np.zeros(7), r"shaped \(7,\)"),
    (np.zeros((2, 3, 11)), r"shaped \(2, 3, 11\)"),
    ([["a"] * 11], "must be real numbers"),
    (np.full(11, 1 + 1j), "must be real numbers"),
    (np.full(11, 3e38), "action for observation 0 is not finite"),
])
def test_bad_observations_are_refused_not_acted_on(run, obs, message):
    policy = load_policy(run)
    with pytest.raises(ValueError, match=message):
        policy(obs)


def test_the_export_acts_like_the_policy_without_training_code(run, tmp_path):
    policy = load_policy(run, "edac", seed=0)
    path = policy.export(tmp_path / "edac.jaxexport")
    obs = np.random.default_rng(1).normal(size=(7, 11)).astype(np.float32)
    act = load_exported(path)
    np.testing.assert_allclose(act(obs), policy(obs), rtol=1e-6, atol=1e-6)
    assert act(obs[:1]).shape == (1, 3)  # any batch size
    np.testing.assert_allclose(act(obs[0]), policy(obs[0]), rtol=1e-6, atol=1e-6)  # one observation, as the policy
    with pytest.raises(ValueError, match=r"observations of shape \(7, 12\): expected \(11,\) or \(B, 11\)"):
        act(np.zeros((7, 12)))
    with pytest.raises(ValueError, match="must be finite"):
        act(np.full(11, np.nan))
    assert act(np.zeros((0, 11))).shape == (0, 3)
    for name, data in (("garbage", b"not an export"), ("half", path.read_bytes()[:200])):
        (tmp_path / name).write_bytes(data)
        with pytest.raises(ValueError, match=f"{name}: not an exported policy"):
            load_exported(tmp_path / name)
    with pytest.raises(ValueError, match="none.jaxexport: cannot be read"):
        load_exported(tmp_path / "none.jaxexport")


@pytest.mark.parametrize("args, message", [
    ({"variant": "nope"}, "no variant 'nope'; the run has scratch, edac"),
    ({"seed": 7}, "no seed 7; the run has seeds 0, 1"),
])
def test_a_variant_or_seed_that_is_not_there_is_one_line(run, args, message):
    with pytest.raises(ValueError, match=message):
        load_policy(run, **args)


def test_a_directory_that_is_not_a_run_is_one_line(tmp_path):
    with pytest.raises(ValueError, match="not a saved run"):
        load_policy(tmp_path)


def test_rollout_prints_scores_and_writes_a_video(run, tmp_path):
    video = tmp_path / "scratch.gif"
    result = subprocess.run([sys.executable, "-m", "offrl_jax.rollout", str(run), "--variant", "scratch",
                             "--seed", "0", "--episodes", "2", "--video", str(video), "--max-frames", "4"],
                            cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.strip().splitlines()
    assert lines[0].startswith("episode 0: return") and lines[-1].startswith("mean: return")
    mean = float(lines[-1].split("score")[1])
    assert mean == pytest.approx(last_score(run, "scratch", 0), abs=0.05)
    import imageio.v2 as imageio

    frames = imageio.mimread(video)
    assert len(frames) == 4 and frames[0].ndim == 3 and frames[0].shape[2] in (3, 4)
    assert np.asarray(frames[0]).std() > 0  # a picture, not a blank frame


def test_rollout_refuses_bad_input_in_one_line(run, tmp_path):
    for args, message in [([str(tmp_path / "none")], "not a saved run"),
                          ([str(run), "--video", str(tmp_path / "x.avi")], "must end in .mp4 or .gif"),
                          ([str(run), "--episodes", "0"], "positive integer")]:
        result = run_module("offrl_jax.rollout", *args)
        assert result.returncode == 2 and result.stderr.strip().splitlines()[-1].startswith("error:")
        assert message in result.stderr and "Traceback" not in result.stderr


@pytest.mark.parametrize("field, value", [("data", "0" * 64), ("seeds", [5, 6])])
def test_a_checkpoint_of_another_run_is_refused(run, tmp_path, field, value):
    import json
    import shutil

    from flax import serialization

    copy = shutil.copytree(run, tmp_path / "copy")
    path = copy / "checkpoints" / "scratch.msgpack"
    payload = serialization.msgpack_restore(path.read_bytes())
    payload["identity"] = json.dumps(json.loads(payload["identity"]) | {field: value})
    path.write_bytes(serialization.msgpack_serialize(payload))
    with pytest.raises(ValueError, match="made by another run"):
        load_policy(copy, "scratch", seed=0)
