"""The start and end of every command (system.interrupts, system.cli.run_main): a Ctrl-C at any moment, and an
XLA_FLAGS that JAX cannot start with, are one line and a non-zero exit, never a traceback, and never lost."""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ENV = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "OFFRL_JAX_USER_XLA_FLAGS")}


# Python with Ctrl-C at its default even when the tests run where it is ignored (a background job of a shell):
# the first interpreter resets it and becomes the second (no preexec_fn: forking a process that holds JAX warns)
PYTHON = [sys.executable, "-c", "import os, signal, sys; signal.signal(signal.SIGINT, signal.SIG_DFL); "
          "os.execv(sys.executable, [sys.executable, *sys.argv[1:]])"]


def python(code: str, **env) -> subprocess.CompletedProcess:
    return subprocess.run([*PYTHON, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120,
                          env=ENV | env)


def one_line(stderr: str) -> str:
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in stderr, stderr
    return lines[0]


@pytest.mark.parametrize("package", ["experiments", "benchmarks", "offrl_jax"])
def test_ctrl_c_while_a_command_imports_ends_it_in_one_line(package):
    """`python -m package.module` sets sys.argv[0] to "-m" while it imports the package: a Ctrl-C then (here sent
    by the process to itself) ends the process at once, before any of the command's work."""
    result = python(f"import sys; sys.argv[0] = '-m'; import {package}, os, signal, time\n"
                    "os.kill(os.getpid(), signal.SIGINT); time.sleep(30); print('went on')")
    assert result.returncode == 130 and "went on" not in result.stdout
    assert one_line(result.stderr) == "interrupted while starting; nothing was written"


def test_an_import_for_other_purposes_keeps_python_s_ctrl_c():
    result = python("import experiments, benchmarks, offrl_jax, signal\n"
                    "assert signal.getsignal(signal.SIGINT) is signal.default_int_handler; print('kept')")
    assert result.returncode == 0 and "kept" in result.stdout, result.stderr


def test_run_main_gives_ctrl_c_back_to_the_command_and_reports_one_it_leaves():
    result = python("import sys; sys.argv[0] = '-m'; import experiments, os, signal, time\n"
                    "from offrl_jax.system.cli import run_main\n"
                    "from offrl_jax.system.interrupts import during_command\n"
                    "def main():\n"
                    "    assert signal.getsignal(signal.SIGINT) is during_command\n"
                    "    os.kill(os.getpid(), signal.SIGINT); time.sleep(30)\n"
                    "run_main(main)")
    assert result.returncode == 130
    assert one_line(result.stderr) == "interrupted"


def test_ctrl_c_inside_an_import_or_a_gc_callback_comes_again_after_it():
    """Inside an import (JAX imported lazily by a command) a KeyboardInterrupt can leave a C extension half
    initialised and crash the process, and inside JAX's garbage-collection callback Python drops it: there the
    handler sends the Ctrl-C again 50 ms later, so it lands after the import."""
    result = python("import sys; sys.argv[0] = '-m'; import experiments, os, signal, time, importlib.util\n"
                    "from offrl_jax.system.cli import run_main\n"
                    "def main():\n"
                    "    open('/dev/null').close()\n"
                    "    spec = importlib.util.spec_from_loader('slow', loader=None)\n"
                    "    import types; m = types.ModuleType('slow')\n"
                    "    code = 'import os, signal, time\\nos.kill(os.getpid(), signal.SIGINT)\\ntime.sleep(0.3)\\n"
                    "open(%r, \"w\").close()'\n"
                    "    import tempfile; d = tempfile.mkdtemp(); sys.path.insert(0, d)\n"
                    "    mark = os.path.join(d, 'imported')\n"
                    "    open(os.path.join(d, 'slowmod.py'), 'w').write(code % mark)\n"
                    "    import slowmod\n"
                    "    print('imported' if os.path.exists(mark) else 'cut'); sys.stdout.flush(); time.sleep(30)\n"
                    "run_main(main)")
    assert result.returncode == 130, result.stderr
    assert result.stdout.strip() == "imported"  # the import ran to its end; the Ctrl-C came after it
    assert one_line(result.stderr) == "interrupted"


def importing_the_command(pid: int, timeout: float = 60.0) -> None:
    """Waits until process `pid` imports the command's own modules (numpy's extension mapped: experiments.theory
    imports it after the package's `quiet_start`). Before that Python itself is starting (the wrapper above, then
    the new interpreter's `site`), and a Ctrl-C there is Python's own KeyboardInterrupt: on a loaded machine that
    lasts past any fixed sleep."""
    end = time.monotonic() + timeout
    while "_multiarray_umath" not in Path(f"/proc/{pid}/maps").read_text():
        assert time.monotonic() < end, "the command never imported numpy"
        time.sleep(0.005)


def test_a_real_command_interrupted_early_is_one_line():
    proc = subprocess.Popen([*PYTHON, "-m", "experiments.theory"], cwd=ROOT, env=ENV, text=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    importing_the_command(proc.pid)
    time.sleep(0.2)  # importing, or already working: either way one line
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130
    assert one_line(err).startswith("interrupted")


UNKNOWN = ("--xla_no_such_flag=1", "Unknown flag")  # XLA itself would end the process with its flag list


@pytest.mark.parametrize("module, flags, said", [
    ("offrl_jax.rollout", *UNKNOWN),
    ("offrl_jax.rollout", "--xla_force_host_platform_device_count=abc", "Couldn't interpret"),
    ("offrl_jax.rollout", "--xla_force_host_platform_device_count=0", "Unable to initialize"),
    ("benchmarks.throughput", *UNKNOWN),
    ("experiments.mujoco_medium", *UNKNOWN),
])
def test_xla_flags_jax_cannot_start_with_are_one_line(tmp_path, module, flags, said):
    result = subprocess.run([sys.executable, "-m", module, "--help"], cwd=tmp_path, capture_output=True, text=True,
                            timeout=120, env=ENV | {"XLA_FLAGS": flags, "PYTHONPATH": str(ROOT)})
    assert result.returncode == 2
    line = one_line(result.stderr)
    assert line.startswith(f"error: JAX cannot start with XLA_FLAGS={flags!r}") and said in line
    assert not list(tmp_path.iterdir())


def test_an_environment_jax_cannot_import_with_is_one_line(tmp_path):
    """JAX reads its own variables when it is imported, before a command's main: one line, not a traceback."""
    result = subprocess.run([sys.executable, "-m", "experiments.theory", "--help"], cwd=tmp_path, capture_output=True,
                            text=True, timeout=120, env=ENV | {"JAX_ENABLE_X64": "garbage", "PYTHONPATH": str(ROOT)})
    assert result.returncode != 0 and not result.stdout
    line = one_line(result.stderr)
    assert line.startswith("error: the command could not start: ValueError:") and "JAX_ENABLE_X64" in line


def test_a_signal_during_a_commands_clean_up_does_not_cut_it_and_a_finished_run_exits_0():
    """The clean-up gives an earlier run back or removes the lock: a SIGTERM or Ctrl-C there is dropped (the results
    are written, or the command is already ending as interrupted), and so is one after `main` returns."""
    result = python("import sys; sys.argv[0] = '-m'; import experiments, argparse, os, signal, time\n"
                    "from offrl_jax.app import command\n"
                    "from offrl_jax.system.cli import run_main\n"
                    "for step in ('read', 'start_processes', 'claim_output', 'check_resume', 'run'):\n"
                    "    setattr(command.Command, step, lambda self, *a: None)\n"
                    "command.Command.load = lambda self: []\n"
                    "def clean_up(self, ok):\n"
                    "    for s in (signal.SIGTERM, signal.SIGINT):\n"
                    "        os.kill(os.getpid(), s)\n"
                    "    time.sleep(0.2); print('cleaned up', ok); return None\n"
                    "command.Command.clean_up = clean_up\n"
                    "def main():\n"
                    "    code = command.run_command(lambda a: None, argparse.ArgumentParser(), [])\n"
                    "    assert signal.getsignal(signal.SIGTERM) is not signal.SIG_IGN  # given back after it\n"
                    "    return code\n"
                    "run_main(main)\n")
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "cleaned up True" and result.stderr == ""


def test_sigterm_while_a_command_imports_ends_it_in_the_same_one_line_with_143():
    result = python("import sys; sys.argv[0] = '-m'; import experiments, os, signal, time\n"
                    "os.kill(os.getpid(), signal.SIGTERM); time.sleep(30); print('went on')")
    assert result.returncode == 143 and "went on" not in result.stdout
    assert one_line(result.stderr) == "interrupted while starting; nothing was written"
