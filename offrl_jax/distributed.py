"""Many processes (or hosts), one run: the member axis (seeds x sweep values) spans every process's devices.

After `initialize`, `jax.devices()` lists the devices of every process, so the driver's seed sharding
(`offrl_jax.driver.seed_sharding`) splits the members over all of them and every process runs the same jitted
chunk on its own share.  Between chunks:

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


def my_block(members: int) -> slice:
    """The contiguous block of members this process evaluates (members divide evenly over the processes)."""
    size = members // jax.process_count()
    return slice(jax.process_index() * size, (jax.process_index() + 1) * size)


def gather(local: np.ndarray) -> np.ndarray:
    """Every process's block (same shape on each), concatenated in process order."""
    if jax.process_count() == 1:
        return np.asarray(local)
    from jax.experimental import multihost_utils

    return np.array(multihost_utils.process_allgather(np.asarray(local), tiled=True))  # a writable copy


def evaluate_shared(states: Any, evaluate: Callable[[Any], np.ndarray]) -> tuple[Any, np.ndarray]:
    """(states whole on this host, every member's score): with one process `evaluate(states)`; with several, each
    process evaluates its block of members and the scores are gathered."""
    if jax.process_count() == 1:
        return states, np.asarray(evaluate(states))
    states = to_host(states)
    block = my_block(len(jax.tree.leaves(states)[0]))
    return states, gather(evaluate(jax.tree.map(lambda x: x[block], states)))


def check_members(members: int) -> None:
    """With several processes, the members must divide over every device (each process holds the same number)."""
    if jax.process_count() > 1 and members % jax.device_count():
        raise ValueError(f"{members} members (seeds x sweep values) do not divide over the {jax.device_count()} "
                         f"devices of {jax.process_count()} processes; use a multiple of {jax.device_count()}")
