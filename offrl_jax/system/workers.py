"""Variants trained at once in worker processes, each pinned to its own CPU core(s).

`--parallel 2` trains two variants at once, each on its own core(s) with one single-threaded XLA device per core
(`cpu_flags`).  On the idle 2-core machine, two processes each pinned to one core ran 10-20 % more updates per
second than two threads of one process (benchmarks/README.md, "Two variants at once").  Results do
not depend on where a variant runs: each variant's randomness is its own.

A worker gets its task by pickling (the dataset included), runs `target(*task, bar, recorder)` and sends back, on
its own pipe, what the threads used to share: rows for curves.csv, progress, messages, and its result or its
error.  The parent owns curves.csv, the progress bar and the run directory's lock.  Workers ignore SIGINT: on
Ctrl-C (or when a variant fails) the parent tells them to stop, and they stop at the end of their current slice (a
tenth of a chunk at most); one still busy after 30 s is terminated (its last checkpoint stays).  A worker whose
parent is gone stops too.
"""
from __future__ import annotations

import contextlib
import multiprocessing
import os
import pickle
import signal
import sys
import threading
import time
import traceback
from collections.abc import Callable
from multiprocessing.connection import wait
from typing import Any

SINGLE_THREAD_XLA = "--xla_cpu_multi_thread_eigen=false"
STOP_GRACE_S = 30.0


USER_XLA_FLAGS = "OFFRL_JAX_USER_XLA_FLAGS"  # the user's own XLA_FLAGS, kept aside the first time they are extended


def cpu_flags(cores: int, env: dict | None = None) -> str:
    """XLA_FLAGS for a process given `cores` CPU cores: one single-threaded XLA device per core, so that a run's
    members split over the cores (`offrl_jax.driver.member_layout`).  The user's own flags come last and win; they
    are kept in `env` under OFFRL_JAX_USER_XLA_FLAGS, so a process started from this one extends the same flags."""
    env = os.environ if env is None else env
    user = env.setdefault(USER_XLA_FLAGS, env.get("XLA_FLAGS", ""))
    return f"{SINGLE_THREAD_XLA} --xla_force_host_platform_device_count={max(1, cores)} {user}".strip()


def process_cores() -> int:
    """The number of cores this process may use."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def core_sets(parallel: int) -> list[list[int]]:
    """The cores this process may use, dealt round-robin into `parallel` sets (fewer when there are fewer cores)."""
    cores = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else list(range(os.cpu_count() or 1))
    n = max(1, min(parallel, len(cores)))
    return [cores[i::n] for i in range(n)]


class _Bar:
    """The worker's stand-in for the parent's progress bar."""

    def __init__(self, conn):
        self.conn = conn

    def update(self, n: int) -> None:
        self.conn.send(("update", n))

    def set_postfix_str(self, text: str) -> None:
        self.conn.send(("postfix", text))

    def status(self, text: str) -> None:
        self.conn.send(("status", text))

    def write(self, text: str, file=None) -> None:
        self.conn.send(("write", text))


class _Stop:
    """`is_set()`: the parent asked the worker to stop (a word on the worker's stop pipe), or the parent is gone
    (the pipe's end).  A pipe, not a multiprocessing Event: an Event is a named semaphore, which a SIGKILLed parent
    leaves to Python's resource tracker, and the tracker's "leaked semaphore" warning to the terminal."""

    def __init__(self, conn, parent: int):
        self.conn, self.parent = conn, parent

    def is_set(self) -> bool:
        return self.conn.poll() or os.getppid() != self.parent


class _Recorder:
    """The worker's stand-in for the parent's recorder: rows go to the parent, which writes curves.csv."""

    def __init__(self, conn, stop: _Stop):
        self.conn, self.stop = conn, stop

    def set(self, rows_by_label: dict[str, list[dict]]) -> None:
        self.conn.send(("rows", rows_by_label))


def _die_with_parent() -> None:
    """Linux: the kernel kills this worker when its parent dies, so no orphan writes a run after the lock is gone."""
    try:
        import ctypes

        ctypes.CDLL(None).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def portable_error(e: BaseException) -> BaseException:
    """`e` if it survives pickling, else an error of its broad kind (ValueError, OSError, RuntimeError) with its
    text, so that the parent reports it the same way (the CLI maps kinds to exit codes)."""
    try:
        pickle.loads(pickle.dumps(e))
        return e
    except Exception:  # noqa: BLE001 -- whatever pickling raises, the text still goes
        kind = next(k for k in (KeyboardInterrupt, ValueError, OSError, RuntimeError, BaseException)
                    if isinstance(e, k))
        return kind(f"{type(e).__name__}: {e}")


def _worker(index: int, target: Callable, tasks, cores: list[int], conn, stop, parent: int) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent decides when to stop (see the module doc)
    _die_with_parent()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, cores)
    os.environ["XLA_FLAGS"] = cpu_flags(len(cores))  # before JAX starts its backend
    try:
        task = tasks.recv()  # the task (the dataset with it) comes on its own pipe, after the start
        tasks.close()
        result = target(*task, _Bar(conn), _Recorder(conn, _Stop(stop, parent)))
        conn.send(("done", result))
    except BaseException as e:  # noqa: BLE001 -- every error goes to the parent, which decides
        if os.environ.get("OFFRL_JAX_DEBUG") == "1":
            traceback.print_exc()
        conn.send(("error", portable_error(e)))
    finally:
        conn.close()


@contextlib.contextmanager
def _sigint_ignored():
    if threading.current_thread() is not threading.main_thread():  # signal handlers belong to the main thread
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _exit_text(code: int | None) -> str:
    if code is not None and code < 0:
        name = signal.Signals(-code).name if -code in signal.valid_signals() else str(-code)
        return f"killed by {name}" + (" (out of memory?)" if -code == signal.SIGKILL else "")
    return f"exit code {code}"


def run_in_processes(target: Callable, tasks: list[tuple], parallel: int, bar, recorder,
                     on_done: Callable[[int, Any], None]) -> None:
    """Run `target(*task, bar, recorder)` for every task, `parallel` at a time, each in a process pinned to its own
    cores; `on_done(index, result)` in the parent as each ends.  The first error tells the others to stop at their
    current slice and is raised here once they have (Ctrl-C likewise); a worker that dies without a word
    raises ChildProcessError."""
    ctx = multiprocessing.get_context("spawn")  # a fresh interpreter: JAX must not be forked
    stops: dict[int, Any] = {}  # index -> the writing end of that worker's stop pipe
    free, pending = core_sets(parallel), list(enumerate(tasks))
    running: dict[int, tuple[Any, Any, list[int]]] = {}  # index -> (process, its pipe's reading end, cores)
    error: BaseException | None = None
    deadline: float | None = None  # after a stop request: when the workers still running are terminated

    def fail(e: BaseException) -> None:
        nonlocal error, deadline
        if error is None:
            error, deadline = e, time.monotonic() + STOP_GRACE_S
            for conn in stops.values():
                with contextlib.suppress(OSError):  # a worker that has ended has closed its end
                    conn.send("stop")

    def finish(index: int, outcome: tuple | None) -> None:
        """The worker `index` ended: with ("done", result), ("error", e), or without a word (None)."""
        process, conn, cores = running.pop(index)
        conn.close()
        stops.pop(index).close()
        process.join(timeout=10)
        free.append(cores)
        if outcome is None:
            fail(ChildProcessError(f"a worker process ended without a result ({_exit_text(process.exitcode)})"))
        elif outcome[0] == "done":
            on_done(index, outcome[1])
        else:
            fail(outcome[1])

    def serve(index: int) -> None:
        """Handle every message waiting on worker `index`'s pipe; notice its end."""
        _, conn, _ = running[index]
        try:
            while conn.poll():
                message = conn.recv()
                kind = message[0]
                if kind == "update":
                    bar.update(message[1])
                elif kind == "postfix":
                    bar.set_postfix_str(message[1])
                elif kind == "status":
                    bar.status(message[1])
                elif kind == "write":
                    bar.write(message[1], file=sys.stderr)
                elif kind == "rows":
                    recorder.set(message[1])
                else:
                    return finish(index, message)
        except (EOFError, OSError, pickle.UnpicklingError):  # the pipe closed (or broke) before a result came
            return finish(index, None)

    try:
        while running or (pending and error is None):
            while pending and free and error is None:
                index, task = pending.pop(0)
                cores = free.pop(0)
                receive, send = ctx.Pipe(duplex=False)
                task_receive, task_send = ctx.Pipe(duplex=False)
                stop_receive, stops[index] = ctx.Pipe(duplex=False)
                process = ctx.Process(target=_worker, args=(index, target, task_receive, cores, send, stop_receive,
                                                            os.getpid()), daemon=True)
                with _sigint_ignored():  # inherited: the worker ignores Ctrl-C from its first instruction
                    process.start()  # quick: only small arguments (a big one would hold Ctrl-C off until the
                    # worker has imported its modules and read it)
                send.close()  # the worker holds the only writing end: its death closes the pipe
                task_receive.close()
                stop_receive.close()  # and the only reading end of its stop pipe
                running[index] = (process, receive, cores)
                try:
                    task_send.send(task)  # Ctrl-C here is seen at once; the worker then reads a closed pipe
                except BrokenPipeError:  # it died starting up (its imports failed): its stderr says why
                    process.join(timeout=10)
                    fail(ChildProcessError(f"a worker process ended before it read its task "
                                           f"({_exit_text(process.exitcode)}; its error is printed above)"))
                finally:
                    task_send.close()
            ready = wait([conn for _, conn, _ in running.values()], timeout=1.0)
            for index in [i for i, (_, conn, _) in list(running.items()) if conn in ready]:
                serve(index)
            if deadline is not None and time.monotonic() > deadline:
                for process, _, _ in running.values():
                    process.terminate()
    except KeyboardInterrupt:  # Ctrl-C in the parent: the workers stop at the end of their current slice
        fail(KeyboardInterrupt())
        bar.write("stopping the worker processes at the end of their current slice (Ctrl-C again: now)",
                  file=sys.stderr)
        while running:
            try:
                ready = wait([conn for _, conn, _ in running.values()], timeout=1.0)
                for index in [i for i, (_, conn, _) in list(running.items()) if conn in ready]:
                    serve(index)
                if time.monotonic() > deadline:
                    for process, _, _ in running.values():
                        process.terminate()
            except KeyboardInterrupt:  # a second Ctrl-C: stop now
                for process, _, _ in running.values():
                    process.terminate()
    if error is not None:
        raise error
