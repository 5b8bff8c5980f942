"""What every benchmark shares: the synthetic hopper-shaped data, the machine's peak-rate probes, its one-line
description, and the results file that `--out` appends to.

    OBS_DIM, ACT_DIM, BATCH     hopper's shapes and the batch every benchmark uses
    synthetic_dataset(n)        a random hopper-shaped `Dataset` of n transitions (episodes of 1000 steps);
                                `synthetic_data(n)` the same as the driver's device arrays
    chain_rate(), matmul_rate() GFLOP/s of a jitted chain of 256-wide dense layers at batch 256, of a 1024^2 matmul
    results_path(parser, out)   where `--out NAME` writes (results/benchmarks/NAME.jsonl), checked before any work
    append_results(path, rows)  one JSON object per line, appended; nothing already there is rewritten
    machine(), log(...)         the CPU/JAX line each results file records; progress to stderr
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from benchmarks.flops import chain_flops
from offrl_jax.data.dataset import Dataset
from offrl_jax.data.device import device_data
from offrl_jax.system.cli import check_writable_file

OBS_DIM, ACT_DIM, BATCH = 11, 3, 256  # hopper
RESULTS_DIR = Path("results/benchmarks")


def log(*args) -> None:
    print(*args, file=sys.stderr, flush=True)


# ------------------------------------------------------------------------------------------------ peak rate probes


def _median_rate(fn, args, flops: float, reps: int) -> float:
    jax.block_until_ready(fn(*args))
    times = []
    for _ in range(reps):
        tic = time.perf_counter()
        jax.block_until_ready(fn(*args))
        times.append(time.perf_counter() - tic)
    return flops / float(np.median(times)) / 1e9


_CHAIN_LAYERS, _CHAIN_REPEATS = 8, 16


@jax.jit
def _chain(x, ws, bs):
    def layer(x, wb):
        return jax.nn.relu(x @ wb[0] + wb[1]), None

    def block(x, _):
        return jax.lax.scan(layer, x, (ws, bs))[0], None

    return jax.lax.scan(block, x, None, length=_CHAIN_REPEATS)[0]


def chain_rate(reps: int = 7, width: int = 256, batch: int = BATCH) -> float:
    """GFLOP/s of a jitted chain of `width`-wide dense+ReLU layers at batch `batch` (matmul FLOPs only)."""
    k1, k2 = jax.random.split(jax.random.PRNGKey(0))
    ws = jax.random.normal(k1, (_CHAIN_LAYERS, width, width)) / np.sqrt(width)
    bs = jnp.zeros((_CHAIN_LAYERS, width))
    x = jax.random.normal(k2, (batch, width))
    return _median_rate(_chain, (x, ws, bs), chain_flops(width, batch, _CHAIN_LAYERS * _CHAIN_REPEATS), reps)


@jax.jit
def _matmul(a, b):
    return a @ b


def matmul_rate(n: int = 1024, reps: int = 7) -> float:
    """GFLOP/s of one jitted n x n x n float32 matmul."""
    k1, k2 = jax.random.split(jax.random.PRNGKey(1))
    a, b = jax.random.normal(k1, (n, n)), jax.random.normal(k2, (n, n))
    return _median_rate(_matmul, (a, b), 2.0 * n**3, reps)


# ------------------------------------------------------------------------------------------------------- dataset


def synthetic_dataset(transitions: int, seed: int = 0) -> Dataset:
    """A random hopper-shaped dataset: episodes of 1000 steps, a few terminals."""
    rng = np.random.default_rng(seed)
    obs = rng.normal(size=(transitions + 1, OBS_DIM)).astype(np.float32)
    timeouts = np.zeros(transitions, np.float32)
    timeouts[999::1000] = 1
    terminals = np.zeros(transitions, np.float32)
    terminals[500::3000] = 1
    ds = Dataset(obs[:-1], rng.uniform(-1, 1, (transitions, ACT_DIM)).astype(np.float32),
                 (1.0 + 0.1 * obs[:-1, 0]).astype(np.float32), obs[1:], terminals, timeouts, env="hopper",
                 name="hopper-synthetic", source="synthetic")
    return ds


def synthetic_data(transitions: int, seed: int = 0) -> dict[str, jax.Array]:
    """`synthetic_dataset` as the driver's device arrays."""
    return device_data(synthetic_dataset(transitions, seed), 0.99).arrays


# ------------------------------------------------------------------------------------------------- results files


def results_path(parser: argparse.ArgumentParser, out: str | None) -> Path | None:
    """Where `--out` writes, checked before any work (one line and exit 2 otherwise); None without --out.

    `--out` appends one JSON object per line to a results file: results/benchmarks/NAME.jsonl for a bare NAME
    (results/benchmarks/NAME if NAME has a suffix), the path as given if it has a folder.  An existing file is only
    appended to if every line of it is a JSON object; nothing in it is ever truncated or rewritten."""
    if out is None:
        return None
    if not out.strip():
        parser.error("--out needs a name or a path")
    path = Path(out)
    if path.parent == Path("."):
        path = RESULTS_DIR / (path.name if path.suffix else f"{path.name}.jsonl")
    try:
        check_writable_file(path)
    except OSError as e:
        parser.error(str(e))
    if path.exists():
        if not path.is_file():
            parser.error(f"{path} is not a regular file; --out appends JSON lines to a results file")
        if not os.access(path, os.W_OK):
            parser.error(f"{path}: not writable")
        try:
            text = path.read_bytes().decode()
            if not all(isinstance(json.loads(line), dict) for line in text.splitlines() if line.strip()):
                raise ValueError
        except OSError as e:
            parser.error(f"{path}: cannot be read ({e.strerror or e})")
        except ValueError:
            parser.error(f"{path} is not a results file (one JSON object per line); --out only appends to one: "
                         "choose another --out")
    return path


def append_results(path: Path, records: list[dict[str, Any]]) -> None:
    """Append `records` to a results file that `results_path` accepted, one JSON object per line."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("a") as f:
        if f.tell() and not path.read_bytes().endswith(b"\n"):  # a last line without its newline
            f.write("\n")
        f.writelines(json.dumps(r) + "\n" for r in records)


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} logical CPUs, jax {jax.__version__} ({jax.default_backend()})"
