"""The fidelity command (`experiments.fidelity`): the target bands, the table built from two studies' summaries
(hand-made here), and a tiny end-to-end run that writes fidelity.json."""
import json
import math

import pytest

from experiments.fidelity import table
from offrl_jax.data.generate.collect import MEDIUM_TARGET_SCORE
from offrl_jax.data.generate.reference import D4RL_V2, target_band
from tests.entry import run_module


def test_target_band_is_the_tolerance_or_corl_spread_whichever_is_wider():
    assert target_band(44.0) == (39.0, 49.0)
    assert target_band((53.51, 1.76)) == pytest.approx((48.51, 58.51))
    assert target_band((63.23, 16.24)) == pytest.approx((46.99, 79.47))  # walker2d's BC: CORL's own spread


def test_medium_targets_are_read_from_the_reference_table():
    assert MEDIUM_TARGET_SCORE == {"hopper": 44.0, "halfcheetah": 40.0, "walker2d": 62.0}
    assert D4RL_V2["hopper-medium"]["bc"] == (53.51, 1.76)


def _summary(path, updates, final, low, high, behaviour=46.0):
    path.mkdir(parents=True)
    s = {"dataset": "hopper-medium", "updates": updates, "seeds": [0, 1], "behaviour_score": behaviour,
         "final_iqm": {"value": final, "low": low, "high": high}}
    (path / "summary.json").write_text(json.dumps([s]))


def test_table_sets_each_measure_beside_its_reference(tmp_path):
    _summary(tmp_path / "bc", 20_000, 57.0, 50.0, 60.0)
    _summary(tmp_path / "td3bc", 100_000, 70.0, 65.0, 75.0)
    result = table(tmp_path, "hopper", "medium")
    rows = {r["measure"]: r for r in result["rows"]}
    assert rows["behaviour data"]["ours"] == 46.0 and rows["behaviour data"]["within"] is True  # 39-49
    assert rows["BC, 20,000 updates"]["within"] is True  # 48.5-58.5
    assert rows["TD3+BC from scratch, 100,000 updates"]["within"] is False  # 55.4-65.4
    assert result["seeds"] == 2 and result["reference_updates"] == 1_000_000


def test_a_tiny_fidelity_run_writes_its_table(tmp_path):
    out = tmp_path / "fid"
    result = run_module("experiments.fidelity", "--bc-updates", "40", "--td3bc-updates", "20", "--seeds", "1",
                        "--eval-episodes", "1", "--max-transitions", "2000", "--out", out, "--no-progress")
    assert result.returncode == 0, result.stderr
    saved = json.loads((out / "fidelity.json").read_text())
    assert [r["measure"] for r in saved["rows"]] == ["behaviour data", "BC, 40 updates",
                                                     "TD3+BC from scratch, 20 updates"]
    assert "| BC, 40 updates |" in result.stdout
    config = json.loads((out / "td3bc" / "config.json").read_text())
    assert "alpha" in json.dumps(config)


def test_fidelity_takes_no_flag_it_would_ignore(tmp_path):
    """Its settings are CORL's: no hyper-parameter flags, and its budgets are its own flags."""
    assert run_module("experiments.fidelity", "--alpha", "3").returncode == 2
    refused = run_module("experiments.fidelity", "--updates", "5000", "--out", tmp_path / "x")
    assert refused.returncode == 2 and "--bc-updates" in refused.stderr and not (tmp_path / "x").exists()
    dry = run_module("experiments.fidelity", "--dry-run", "--td3bc-updates", "30000", cwd=tmp_path)
    assert dry.returncode == 0, dry.stderr
    assert "study bc" in dry.stdout and "study td3bc" in dry.stdout and "30,000 updates" in dry.stdout
    assert "alpha = 2.5  (study)" in dry.stdout and list(tmp_path.iterdir()) == []


def test_scan_scores_each_checkpoint_of_a_sac_run(tmp_path):
    """A tiny SAC run's checkpoint: its behaviour sample and BC on it, one line in scan.jsonl; a missing step is
    one line, nothing written."""
    from offrl_jax.data.generate.sac import SACConfig, train

    run = tmp_path / "sac"
    train("hopper", 300, run, seed=0, cfg=SACConfig(hidden=(32, 32), batch_size=32, warmup_steps=100),
          eval_every=150, eval_episodes=1, progress=False, max_episode_steps=50)
    missing = run_module("experiments.scan_checkpoints", "--run", run, "--steps", "200", "--out", tmp_path / "none")
    assert missing.returncode == 2 and "no checkpoint at step 200" in missing.stderr
    assert not (tmp_path / "none").exists()
    out = tmp_path / "scan"
    done = run_module("experiments.scan_checkpoints", "--run", run, "--steps", "150", "--transitions", "400",
                      "--seeds", "1", "--bc-updates", "40", "--out", out)
    assert done.returncode == 0, done.stderr
    line = json.loads((out / "scan.jsonl").read_text())
    assert line["step"] == 150 and line["transitions"] == 400
    assert math.isfinite(line["bc"]) and math.isfinite(line["behaviour"])  # normalised scores of real rollouts
    assert (out / "hopper-150-n400-bc-s1-u40" / "fidelity.json").exists()
