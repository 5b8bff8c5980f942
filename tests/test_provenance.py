"""What a run records about itself: the resolved config of every variant and where the run came from."""
import json

import numpy as np

from offrl_jax.run.provenance import command_line, fingerprint, run_record
from offrl_jax.run.runner import run_study
from offrl_jax.run.study import Study, Variant


def test_config_json_holds_the_resolved_config_and_round_trips(tiny_dataset):
    study = Study(name="t", dataset="hopper-medium", env="hopper", seeds=(0,), updates=20_000, eval_every=1_000,
                  variants=(Variant.of("default", "td3bc"), Variant.of("a2.5", "td3bc", alpha=2.5)))
    text = study.record_json(tiny_dataset)
    raw = json.loads(text)
    assert Study.from_json(text) == study  # what the run wrote about itself does not change the study
    resolved = raw["resolved"]
    assert resolved["default"]["alpha"] == 10.0  # hopper's per-env default, which the overrides do not show
    assert resolved["a2.5"]["alpha"] == 2.5
    for field in ("actor_lr", "critic_lr", "gamma", "tau", "hidden", "policy_noise", "layer_norm_eps", "timeouts"):
        assert field in resolved["default"], field
    (record,) = raw["runs"]
    assert record["command"].startswith("python")
    assert set(record["versions"]) >= {"python", "jax", "jaxlib", "flax", "optax", "gymnasium", "mujoco", "numpy"}
    assert record["backend"]["platform"] == "cpu" and record["backend"]["device_kind"]
    assert record["dataset"] == {"source": "hopper-medium", "name": tiny_dataset.name,
                                 "transitions": len(tiny_dataset), "sha256": fingerprint(tiny_dataset)}
    assert record["git"] is None or set(record["git"]) == {"commit", "dirty"}
    # a resume adds its own record and keeps the first
    again = json.loads(study.record_json(tiny_dataset, text))
    assert len(again["runs"]) == 2 and again["runs"][0] == record


def test_fingerprint_tells_datasets_apart(tiny_dataset):
    same = fingerprint(tiny_dataset)
    assert fingerprint(tiny_dataset.select(slice(0, len(tiny_dataset)))) == same
    assert fingerprint(tiny_dataset.select(slice(0, len(tiny_dataset) - 1))) != same
    changed = tiny_dataset.select(slice(0, len(tiny_dataset)))
    changed.rewards[0] += 1.0
    assert fingerprint(changed) != same


def test_summary_carries_the_resolved_config(tmp_path, tiny_dataset):
    study = Study(name="t", dataset="hopper-medium", env="hopper", seeds=(0,), updates=200, eval_every=100,
                  variants=(Variant.of("scratch", "td3bc", pretrain="none", hidden=(16, 16)),), eval_episodes=1)
    summary = run_study(study, tmp_path, tiny_dataset, progress=False)
    saved = json.loads((tmp_path / "config.json").read_text())
    in_summary = json.loads(json.dumps(summary[0]["config"]))
    assert in_summary == saved["resolved"]["scratch"]
    assert in_summary["alpha"] == 10.0 and in_summary["hidden"] == [16, 16]
    assert json.loads((tmp_path / "summary.json").read_text())[0]["config"]["pretrain"] == "none"


def test_command_line_is_the_typed_command():
    assert command_line(["x.py", "--alpha", "2.5 10"]).endswith("'2.5 10'")
    assert np.all(run_record()["versions"]["numpy"])
