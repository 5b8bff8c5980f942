"""Seeds split over 2 (forced host) devices give the same per-seed results as one device, 3 seeds included (the
second device pads its share with a copy of the last seed, whose results are dropped)."""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

SCRIPT = r"""
import json, sys, jax, numpy as np
sys.path.insert(0, "tests")
from conftest import synthetic_dataset
from offrl_jax.algos import make_algorithm, make_config
from offrl_jax.data.device import device_data
from offrl_jax.driver import Driver
ds = synthetic_dataset(2000)
config = make_config("td3bc", "hopper", pretrain_updates=100, hidden=(32, 32))
algo = make_algorithm(config, ds.obs_dim, ds.act_dim, len(ds))
data = device_data(ds, config.gamma).arrays
driver = Driver(algo, data, (0, 1, 2), batch_size=32)
chunks = list(driver.run(algo.phases(200), 100))
leaf = jax.tree.leaves(chunks[-1].states)[0]
print(json.dumps({"devices": len(jax.devices()), "shards": driver.layout.mesh.size, "members": len(leaf),
                  "critic_loss": [c.metrics["critic_loss"].tolist() for c in chunks]}))
"""


def run(devices: int) -> dict:
    env = dict(os.environ, XLA_FLAGS=f"--xla_force_host_platform_device_count={devices}")
    out = subprocess.run([sys.executable, "-c", SCRIPT], cwd=ROOT, env=env, capture_output=True, text=True,
                         check=True, timeout=600).stdout
    return json.loads(out.strip().splitlines()[-1])


@pytest.mark.slow  # tests/test_distributed.py splits the members over two devices (of two processes) in CI
def test_two_devices_match_one():
    one, two = run(1), run(2)
    assert one["shards"] == 1 and two["devices"] == 2 and two["shards"] == 2
    assert one["members"] == two["members"] == 3  # the padding member is not reported
    for a, b in zip(one["critic_loss"], two["critic_loss"]):
        assert len(a) == len(b) == 3
        assert all(abs(x - y) <= 1e-6 * max(1.0, abs(x)) for x, y in zip(a, b)), (a, b)
