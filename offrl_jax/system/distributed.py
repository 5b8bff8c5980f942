"""Many processes (or hosts), one run: the member axis (seeds x sweep values) spans every process's devices.

After `initialize`, `jax.devices()` lists the devices of every process, so the driver's layout
(`offrl_jax.driver.member_layout`) splits the members over all of them (padded with copies of the last member when
they do not divide) and every process runs the same jitted chunk on its own share.  Between chunks:

* metrics and states come to every host whole (`to_host`, an all-gather; a few MB at the sizes used here);
* each process evaluates only its block of members (`my_block`), and the scores are gathered (`gather`);
* process 0 alone writes config.json, curves.csv, summary.json, plots and checkpoints (`is_writer`), with the
  whole state; on `--resume` every process reads the same checkpoint (the run directory must be on a file
  system that every process sees, as on a cluster's shared disk).

On the CPU the collectives are gloo's.  With one process, all of this is a no-op.

    python -m experiments.mujoco_medium --out runs/x --coordinator host0:12355 --num-processes 2 --process-id 0
    python -m experiments.mujoco_medium --out runs/x --coordinator host0:12355 --num-processes 2 --process-id 1

Under SLURM or on a TPU slice, `--distributed` alone lets JAX read the cluster's environment (`srun` one task
per host; on a TPU slice, the same command on every worker).
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import numpy as np


def initialize(coordinator: str | None = None, num_processes: int | None = None,
               process_id: int | None = None) -> None:
    """`jax.distributed.initialize` with the CPU's collectives set; without arguments JAX detects the cluster
    (SLURM, TPU slices, Open MPI).  Call it before anything else touches JAX's devices."""
    if jax.config.jax_platforms in (None, "", "cpu") or str(jax.config.jax_platforms).startswith("cpu"):
        jax.config.update("jax_cpu_collectives_implementation", "gloo")
    kwargs = {} if coordinator is None else {"coordinator_address": coordinator, "num_processes": num_processes,
                                             "process_id": process_id}
    jax.distributed.initialize(**kwargs)


class LocalProcesses:
    """One run over `n` processes of this machine: this one is process 0 and starts processes 1..n-1 as copies of
    the command (`argv`, with the coordinator flags added), each pinned to its share of the cores with
    one single-threaded XLA device per core, as `offrl_jax.system.workers` does for variants.  Call `start`
    before JAX's backend starts; `close` waits for the others (or stops them after a failure)."""

    def __init__(self, n: int, module: str, argv: list[str]):
        self.n, self.module, self.argv, self.procs, self.logs = n, module, list(argv), [], []
        self.closing = False  # set by `close`: the processes it stops are not failures to report

    def start(self) -> None:
        import os
        import socket
        import subprocess
        import sys
        import tempfile
        import threading

        from offrl_jax.system.workers import core_sets, cpu_flags

        with socket.socket() as s:
            s.bind(("localhost", 0))
            port = s.getsockname()[1]
        cores = core_sets(self.n)
        share = [cores[i % len(cores)] for i in range(self.n)]
        for i in range(1, self.n):
            env = dict(os.environ)
            env["XLA_FLAGS"] = cpu_flags(len(share[i]), env)
            log = tempfile.TemporaryFile("w+")
            self.logs.append(log)
            self.procs.append(subprocess.Popen(
                [sys.executable, "-m", self.module, *self.argv, "--coordinator", f"localhost:{port}",
                 "--num-processes", str(self.n), "--process-id", str(i)], env=env, stdout=subprocess.DEVNULL,
                stderr=log, preexec_fn=(lambda c=share[i]: os.sched_setaffinity(0, c))
                if hasattr(os, "sched_setaffinity") else None))
        if hasattr(os, "sched_setaffinity"):
            os.sched_setaffinity(0, share[0])
        os.environ["XLA_FLAGS"] = cpu_flags(len(share[0]))
        threading.Thread(target=self._watch, daemon=True).start()
        initialize(f"localhost:{port}", self.n, 0)

    def _failure(self) -> str | None:
        for i, (proc, log) in enumerate(zip(self.procs, self.logs), 1):
            if proc.poll() not in (None, 0):
                log.seek(0)
                lines = [line for line in log.read().splitlines() if line.strip()]
                return f"process {i} of this run failed (exit {proc.returncode}{': ' + lines[-1] if lines else ''})"
        return None

    def _watch(self) -> None:
        """A process that dies leaves the others waiting in a collective: end the run with its reason."""
        import os
        import sys
        import time

        while any(p.poll() is None for p in self.procs):
            time.sleep(1.0)
            if self.closing:
                return
            if (why := self._failure()) is not None and not self.closing:
                print(f"error: {why}", file=sys.stderr, flush=True)
                for p in self.procs:
                    p.terminate()
                os._exit(2)

    def close(self, ok: bool) -> str | None:
        """Wait for the other processes (stop them if this one failed); the reason one of them failed, if any."""
        self.closing = not ok
        if ok:  # leave together: each process's exit waits at a shutdown barrier that this one must reach too
            try:
                jax.distributed.shutdown()
            except Exception:  # noqa: BLE001 -- the others are waited for (or stopped) below either way
                pass
        for p in self.procs:
            if not ok:
                p.terminate()
            try:
                p.wait(timeout=60 if ok else 5)  # a process waiting in JAX's start-up may not heed SIGTERM
            except Exception:  # noqa: BLE001 -- a process that does not end is stopped
                p.kill()
                p.wait()
        return self._failure() if ok else None


def processes() -> int:
    return jax.process_count()


def is_writer() -> bool:
    """Whether this process writes the run's files (process 0, or the only one)."""
    return jax.process_index() == 0


def to_host(tree: Any) -> Any:
    """Every leaf as a whole numpy array on this host (an all-gather for arrays spread over processes)."""
    if jax.process_count() == 1:
        return jax.tree.map(np.asarray, tree)
    from jax.experimental import multihost_utils

    def one(x):
        if isinstance(x, jax.Array) and not x.is_fully_addressable:
            return np.array(multihost_utils.process_allgather(x, tiled=True))  # a writable copy
        return np.asarray(x)
    return jax.tree.map(one, tree)


def _block_size(members: int) -> int:
    return -(-members // jax.process_count())  # ceil(members / processes)


def my_block(members: int) -> slice:
    """The contiguous block of members this process evaluates: blocks of ceil(members / processes), the last ones
    shorter (or empty)."""
    size = _block_size(members)
    start = min(members, jax.process_index() * size)
    return slice(start, min(members, start + size))


def gather(local: np.ndarray, members: int) -> np.ndarray:
    """Every process's block of a (members, ...) array (`my_block`), concatenated in process order."""
    if jax.process_count() == 1:
        return np.asarray(local)
    from jax.experimental import multihost_utils

    local = np.asarray(local, np.float64)
    block = np.full((_block_size(members), *local.shape[1:]), np.nan)  # every process sends a whole block, NaN-padded
    block[:len(local)] = local
    return np.array(multihost_utils.process_allgather(block, tiled=True))[:members]  # a writable copy


def evaluate_shared(states: Any, evaluate: Callable[[Any], np.ndarray]) -> tuple[Any, np.ndarray]:
    """(states whole on this host, every member's score): with one process `evaluate(states)`; with several, each
    process evaluates its block of members and the scores are gathered."""
    if jax.process_count() == 1:
        return states, np.asarray(evaluate(states))
    states = to_host(states)
    members = len(jax.tree.leaves(states)[0])
    block = my_block(members)
    mine = evaluate(jax.tree.map(lambda x: x[block], states)) if block.stop > block.start else np.zeros(0)
    return states, gather(mine, members)
