"""A run spread over 2 local CPU processes (`jax.distributed`, gloo collectives, a localhost coordinator) equals the
same run in one process: same curves to float tolerance, one set of files written by process 0, and `--resume`
(here extending the run) by two processes again.  Its 3 seeds do not divide over the 2 processes: the second
pads its share with a copy of the last seed, and evaluates one seed fewer.  The first two-process part is started
as `--processes 2` (the command starts its second process itself), the resume by hand
(`--coordinator/--num-processes/--process-id`)."""
from __future__ import annotations

import csv
import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from .conftest import synthetic_dataset

ROOT = Path(__file__).resolve().parents[1]

TINY = ["--pretrain", "actor+critic", "--pretrain-updates", "100", "--eval-every", "100", "--eval-episodes", "1",
        "--seeds", "3", "--hidden", "16", "16", "--batch-size", "32", "--no-progress"]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("localhost", 0))
        return s.getsockname()[1]


def launch(processes: int, *args) -> None:
    """`python -m experiments.mujoco_medium *args` in `processes` local processes joined by jax.distributed."""
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    port, command = free_port(), [sys.executable, "-m", "experiments.mujoco_medium", *map(str, args)]
    procs = [subprocess.Popen(command + ([] if processes == 1 else ["--coordinator", f"localhost:{port}",
                                                                    "--num-processes", str(processes),
                                                                    "--process-id", str(i)]),
                              cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
             for i in range(processes)]
    outputs = [p.communicate(timeout=600)[0] for p in procs]
    assert all(p.returncode == 0 for p in procs), "\n".join(o[-3000:] for o in outputs)


def rows(run: Path) -> dict[tuple, dict]:
    return {(r["variant"], r["seed"], r["update"]): r for r in csv.DictReader((run / "curves.csv").open())}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    base = tmp_path_factory.mktemp("distributed")
    data = synthetic_dataset(2000)
    path = base / "tiny-hopper.npz"
    np.savez(path, **{k: getattr(data, k) for k in ("observations", "actions", "rewards", "terminals", "timeouts")})
    launch(1, "--dataset-path", path, "--updates", 300, "--out", base / "one", *TINY)
    launch(1, "--dataset-path", path, "--updates", 200, "--out", base / "two", *TINY, "--processes", 2)  # it starts
    # the other process itself; then two processes started by hand extend the run
    launch(2, "--resume", base / "two", "--updates", 300)
    return base / "one", base / "two"


@pytest.mark.slow  # one of the suite's longest (1-5 min on 2 busy cores); -m slow runs it
def test_two_processes_equal_one(runs):
    one, two = rows(runs[0]), rows(runs[1])
    assert one.keys() == two.keys() and len(one) == 3 * 3
    for key, a in one.items():
        b = two[key]
        for name in ("score", "critic_loss", "actor_loss", "q_mean"):
            if a.get(name):
                x, y = float(a[name]), float(b[name])
                assert abs(x - y) <= 1e-6 * max(1.0, abs(x)), (key, name, x, y)


@pytest.mark.slow  # shares test_two_processes_equal_one's two-process runs (the suite's longest set-up)
def test_process_zero_writes_one_set_of_files(runs):
    two = runs[1]
    summary = json.loads((two / "summary.json").read_text())
    assert [s["variant"] for s in summary] == ["pretrained"]
    assert sorted(p.name for p in (two / "checkpoints").iterdir()) == ["pretrained.best.msgpack", "pretrained.msgpack"]
    assert len(json.loads((two / "config.json").read_text())["runs"]) == 2  # the start and the resume


def test_a_local_run_that_fails_is_one_line_and_leaves_nothing(tmp_path):
    """Bad data with --processes 2: the other process is stopped, one line, exit 2, no lock file left behind."""
    result = subprocess.run([sys.executable, "-m", "experiments.mujoco_medium", "--processes", "2", "--out",
                             str(tmp_path / "run"), "--dataset-path", str(tmp_path / "missing.npz"), *TINY],
                            cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 2 and result.stderr.strip().splitlines() == [
        f"error: {tmp_path / 'missing.npz'}: no such file"], result.stderr[-2000:]
    assert list(tmp_path.iterdir()) == []


def test_more_processes_than_cores_is_refused(tmp_path):
    result = subprocess.run([sys.executable, "-m", "experiments.mujoco_medium", "--processes", "1000", "--out",
                             str(tmp_path / "run"), *TINY], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 2 and "--processes 1000: this command may use" in result.stderr
    assert list(tmp_path.iterdir()) == []
