"""Ctrl-C in a command, at any moment from its package's first import on: one line and exit 130, never a traceback
and never lost (before that, in Python's own start-up, a Ctrl-C is Python's).

`quiet_start` (called by the `__init__` of each package that holds commands, so this module imports nothing heavy)
covers the imports before a command's `main`: a Ctrl-C there ends the process at once, and an exception there (a JAX
environment variable JAX cannot read) is one line. `during_command` is the handler from `cli.run_main` on:
Ctrl-C raises KeyboardInterrupt, which the command handles (a training run stops at the end of its current slice),
except where Python would lose it or a C extension could crash on it: inside an import (JAX imported lazily: a half-
initialised extension aborts the process or leaves an ImportError) or inside a callback whose exception Python
prints and drops (JAX's garbage-collection callback, a weak reference's callback, a `__del__`). There it is put off
and tried again every 50 ms; one still put off when the command's `main` returns makes the command end as
interrupted."""
from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading

from offrl_jax.system.cache import keep_compiled_programs

RETRY_S = 0.05


def _interrupted_while_starting(signum, frame) -> None:
    os.write(2, b"interrupted while starting; nothing was written\n")
    os._exit(143 if signum == signal.SIGTERM else 130)


def quiet_start() -> None:
    """When Python runs one of the package's modules as a command (`python -m ...`: sys.argv[0] is "-m" while the
    package imports), a Ctrl-C (or SIGTERM) until `run_main` ends the process at once, with one line and exit 130
    (143).  An import
    for any other purpose, or a process that ignores Ctrl-C, is left as it is.  A command also keeps JAX's compiled
    programs (`offrl_jax.system.cache.keep_compiled_programs`)."""
    if sys.argv[:1] != ["-m"]:
        return
    keep_compiled_programs()
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        signal.signal(signal.SIGINT, _interrupted_while_starting)
    if signal.getsignal(signal.SIGTERM) is signal.SIG_DFL:  # `kill` while the imports run: the same line, exit 143
        signal.signal(signal.SIGTERM, _interrupted_while_starting)
    if sys.excepthook is sys.__excepthook__:
        sys.excepthook = _could_not_start


def _could_not_start(kind, value, tb) -> None:
    """An exception while the command's modules import is the environment's (a JAX variable JAX cannot read, a
    broken install), not the command's: one line, unless OFFRL_JAX_DEBUG=1 asks for the traceback."""
    if os.environ.get("OFFRL_JAX_DEBUG") == "1":
        sys.__excepthook__(kind, value, tb)
        return
    text = " ".join(str(value).split())
    sys.stderr.write(f"error: the command could not start: {kind.__name__}: {text[:300]} (OFFRL_JAX_DEBUG=1 shows "
                     "where)\n")


def _unsafe(frame) -> bool:
    """Whether an exception raised here could crash the process, turn into another error or be dropped (see the
    module doc): anywhere inside an import (a C extension being initialised crashes on it, numpy's turns it into an
    ImportError), or inside a callback whose exception Python prints and drops (JAX's garbage-collection callback,
    a weak reference's callback, a `__del__`)."""
    while frame is not None:
        code = frame.f_code
        if (code.co_filename.startswith("<frozen importlib") or code.co_name in ("_xla_gc_callback", "__del__")
                or code.co_filename.endswith(("weakref.py", "_weakrefset.py"))):
            return True
        frame = frame.f_back
    return False


_pending = False  # a Ctrl-C put off by `during_command` and not raised yet
_terminated = False  # the interrupt was a SIGTERM (exit 143, not 130)


def during_command(signum, frame) -> None:
    """SIGINT (or SIGTERM) while a command runs: KeyboardInterrupt, or, where it would be lost, the same again in
    50 ms (a timer's SIGALRM comes back here: no thread is started inside a callback)."""
    global _pending, _terminated
    if signum == signal.SIGTERM:
        _terminated = True
    if signum == signal.SIGALRM and not _pending:
        return  # a timer set before `finish` cancelled it
    if _unsafe(frame):
        _pending = True
        signal.signal(signal.SIGALRM, during_command)
        signal.setitimer(signal.ITIMER_REAL, RETRY_S)
        return
    _pending = False
    raise KeyboardInterrupt


def exit_code(code: int) -> int:
    """The exit status for a command that returned `code`: 143 for one that a SIGTERM interrupted (130 otherwise)."""
    return 143 if code == 130 and _terminated else code


@contextlib.contextmanager
def shielded():
    """Ctrl-C and SIGTERM ignored inside: for a command's clean-up, which must not stop half-way (an earlier run being
    given back, a lock being removed).  One that comes in there is dropped: the command has already written its
    results, or is already ending as interrupted; `finish` ignores them from when `main` returns."""
    if threading.current_thread() is not threading.main_thread():  # only the main thread may set handlers
        yield
        return
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    for s in before:
        signal.signal(s, signal.SIG_IGN)
    try:
        yield
    finally:
        for s, handler in before.items():
            signal.signal(s, handler)


def finish() -> bool:
    """When the command's `main` has returned: Ctrl-C and SIGTERM are ignored from now on (the interpreter is
    shutting down), any timer is cancelled, and the result says whether a Ctrl-C was still put off (the command
    then counts as interrupted)."""
    global _pending
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    signal.setitimer(signal.ITIMER_REAL, 0)
    pending, _pending = _pending, False
    return pending


def hand_over() -> None:
    """From `run_main`: the command's own Ctrl-C handling (`during_command`) replaces `quiet_start`'s."""
    if signal.getsignal(signal.SIGINT) in (_interrupted_while_starting, signal.default_int_handler):
        signal.signal(signal.SIGINT, during_command)
    # `kill`, a scheduler's stop: the same as Ctrl-C, also for a background job, whose SIGINT the shell ignores
    if signal.getsignal(signal.SIGTERM) in (_interrupted_while_starting, signal.SIG_DFL):
        signal.signal(signal.SIGTERM, during_command)
    if sys.excepthook is _could_not_start:  # the command reports its own errors from here on
        sys.excepthook = sys.__excepthook__
