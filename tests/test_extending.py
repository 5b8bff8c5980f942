"""docs/extending.md's examples run as written: its blocks marked "(tested: ...)" are executed here."""
import re
from pathlib import Path

import jax
import numpy as np
import pytest

from offrl_jax.algos import ALGOS, make_config
from offrl_jax.driver import Driver, device_data

DOC = Path(__file__).resolve().parents[1] / "docs" / "extending.md"


@pytest.fixture
def doc_namespace(monkeypatch):
    monkeypatch.setattr("offrl_jax.algos.ALGOS", dict(ALGOS))  # the registry example must not leak into other tests
    marker = "(tested: tests/test_extending.py)"
    blocks = [b for b in re.findall(r"```python\n(.*?)```", DOC.read_text(), re.S) if marker in b]
    assert len(blocks) == 2
    namespace: dict = {}
    for block in blocks:
        exec(compile(block, str(DOC), "exec"), namespace)
    return namespace


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
