"""A run spread over 2 local CPU processes (`jax.distributed`, gloo collectives, a localhost coordinator) equals the
same run in one process: same curves to float tolerance, one set of files written by process 0, and `--resume`."""
from __future__ import annotations

import csv
import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

SCRIPT = r"""
import sys
from pathlib import Path
out, n, pid, port, updates = Path(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), sys.argv[4], int(sys.argv[5])
from offrl_jax import distributed
if n > 1:
    distributed.initialize(f"localhost:{port}", n, pid)
sys.path.insert(0, "tests")
from conftest import synthetic_dataset
from offrl_jax.runner import run_study
from offrl_jax.study import Study, Variant
study = Study(name="d", dataset="synthetic", env="hopper", seeds=(0, 1, 2, 3), updates=updates, eval_every=100,
              eval_episodes=1, batch_size=32, variants=(
                  Variant.of("pretrained", "td3bc", pretrain="actor+critic", pretrain_updates=100, hidden=(16, 16)),))
run_study(study, out, synthetic_dataset(), resume=(out / "checkpoints").is_dir(), progress=False)
"""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("localhost", 0))
        return s.getsockname()[1]


def launch(out: Path, processes: int, updates: int) -> None:
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    port = free_port()
    procs = [subprocess.Popen([sys.executable, "-c", SCRIPT, str(out), str(processes), str(i), str(port),
                               str(updates)], cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                              text=True) for i in range(processes)]
    outputs = [p.communicate(timeout=600)[0] for p in procs]
    assert all(p.returncode == 0 for p in procs), "\n".join(o[-3000:] for o in outputs)


def rows(run: Path) -> dict[tuple, dict]:
    return {(r["variant"], r["seed"], r["update"]): r for r in csv.DictReader((run / "curves.csv").open())}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    base = tmp_path_factory.mktemp("distributed")
    launch(base / "one", 1, 300)
    launch(base / "two", 2, 200)  # then resumed to 300 by two processes again
    launch(base / "two", 2, 300)
    return base / "one", base / "two"


def test_two_processes_equal_one(runs):
    one, two = rows(runs[0]), rows(runs[1])
    assert one.keys() == two.keys() and len(one) == 4 * 3
    for key, a in one.items():
        b = two[key]
        for name in ("score", "critic_loss", "actor_loss", "q_mean"):
            if a.get(name):
                x, y = float(a[name]), float(b[name])
                assert abs(x - y) <= 1e-3 * max(1.0, abs(x)), (key, name, x, y)


def test_process_zero_writes_one_set_of_files(runs):
    two = runs[1]
    summary = json.loads((two / "summary.json").read_text())
    assert [s["variant"] for s in summary] == ["pretrained"]
    assert sorted(p.name for p in (two / "checkpoints").iterdir()) == ["pretrained.best.msgpack", "pretrained.msgpack"]
    assert len(json.loads((two / "config.json").read_text())["runs"]) == 2  # the start and the resume
