"""`python -m MODULE ARGS` for the tests, in a tenth of the time: `run_module` hands the command to a server process
that has imported JAX, flax and the package once and forks a child per command, which runs the module as `python
-m` would (`runpy`, `quiet_start`'s handlers, exit functions at the end) with its own stdout, stderr, cwd and an
empty stdin.  A command starts in ~0.3 s instead of ~3 s of imports, which is most of what a refused command costs.

What the fork cannot give is a fresh interpreter's environment: a call with `env` (read by JAX or XLA when they are
imported) runs as a plain subprocess, as do the tests of signals and worker processes (they call `subprocess`
themselves).  One server per test process (pytest-xdist worker), started on first use, ended at exit.
"""
from __future__ import annotations

import atexit
import json
import os
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SERVER = r'''
import atexit, json, os, runpy, signal, sys, time, traceback
import jax, flax, optax  # noqa: F401 -- imported once, before any fork; no backend is started here
import offrl_jax.app.command, offrl_jax.app.studies, offrl_jax.policy, offrl_jax.data.readers  # noqa: F401
from offrl_jax.system.interrupts import quiet_start

def child(req):
    for fd, path, flags in ((0, os.devnull, os.O_RDONLY), (1, req["stdout"], os.O_WRONLY | os.O_TRUNC),
                            (2, req["stderr"], os.O_WRONLY | os.O_TRUNC)):
        os.dup2(os.open(path, flags), fd)
    os.chdir(req["cwd"])
    sys.argv = ["-m"]
    quiet_start()  # what a package's __init__ does for `python -m`
    sys.argv = [req["module"], *req["args"]]
    # run as __main__, not found already imported (runpy would warn); a package runs its __main__ submodule
    main = req["module"] + ".__main__" if hasattr(sys.modules.get(req["module"]), "__path__") else req["module"]
    sys.modules.pop(main, None)
    code = 0
    try:
        runpy.run_module(req["module"], run_name="__main__", alter_sys=True)
    except SystemExit as e:
        code = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
        if not isinstance(e.code, (int, type(None))):
            print(e.code, file=sys.stderr)
    except BaseException:
        sys.excepthook(*sys.exc_info())
        code = 1
    try:
        atexit._run_exitfuncs()
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)

for line in sys.stdin:
    req = json.loads(line)
    pid = os.fork()
    if pid == 0:
        child(req)
    deadline, status = time.monotonic() + req["timeout"], None
    while status is None:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done == 0:
            status = None
            if time.monotonic() > deadline:
                os.kill(pid, signal.SIGKILL)
            time.sleep(0.01)
    print(json.dumps({"returncode": os.waitstatus_to_exitcode(status)}), flush=True)
'''

_server: subprocess.Popen | None = None
_lock = threading.Lock()


def _start() -> subprocess.Popen:
    global _server
    if _server is None or _server.poll() is not None:
        _server = subprocess.Popen([sys.executable, "-c", SERVER], cwd=ROOT, stdin=subprocess.PIPE,
                                   stdout=subprocess.PIPE, text=True, bufsize=1)
        atexit.register(_server.kill)
    return _server


def run_module(module: str, *args, cwd=ROOT, timeout: float = 300, env: dict | None = None
               ) -> subprocess.CompletedProcess:
    """`python -m module args` in `cwd`: a CompletedProcess with text stdout and stderr."""
    argv = [str(a) for a in args]
    if env is not None:
        return subprocess.run([sys.executable, "-m", module, *argv], cwd=cwd, env={**os.environ, **env},
                              capture_output=True, text=True, timeout=timeout)
    with _lock, tempfile.TemporaryDirectory() as tmp:
        out, err = Path(tmp) / "stdout", Path(tmp) / "stderr"
        out.touch()
        err.touch()
        server = _start()
        request = {"module": module, "args": argv, "cwd": str(cwd), "timeout": timeout, "stdout": str(out),
                   "stderr": str(err)}
        server.stdin.write(json.dumps(request) + "\n")
        reply = json.loads(server.stdout.readline())
        return subprocess.CompletedProcess([sys.executable, "-m", module, *argv], reply["returncode"],
                                           out.read_text(), err.read_text())
