"""Atomic files and checkpoints (flax.serialization msgpack): write to a temporary file in the same directory, fsync,
then `os.replace`, so a reader (or a resumed run) only ever sees a complete old file or a complete new one.

A checkpoint holds every seed's agent state (parameters, target parameters, optimiser states, temperature, soft
returns), the global update counter, the training seconds so far and the evaluation history.  No RNG state needs
saving: every key is a pure function of (seed, update) (see `offrl_jax.driver`).
"""
from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any

from flax import serialization


def _umask() -> int:
    """The process's umask (read by setting and restoring it: call it where no other thread creates files)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


_UMASK = _umask()  # once, at import, before any writer thread exists


def atomic_write_bytes(path: str | Path, data: bytes) -> None:
    """Write `path` all at once; its mode is what the umask gives a new file (mkstemp's own is 0600)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        os.fchmod(fd, 0o666 & ~_UMASK)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def atomic_write_text(path: str | Path, text: str) -> None:
    atomic_write_bytes(path, text.encode())


def save_checkpoint(path: str | Path, states: Any, update: int, seconds: float, history: list[dict],
                    meta: dict[str, Any] | None = None) -> None:
    """`meta`: what the states belong to and what acting needs, stored beside them: "fingerprint"
    (`offrl_jax.run.resume.group_fingerprint`, checked on resume), "members" ([label, seed] per member), "env",
    "obs_mean" and "obs_std" (the observation normalisation of training; `offrl_jax.policy`)."""
    payload = {
        "states": serialization.to_state_dict(states),
        "update": update,
        "seconds": seconds,
        "history": json.dumps(history),
    } | (meta or {})
    atomic_write_bytes(path, serialization.msgpack_serialize(payload))


def load_checkpoint(path: str | Path, template_states: Any) -> tuple[Any, int, float, list[dict]]:
    """(states, update, seconds, history); `template_states` gives the pytree structure (e.g. a fresh init)."""
    return checkpoint_contents(serialization.msgpack_restore(Path(path).read_bytes()), template_states)


def checkpoint_contents(payload: dict, template_states: Any) -> tuple[Any, int, float, list[dict]]:
    """`load_checkpoint` of a checkpoint's payload already read (`serialization.msgpack_restore`)."""
    states = serialization.from_state_dict(template_states, payload["states"])
    return states, int(payload["update"]), float(payload["seconds"]), json.loads(payload["history"])
