"""Variants in worker processes (`system.workers`): results, progress and errors reach the parent; a failure or a
dead worker stops the run with one error; a one-core worker runs single-threaded XLA on its own core."""
from __future__ import annotations

import os
import time

import pytest

from offrl_jax.system.workers import SINGLE_THREAD_XLA, core_sets, run_in_processes


class Bar:
    def __init__(self):
        self.n, self.postfix, self.lines = 0, [], []

    def update(self, n):
        self.n += n

    def set_postfix_str(self, text):
        self.postfix.append(text)

    def write(self, text, file=None):
        self.lines.append(text)


class Recorder:
    def __init__(self):
        self.rows = {}

    def set(self, rows_by_label):
        self.rows.update(rows_by_label)


def report(label, bar, recorder):
    """A well-behaved task: progress, a message, rows, then where it ran."""
    bar.update(5)
    bar.set_postfix_str(f"{label} half way")
    bar.write(f"{label} says hello")
    recorder.set({label: [{"variant": label, "update": 5}]})
    return {"label": label, "cores": sorted(os.sched_getaffinity(0)), "xla_flags": os.environ.get("XLA_FLAGS", "")}


def fail_or_wait(label, bar, recorder):
    if label == "fails":
        raise ValueError("this variant is broken")
    deadline = time.monotonic() + 60
    while not recorder.stop.is_set() and time.monotonic() < deadline:
        time.sleep(0.05)
    raise RuntimeError("stopped" if recorder.stop.is_set() else "never told to stop")


def vanish(label, bar, recorder):
    os._exit(7)


class Unpicklable(ValueError):
    def __reduce__(self):
        raise TypeError("not picklable")


class Custom(RuntimeError):
    """Like runner.Diverged: a module-level subclass whose type the CLI reads."""


def raise_kind(label, bar, recorder):
    raise Unpicklable("a lock inside") if label == "unpicklable" else Custom("every seed diverged")


def killed_or_chatty(label, bar, recorder):
    import signal

    if label == "killed":
        time.sleep(0.5)
        os.kill(os.getpid(), signal.SIGKILL)
    deadline = time.monotonic() + 60
    while not recorder.stop.is_set() and time.monotonic() < deadline:
        bar.update(1)  # a busy neighbour: messages keep coming
        time.sleep(0.01)
    return "stopped"


def test_core_sets_deal_every_core_once():
    cores = sorted(os.sched_getaffinity(0))
    for parallel in (1, 2, 3, 8):
        sets = core_sets(parallel)
        assert len(sets) == min(parallel, len(cores))
        assert sorted(c for s in sets for c in s) == cores


def test_results_progress_and_rows_reach_the_parent():
    bar, recorder, done = Bar(), Recorder(), {}
    run_in_processes(report, [("a",), ("b",)], 2, bar, recorder, done.__setitem__)
    assert sorted(done) == [0, 1] and [done[i]["label"] for i in (0, 1)] == ["a", "b"]
    assert bar.n == 10 and sorted(bar.lines) == ["a says hello", "b says hello"]
    assert recorder.rows == {"a": [{"variant": "a", "update": 5}], "b": [{"variant": "b", "update": 5}]}
    sets = core_sets(2)
    for result in done.values():
        assert result["cores"] in sets
        if len(result["cores"]) == 1:
            assert result["xla_flags"].startswith(SINGLE_THREAD_XLA)
    if len(sets) == 2:
        assert done[0]["cores"] != done[1]["cores"]


def test_a_failing_worker_stops_the_others_and_its_error_is_raised():
    tic = time.monotonic()
    with pytest.raises(ValueError, match="this variant is broken"):
        run_in_processes(fail_or_wait, [("waits",), ("fails",)], 2, Bar(), Recorder(), lambda i, r: None)
    assert time.monotonic() - tic < 45  # the waiting worker was told to stop, not left to its 60 s


def test_a_worker_that_dies_without_a_word_is_an_error():
    with pytest.raises(ChildProcessError, match="ended without a result \\(exit code 7\\)"):
        run_in_processes(vanish, [("x",)], 1, Bar(), Recorder(), lambda i, r: None)


def test_a_killed_worker_is_noticed_while_another_keeps_talking():
    tic = time.monotonic()
    with pytest.raises(ChildProcessError, match="killed by SIGKILL"):
        run_in_processes(killed_or_chatty, [("chatty",), ("killed",)], 2, Bar(), Recorder(), lambda i, r: None)
    assert time.monotonic() - tic < 45


def test_errors_keep_their_kind_even_when_they_do_not_pickle():
    with pytest.raises(Custom, match="every seed diverged"):
        run_in_processes(raise_kind, [("custom",)], 1, Bar(), Recorder(), lambda i, r: None)
    with pytest.raises(ValueError, match="Unpicklable: a lock inside"):
        run_in_processes(raise_kind, [("unpicklable",)], 1, Bar(), Recorder(), lambda i, r: None)


def test_more_tasks_than_workers_all_run():
    done = {}
    run_in_processes(report, [(str(i),) for i in range(3)], 2, Bar(), Recorder(), done.__setitem__)
    assert sorted(r["label"] for r in done.values()) == ["0", "1", "2"]


def test_a_killed_parent_leaves_no_leaked_semaphore_warning():
    """The workers' stop is a pipe, not a multiprocessing Event (a named semaphore, which a SIGKILLed parent leaves
    to Python's resource tracker and its "leaked semaphore" warning)."""
    import subprocess
    import sys
    from pathlib import Path

    code = ("import os, signal, threading\n"
            "from offrl_jax.system.workers import run_in_processes\n"
            "from tests.test_workers import Bar, Recorder, fail_or_wait\n"
            "threading.Timer(3.0, lambda: os.kill(os.getpid(), signal.SIGKILL)).start()\n"
            "run_in_processes(fail_or_wait, [('waits',), ('waits too',)], 2, Bar(), Recorder(), lambda i, r: None)\n")
    result = subprocess.run([sys.executable, "-c", code], cwd=Path(__file__).resolve().parents[1],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == -9, result.stderr
    assert "leaked" not in result.stderr and "resource_tracker" not in result.stderr, result.stderr
