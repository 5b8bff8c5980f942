"""docs/extending.md's examples run as written: its blocks marked "(tested: ...)" are executed here."""
import importlib.util
import re
import sys
from pathlib import Path

import jax
import numpy as np
import pytest

from offrl_jax.algos import ALGOS, make_config
from offrl_jax.driver import Driver, device_data

DOC = Path(__file__).resolve().parents[1] / "docs" / "extending.md"


@pytest.fixture
def doc_namespace(monkeypatch, tmp_path):
    """Every tested block of the doc, each run as a module file of its own (so `inspect` finds its source)."""
    monkeypatch.setattr("offrl_jax.algos.ALGOS", dict(ALGOS))  # the registry example must not leak into other tests
    marker = "(tested: tests/test_extending.py)"
    blocks = [b for b in re.findall(r"```python\n(.*?)```", DOC.read_text(), re.S) if marker in b]
    assert len(blocks) == 3
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

    from experiments.flags import NOT_FLAGS
    from experiments.mujoco_medium import make_parser
    from offrl_jax.algos import EDACConfig, TD3BCConfig

    dests = {a.dest for a in make_parser()._actions}
    for cls in (TD3BCConfig, EDACConfig):
        for f in dataclasses.fields(cls):
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
    data, _ = device_data(tiny_dataset, config.gamma)
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
