"""docs/extending.md's examples run as written: its blocks marked "(tested: ...)" are executed here."""
import importlib.util
import re
import sys
from pathlib import Path

import jax
import numpy as np
import pytest

from offrl_jax.algos import ALGOS, FAMILIES, make_config
from offrl_jax.data.device import device_data
from offrl_jax.driver import Driver

DOC = Path(__file__).resolve().parents[1] / "docs" / "extending.md"


@pytest.fixture
def doc_namespace(monkeypatch, tmp_path):
    """Every tested block of the doc, each run as a module file of its own (so `inspect` finds its source)."""
    # the registry examples must not leak into other tests
    monkeypatch.setattr("offrl_jax.algos.ALGOS", dict(ALGOS))
    monkeypatch.setattr("offrl_jax.algos.FAMILIES", dict(FAMILIES))
    marker = "(tested: tests/test_extending.py)"
    blocks = [b for b in re.findall(r"```python\n(.*?)```", DOC.read_text(), re.S) if marker in b]
    assert len(blocks) == 4
    namespace: dict = {}
    for i, block in enumerate(blocks):
        path = tmp_path / f"extending_block_{i}.py"
        path.write_text(block)
        spec = importlib.util.spec_from_file_location(path.stem, path)
        module = importlib.util.module_from_spec(spec)
        monkeypatch.setitem(sys.modules, path.stem, module)
        spec.loader.exec_module(module)
        namespace |= vars(module)
    return namespace


def test_hyper_parameter_example_is_a_flag_with_its_comment_as_help(doc_namespace):
    assert doc_namespace["args"].actor_grad_clip == 1.0
    text = doc_namespace["parser"].format_help()
    assert "--actor-grad-clip" in text and "clip the actor's gradient norm" in " ".join(text.split())


def test_every_config_field_has_a_flag():
    import dataclasses

    from experiments import finetune
    from experiments.mujoco_medium import make_parser
    from offrl_jax.algos import FAMILIES
    from offrl_jax.algos.config import ONLINE_FIELDS
    from offrl_jax.app.flags import NOT_FLAGS

    dests = {a.dest for a in make_parser()._actions}
    online = {a.dest for a in finetune.make_parser()._actions}
    for cls in (family.config for family in FAMILIES.values()):
        for f in dataclasses.fields(cls):
            if f.name in ONLINE_FIELDS:  # the fine-tuning study's flags only: an offline study would ignore them
                assert f.name in online and f.name not in dests, f.name
                continue
            assert f.name in dests or f.name in NOT_FLAGS or f.name == "pretrain_auto", f.name
    assert {"pretrain", "pretrain_updates"} <= dests  # the study's own flags for those


def test_registry_example_makes_a_checked_config(doc_namespace):
    from offrl_jax import algos
    assert "td3bc_maxmc" in algos.ALGOS and "td3bc_maxmc" not in ALGOS
    config = algos.make_config("td3bc_maxmc", "hopper")
    assert config.target == "max_mc" and config.pretrain == "none" and config.alpha == 10.0  # hopper's alpha


def test_sequential_pretraining_example_runs_its_three_phases(doc_namespace, tiny_dataset):
    config = make_config("td3bc", "hopper", pretrain="actor+critic", pretrain_updates=200, hidden=(32, 32))
    algo = doc_namespace["SequentialPretrainTD3BC"](config, tiny_dataset.obs_dim, tiny_dataset.act_dim)
    data = device_data(tiny_dataset, config.gamma).arrays
    phases, metrics, actors = [], [], []
    for chunk in Driver(algo, data, seeds=(0, 1), batch_size=32).run(algo.phases(400), chunk_updates=100):
        # copies: the driver donates each chunk's state buffers to the next
        phases.append(chunk.phase)
        metrics.append(set(chunk.metrics))
        actors.append([np.array(x) for x in jax.tree.leaves(chunk.states.actor.params)])
    assert phases == ["actor_pretrain", "critic_pretrain", "offline_rl", "offline_rl"]
    assert "bc_loss" in metrics[0] and "critic_loss" in metrics[1]
    for a, b in zip(actors[0], actors[1]):  # the critic phase leaves the BC actor as it was
        np.testing.assert_array_equal(a, b)
    assert any(not np.array_equal(a, b) for a, b in zip(actors[1], actors[3]))  # TD3+BC then trains it


def test_new_family_example_runs_through_the_runner(doc_namespace, tmp_path, tiny_dataset):
    """The doc's family is its file plus two registry lines: its config is checked, and a study trains, evaluates,
    summarises and resumes it as it does the built-in families."""
    import json

    from offrl_jax import algos
    from offrl_jax.run.results import read_curves
    from offrl_jax.run.runner import run_study
    from offrl_jax.run.study import Study, Variant

    assert "mse_bc" in algos.FAMILIES and "mse_bc" not in FAMILIES
    with pytest.raises(ValueError, match="MSEBCConfig.weight_decay = -1.0 must be >= 0"):
        algos.make_config("mse_bc", "hopper", weight_decay=-1.0)
    with pytest.raises(ValueError, match="MSEBCConfig.gamma = 1.5 must be in"):  # the shared fields' checks
        algos.make_config("mse_bc", "hopper", gamma=1.5)
    study = Study(name="t", dataset="synthetic", env="hopper", seeds=(0, 1), updates=200, eval_every=100,
                  eval_episodes=1, batch_size=32,
                  variants=(Variant.of("BC", "mse_bc", weight_decay=1e-4, hidden=(16, 16)),))
    run_study(study, tmp_path, tiny_dataset, progress=False)
    rows = read_curves(tmp_path / "curves.csv")
    assert [(r["update"], r["seed"]) for r in rows] == [(100, 0), (100, 1), (200, 0), (200, 1)]
    assert json.loads((tmp_path / "config.json").read_text())["resolved"]["BC"]["weight_decay"] == 1e-4
    (summary,) = json.loads((tmp_path / "summary.json").read_text())
    assert summary["variant"] == "BC"


def test_a_run_resolves_each_config_once(monkeypatch, tmp_path, tiny_dataset):
    """A variant's config is built once, when it is made: the runner and the summary read it from the study; a
    resume resolves each once more, to refuse a config.json edited by hand."""
    from offrl_jax.run import variant as variant_module
    from offrl_jax.run.runner import run_study
    from offrl_jax.run.study import Study, Variant

    calls = []
    real = variant_module.resolve
    monkeypatch.setattr(variant_module, "resolve", lambda *a, **k: calls.append(a[0]) or real(*a, **k))
    study = Study(name="t", dataset="synthetic", env="hopper", seeds=(0,), updates=200, eval_every=100,
                  eval_episodes=1, batch_size=32,
                  variants=(Variant.of("a", "td3bc", hidden=(16, 16), pretrain_updates=100),
                            Variant.of("b", "bc", hidden=(16, 16))))
    assert calls == ["td3bc", "bc"]
    run_study(study, tmp_path, tiny_dataset, progress=False)
    assert calls == ["td3bc", "bc"], calls
    run_study(study, tmp_path, tiny_dataset, progress=False, resume=True)  # the resume check included
    assert calls == ["td3bc", "bc"] * 2, calls
