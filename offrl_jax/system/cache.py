"""Where the project keeps what it can make again: generated datasets, SAC runs, JAX's compiled programs."""
from __future__ import annotations

import os
from pathlib import Path


def cache_dir() -> Path:
    """$OFFRL_JAX_CACHE, else $XDG_CACHE_HOME/offrl_jax, else ~/.cache/offrl_jax."""
    if os.environ.get("OFFRL_JAX_CACHE"):
        return Path(os.environ["OFFRL_JAX_CACHE"])
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "offrl_jax"


def keep_compiled_programs() -> None:
    """JAX's compiled programs in cache_dir()/xla, for the next command (unless $JAX_COMPILATION_CACHE_DIR says
    where): set in the environment before JAX is imported, so worker processes have it too."""
    if "JAX_COMPILATION_CACHE_DIR" not in os.environ:  # 12 s less start-up for a tiny run the second time
        os.environ["JAX_COMPILATION_CACHE_DIR"] = str(cache_dir() / "xla")
        os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.1")  # most of a tiny run's programs
