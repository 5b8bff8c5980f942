"""Variants trained at once in worker processes, each pinned to its own CPU core(s).

At these network sizes one XLA program keeps about one core busy, so `--parallel 2` trains two variants at once.
On the idle 2-core machine, two processes each pinned to one core with single-threaded XLA run 20 % more updates
per second than two threads of one process (321 vs 267 TD3+BC updates/s for two 3-seed variants; measured in
benchmarks/README.md, "Two variants at once").  Results do not depend on where a variant runs: each variant's
randomness is its own.

A worker gets its task by pickling (the dataset included), runs `target(*task, bar, recorder)` and sends back, on
one queue, what the threads used to share: rows for curves.csv, progress, messages, and its result or its error.
The parent owns curves.csv, the progress bar and the run directory's lock; a worker stops at its next chunk
boundary when told to (another variant failed, Ctrl-C) or when the parent is gone.
"""
from __future__ import annotations

import multiprocessing
import os
import queue as queues
import sys
import time
import traceback
from collections.abc import Callable
from typing import Any

SINGLE_THREAD_XLA = "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"


def core_sets(parallel: int) -> list[list[int]]:
    """The cores this process may use, dealt round-robin into `parallel` sets (fewer when there are fewer cores)."""
    cores = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else list(range(os.cpu_count() or 1))
    n = max(1, min(parallel, len(cores)))
    return [cores[i::n] for i in range(n)]


class _Bar:
    """The worker's stand-in for the parent's tqdm bar."""

    def __init__(self, queue):
        self.queue = queue

    def update(self, n: int) -> None:
        self.queue.put(("update", n))

    def set_postfix_str(self, text: str) -> None:
        self.queue.put(("postfix", text))

    def write(self, text: str, file=None) -> None:
        self.queue.put(("write", text))


class _Stop:
    """`is_set()`: the parent asked the workers to stop, or the parent is gone."""

    def __init__(self, event, parent: int):
        self.event, self.parent = event, parent

    def is_set(self) -> bool:
        return self.event.is_set() or os.getppid() != self.parent


class _Recorder:
    """The worker's stand-in for the parent's recorder: rows go to the parent, which writes curves.csv."""

    def __init__(self, queue, stop: _Stop):
        self.queue, self.stop = queue, stop

    def set(self, rows_by_label: dict[str, list[dict]]) -> None:
        self.queue.put(("rows", rows_by_label))


def _die_with_parent() -> None:
    """Linux: the kernel kills this worker when its parent dies, so no orphan writes a run after the lock is gone."""
    try:
        import ctypes
        import signal

        ctypes.CDLL(None).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def _worker(index: int, target: Callable, task: tuple, cores: list[int], queue, stop, parent: int) -> None:
    _die_with_parent()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, cores)
    if len(cores) == 1:  # before JAX starts its backend; a user's own XLA_FLAGS come last and win
        os.environ["XLA_FLAGS"] = f"{SINGLE_THREAD_XLA} {os.environ.get('XLA_FLAGS', '')}".strip()
    try:
        result = target(*task, _Bar(queue), _Recorder(queue, _Stop(stop, parent)))
        queue.put(("done", index, result))
    except BaseException as e:  # noqa: BLE001 -- every error goes to the parent, which decides
        if os.environ.get("OFFRL_JAX_DEBUG") == "1":
            traceback.print_exc()
        try:
            queue.put(("error", index, e))
        except Exception:  # an error that does not pickle still reaches the parent, as its text
            queue.put(("error", index, RuntimeError(f"{type(e).__name__}: {e}")))


def run_in_processes(target: Callable, tasks: list[tuple], parallel: int, bar, recorder,
                     on_done: Callable[[int, Any], None]) -> None:
    """Run `target(*task, bar, recorder)` for every task, `parallel` at a time, each in a process pinned to its own
    cores; `on_done(index, result)` in the parent as each ends.  The first error stops the others at their next
    chunk boundary and is raised here once they have stopped (Ctrl-C likewise)."""
    ctx = multiprocessing.get_context("spawn")  # a fresh interpreter: JAX must not be forked
    queue, stop = ctx.Queue(), ctx.Event()
    free, pending, running = core_sets(parallel), list(enumerate(tasks)), {}
    error: BaseException | None = None

    def handle(message: tuple) -> None:
        nonlocal error
        kind = message[0]
        if kind == "update":
            bar.update(message[1])
        elif kind == "postfix":
            bar.set_postfix_str(message[1])
        elif kind == "write":
            bar.write(message[1], file=sys.stderr)
        elif kind == "rows":
            recorder.set(message[1])
        else:
            index, value = message[1], message[2]
            process, cores = running.pop(index)
            process.join()
            free.append(cores)
            if kind == "done":
                on_done(index, value)
            elif error is None:
                error = value
                stop.set()

    try:
        while running or (pending and error is None):
            while pending and free and error is None:
                index, task = pending.pop(0)
                cores = free.pop(0)
                process = ctx.Process(target=_worker, args=(index, target, task, cores, queue, stop, os.getpid()),
                                      daemon=True)
                process.start()
                running[index] = (process, cores)
            try:
                handle(queue.get(timeout=1.0))
            except queues.Empty:
                for index, (process, _) in list(running.items()):
                    if process.exitcode is not None:  # killed without a word (out of memory, a signal)
                        handle(("error", index, RuntimeError(
                            f"a worker process ended without a result (exit code {process.exitcode})")))
    except BaseException:  # Ctrl-C in the parent: the workers stop too (they also got the signal on a terminal)
        stop.set()
        deadline = time.monotonic() + 30
        while any(p.is_alive() for p, _ in running.values()) and time.monotonic() < deadline:
            try:  # keep reading, so that no worker blocks on a full pipe; their rows still reach curves.csv
                message = queue.get(timeout=0.2)
                if message[0] == "rows":
                    recorder.set(message[1])
            except queues.Empty:
                pass
        for process, _ in running.values():
            if process.is_alive():
                process.terminate()
        raise
    if error is not None:
        raise error
