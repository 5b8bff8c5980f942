"""What a run records about where it came from: the command, the code, the software, the machine and the data.

`run_record(dataset)` is written into every run's config.json (and each resume adds one), so a reader of a result
can tell which commit, which versions and which exact dataset made it:

    command      the command line, as typed (`python -m experiments.mujoco_medium --alpha 10`)
    git          commit and whether the working tree had uncommitted changes (null outside a git checkout)
    versions     python and the packages whose behaviour shapes a result
    backend      JAX's platform and device kind
    dataset      name or path, transitions used, and a SHA-256 of the arrays trained on
"""
from __future__ import annotations

import hashlib
import json
import platform
import shlex
import subprocess
import sys
import time
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

PACKAGES = ("jax", "jaxlib", "flax", "optax", "gymnasium", "mujoco", "minari", "numpy")
DATA_ARRAYS = ("observations", "actions", "rewards", "next_observations", "terminals", "timeouts")


def command_line(argv: list[str] | None = None) -> str:
    """The command as typed: `python -m <module> args` for a module run, else `python <script> args`."""
    argv = list(sys.argv if argv is None else argv)
    main = sys.modules.get("__main__")
    spec = getattr(main, "__spec__", None)
    head = ["python", "-m", spec.name] if spec is not None and spec.name != "__main__" else ["python", *argv[:1]]
    return shlex.join(head + argv[1:])


def git_state(where: Path | None = None) -> dict[str, Any] | None:
    """{"commit", "dirty"} of the checkout holding this package (None if it is not one, or git is missing)."""
    where = where or Path(__file__).resolve().parents[2]
    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=where, capture_output=True, text=True, timeout=10)
        if commit.returncode != 0:
            return None
        status = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=where,
                                capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return None
    return {"commit": commit.stdout.strip(), "dirty": bool(status.stdout.strip())}


def versions() -> dict[str, str | None]:
    found: dict[str, str | None] = {"python": platform.python_version()}
    for name in PACKAGES:
        try:
            found[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            found[name] = None
    return found


def backend() -> dict[str, Any]:
    import jax

    devices = jax.devices()
    return {"platform": jax.default_backend(), "device_kind": devices[0].device_kind, "devices": len(devices),
            "machine": platform.machine(), "system": platform.system()}


def fingerprint(ds) -> str:
    """SHA-256 over the dataset's arrays (field names, shapes, dtypes and bytes, in a fixed order)."""
    digest = hashlib.sha256()
    for name in DATA_ARRAYS:
        array = np.ascontiguousarray(getattr(ds, name))
        digest.update(f"{name}:{array.shape}:{array.dtype};".encode())
        digest.update(array.tobytes())
    return digest.hexdigest()


def dataset_identity(ds, source: str, sha256: str | None = None) -> dict[str, Any]:
    return {"source": source, "name": getattr(ds, "name", None), "transitions": len(ds),
            "sha256": sha256 or fingerprint(ds)}


def run_record(ds=None, source: str = "", sha256: str | None = None) -> dict[str, Any]:
    """Everything above, with the time it was taken (`sha256`: the dataset's fingerprint, if already computed)."""
    record = {"time": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "command": command_line(), "git": git_state(),
              "versions": versions(), "backend": backend()}
    if ds is not None:
        record["dataset"] = dataset_identity(ds, source, sha256)
    return record


def recorded_data(config_path) -> str | None:
    """The dataset SHA-256 that a run's config.json recorded last (None for runs that recorded none)."""
    try:
        runs = json.loads(config_path.read_text()).get("runs", [])
        return next((r["dataset"]["sha256"] for r in reversed(runs) if isinstance(r.get("dataset"), dict)
                     and isinstance(r["dataset"].get("sha256"), str)), None)
    except (ValueError, AttributeError, TypeError, OSError):
        return None


def recorded_command(config_path) -> list[str] | None:
    """The command line of a run's last start or resume, as its config.json recorded it (None where none was)."""
    try:
        runs = json.loads(config_path.read_text()).get("runs", [])
        return shlex.split(runs[-1]["command"]) if runs and isinstance(runs[-1].get("command"), str) else None
    except (ValueError, AttributeError, TypeError, OSError, KeyError):
        return None
