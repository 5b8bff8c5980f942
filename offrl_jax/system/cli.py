"""What every command of the project shares: one-line errors (`error: ...`, exit 2), typed numbers that refuse NaN,
infinities and out-of-range values while the flags are parsed, a check that an output place is writable before
any work is spent, and the end of a command (`run_main`): an unhandled Ctrl-C and an XLA_FLAGS that JAX cannot
start with are one line (`offrl_jax.system.interrupts` for Ctrl-C while a command starts)."""
from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import NoReturn

from offrl_jax.system.interrupts import exit_code, finish, hand_over


class UsageError(ValueError):
    """A command line that cannot run as given: reported as one line, exit 2."""


def print_error(message: object) -> None:
    """One line on stderr, whatever the message holds: a newline in a path or a value is shown as \\n."""
    text = str(message).replace("\r", "\\r").replace("\n", "\\n")
    print(f"error: {text}", file=sys.stderr)


class OneLineParser(argparse.ArgumentParser):
    """argparse with a one-line error (argparse prints usage + error), no prefix matching of flags ("--pretrain"
    must not silently mean "--pretrain-updates"), and no repeated value in a list of choices ("--envs hopper
    hopper" would train the same study twice)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **{"allow_abbrev": False} | kwargs)

    def parse_known_args(self, args=None, namespace=None):
        parsed, extra = super().parse_known_args(args, namespace)
        for action in self._actions:
            values = getattr(parsed, action.dest, None)
            if action.choices is not None and action.nargs in ("+", "*") and isinstance(values, list):
                repeated = sorted({str(v) for v in values if values.count(v) > 1})
                if repeated:
                    self.error(f"argument {'/'.join(action.option_strings) or action.dest}: "
                               f"{', '.join(repeated)} given more than once")
        return parsed, extra

    def error(self, message: str):
        print_error(message)
        sys.exit(2)


COUNT_MAX = 2**31 - 1  # counters (updates, evaluation steps) are int32 inside the jitted programs


def _whole(text: str, what: str) -> int:
    """`text` as an integer, "1e6" included ("2.5e0" and "1e400" not)."""
    try:
        number = float(text) if "e" in text.lower() else int(text)
        value = int(number)
        if value != number:
            raise ValueError
    except (ValueError, OverflowError):
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
    return value


def integer(text: str) -> int:
    """A config's integer field from the command line (its range is the config's to check): |value| < 2**31."""
    value = _whole(text, "an integer")
    if abs(value) > COUNT_MAX:
        raise argparse.ArgumentTypeError(f"expected an integer below 2**31 in size, got {text!r}")
    return value


def positive_int(text: str) -> int:
    """A count: an integer in [1, 2**31); "1e6" is accepted, "2.5e0", "1e400" and "1e26" are not."""
    value = _whole(text, "a positive integer")
    if not 0 < value <= COUNT_MAX:
        raise argparse.ArgumentTypeError(f"expected a positive integer below 2**31, got {text!r}")
    return value


def seed_int(text: str) -> int:
    """A random seed: an integer in [0, 2**31)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a seed (an integer in [0, 2**31)), got {text!r}") from None
    if not 0 <= value < 2**31:
        raise argparse.ArgumentTypeError(f"expected a seed (an integer in [0, 2**31)), got {text!r}")
    return value


def int_at_least(low: int, high: int = COUNT_MAX) -> Callable[[str], int]:
    """An integer in [low, high] (by default below 2**31, as every count is)."""
    where = f">= {low}" if high == COUNT_MAX else f"in [{low}, {high}]"

    def convert(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer {where}, got {text!r}") from None
        if value < low or value > high:
            bound = " below 2**31" if high == COUNT_MAX and value > high else ""
            raise argparse.ArgumentTypeError(f"expected an integer {where}{bound}, got {text!r}")
        return value
    return convert


def number(low: float = -math.inf, high: float = math.inf, low_open: bool = False,
           high_open: bool = False) -> Callable[[str], float]:
    """A finite float within [low, high] (open at an end where asked), as an argparse type."""
    left, right = "(" if low_open else "[", ")" if high_open else "]"
    if high == math.inf:
        where = "" if low == -math.inf else f" {'>' if low_open else '>='} {low:g}"
    else:
        where = f" {'<' if high_open else '<='} {high:g}" if low == -math.inf else f" in {left}{low:g}, {high:g}{right}"

    def convert(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number{where}, got {text!r}") from None
        inside = (value > low if low_open else value >= low) and (value < high if high_open else value <= high)
        if not math.isfinite(value) or not inside:
            raise argparse.ArgumentTypeError(f"expected a finite number{where}, got {text!r}")
        return value
    return convert


def file_for_run_dir(path: Path, what: str, marker: str) -> str | None:
    """The one-line refusal of a file given to --resume where `what` (a run directory) belongs, naming the file's
    folder when that holds `marker`, a file such a run writes; None when `path` is not a file."""
    if not path.is_file():
        return None
    mean = f": did you mean {path.parent}?" if (path.parent / marker).is_file() else ""
    return f"--resume takes {what}, not a file{mean}"


def check_writable_dir(path: Path) -> None:
    """Raise OSError (one line) unless `path` is, or can be made, a directory this process can write a file in.
    Tried for real (directories made, a temporary file written), then undone: nothing is left behind."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise OSError(f"{path} is a file, not a directory")
    missing = [d for d in (path, *path.parents) if not d.exists()]
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path):
            pass
    except OSError as e:
        raise OSError(f"{path}: not writable ({e.strerror or e})") from None
    finally:
        for d in missing:  # deepest first
            try:
                d.rmdir()
            except OSError:
                pass


def check_writable_file(path: Path) -> None:
    """Raise OSError unless a file can be written at `path` (its directory writable, itself not a directory)."""
    path = Path(path)
    if path.is_dir():
        raise OSError(f"{path} is a directory, not a file")
    check_writable_dir(path.parent if str(path.parent) else Path("."))


def lock_file(path: Path) -> Path:
    """The OS lock of run directory `path` (`lock_run_dir`): a file beside it."""
    path = Path(path).resolve()
    return path.parent / f".{path.name}.lock"


def being_written(path: Path) -> bool:
    """Whether a process holds the lock of run directory `path` now (a run, a resume or an --overwrite of it)."""
    import fcntl

    try:
        handle = open(lock_file(path))  # noqa: SIM115
    except OSError:  # no lock file: nobody has it
        return False
    with handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return True
    return False


def lock_run_dir(path: Path):
    """Hold an OS lock (flock) on `path` for as long as the returned file stays open (the process's life): a second
    process asking for the same run directory gets OSError at once.  The lock file sits beside the directory
    (`.<name>.lock`), so it also covers a directory that --overwrite deletes and makes again."""
    import fcntl

    path = Path(path).resolve()
    created = [p for p in reversed(path.parents) if not p.exists()]  # made here, outermost first
    path.parent.mkdir(parents=True, exist_ok=True)
    place = lock_file(path)
    while True:
        handle = open(place, "a")  # noqa: SIM115  (kept open: it is the lock)
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.close()
            raise OSError(f"{path} is being written by another process; wait for it or choose another --out") from None
        # the holder before us deletes the lock file as it lets go: a lock on a file no longer at its place is no
        # lock (a third process would lock a new file there), so take the one at its place
        try:
            current = os.stat(place).st_ino == os.fstat(handle.fileno()).st_ino
        except FileNotFoundError:
            current = False
        if current:
            handle.created_dirs = created  # the caller removes them (if still empty) with the lock
            return handle
        handle.close()


def one_line_warnings() -> None:
    """Print Python warnings as one `warning: ...` line each (not Python's two lines with a source path)."""
    import warnings

    def show(message, category, filename, lineno, file=None, line=None):
        print(f"warning: {' '.join(str(message).split())}", file=sys.stderr if file is None else file)

    warnings.showwarning = show


XLA_FLAGS_CHECKED = "OFFRL_JAX_XLA_FLAGS_CHECKED"  # the user's XLA_FLAGS that a process of this command tree checked


def check_xla_flags() -> None:
    """Raise UsageError (one line) if JAX cannot start with the user's XLA_FLAGS.  XLA ends the process itself
    (a fatal log, its whole flag list) on an unknown flag or a value it cannot read, so the flags are tried in a
    child process first: about a second, and only when XLA_FLAGS is set (once per command, not again in the
    processes it starts)."""
    from offrl_jax.system.workers import USER_XLA_FLAGS

    flags = os.environ.get(USER_XLA_FLAGS, os.environ.get("XLA_FLAGS", "")).strip()
    if not flags or os.environ.get(XLA_FLAGS_CHECKED) == flags:
        return
    env = {k: v for k, v in os.environ.items() if k != USER_XLA_FLAGS} | {"XLA_FLAGS": flags}
    try:
        tried = subprocess.run([sys.executable, "-c", "import jax; jax.devices()"], env=env, capture_output=True,
                               text=True, timeout=300, stdin=subprocess.DEVNULL)
    except (OSError, subprocess.TimeoutExpired):
        return  # no verdict: the command itself will tell
    if tried.returncode != 0:
        lines = [line.strip() for line in tried.stderr.splitlines() if line.strip()]
        said = next((line for line in lines if any(k in line for k in ("Unknown flag", "Couldn't interpret",
                                                                         "Unable to initialize"))),
                    lines[-1] if lines else f"exit status {tried.returncode}")
        said = said.split("] ", 1)[-1] if said[:1] in "EFW" and "] " in said else said  # drop XLA's log prefix
        raise UsageError(f"JAX cannot start with XLA_FLAGS={flags!r}: {said[:300]}")
    os.environ[XLA_FLAGS_CHECKED] = flags


def run_main(main: Callable[[], object]) -> NoReturn:
    """The `if __name__ == "__main__"` of every command.  Ctrl-C (and SIGTERM) is a KeyboardInterrupt from here on
    (`offrl_jax.system.interrupts`); one the command does not handle itself is one line, exit 130 (143 for SIGTERM), and
    the process ends at
    once (an interpreter shutting down while XLA was compiling could crash).  An XLA_FLAGS that JAX cannot start
    with is one line, exit 2, before the command's work."""
    try:
        hand_over()
        check_xla_flags()
        code = main()
        if finish():  # a Ctrl-C put off until main had returned
            raise KeyboardInterrupt
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(exit_code(130))
    except (UsageError, RuntimeError) as e:
        if os.environ.get("OFFRL_JAX_DEBUG") == "1" or not (
                isinstance(e, UsageError) or "Unable to initialize backend" in str(e)):
            raise
        print_error(e)
        code = 2
    if code == 130:  # interrupted, and said so: leave at once too (a shutdown after a SIGTERM could segfault)
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(exit_code(130))
    sys.exit(exit_code(code) if isinstance(code, int) else 0)
