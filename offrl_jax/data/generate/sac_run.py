"""A SAC run directory's state (the files are listed in `offrl_jax.data.generate.sac`): the whole training state
saved at an evaluation (`save_state`), a new run's --out checked to hold no run (`check_new_run`), a stopped run's
files checked to resume from (`resume_info`), and what a run stopped before its first saved state wrote removed
(`discard_unstarted`).
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from offrl_jax.data.generate.replay import chunk_range
from offrl_jax.data.generate.sac_learner import SACConfig, SACState, check_state_bytes, state_to_bytes
from offrl_jax.envs.registry import get_env_spec
from offrl_jax.system.checkpoint import atomic_write_bytes, atomic_write_text
from offrl_jax.system.cli import file_for_run_dir


def save_state(out: Path, state: SACState, rng: np.random.Generator, step: int) -> None:
    """The whole training state after `step` env steps (atomic: a kill leaves the previous one)."""
    atomic_write_bytes(out / "state.msgpack", state_to_bytes(state))
    atomic_write_text(out / "state.json", json.dumps({"step": step, "rng": rng.bit_generator.state}))


def check_new_run(out: Path) -> None:
    """Raise FileExistsError (one line) if `out` holds what a SAC run writes: a new run there would mix with it."""
    out = Path(out)
    if not out.is_dir():
        return
    found = [n for n in ("run.json", "state.json", "state.msgpack") if (out / n).exists()]
    if (out / "log.jsonl").is_file() and (out / "log.jsonl").stat().st_size > 0:
        found.append("log.jsonl")
    found += [f"{d}/" for d in ("checkpoints", "replay") if (out / d).is_dir() and any((out / d).iterdir())]
    if found:
        raise FileExistsError(f"{out} already holds a SAC run ({', '.join(found)}); use a new --out or --resume")


def resume_info(out: Path) -> tuple[dict[str, Any], dict[str, Any], SACConfig]:
    """(run.json, state.json: {"step", "rng"}, config) of a run to resume; ValueError (one line) for a directory
    that holds no complete run to continue."""
    if refusal := file_for_run_dir(out, "a SAC run directory", "run.json"):
        raise FileNotFoundError(refusal)
    if not (out / "run.json").is_file() or not (out / "state.json").is_file():
        raise FileNotFoundError(f"{out}: nothing to resume (needs run.json and state.json from a run of this version)")
    try:
        run, saved = json.loads((out / "run.json").read_text()), json.loads((out / "state.json").read_text())
        needed = {"run.json": (run, ("env", "seed", "steps", "eval_every", "eval_episodes", "config", "checkpoints")),
                  "state.json": (saved, ("step", "rng"))}
        for name, (content, keys) in needed.items():
            if missing := [k for k in keys if k not in content]:
                raise ValueError(f"{name} has no {', '.join(missing)}")
        start = int(saved["step"])
        get_env_spec(run["env"])
        cfg = SACConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in run["config"].items()})
        upto = 0  # replay chunks must cover the first `start` steps without a gap
        for lo, hi in sorted(chunk_range(f) for f in (out / "replay").glob("*.npz")):
            upto = hi if lo == upto else upto
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as e:
        raise ValueError(f"{out}: not a SAC run that can be resumed ({type(e).__name__}: {e})") from None
    if not (out / "state.msgpack").is_file():
        raise FileNotFoundError(f"{out}: nothing to resume (state.msgpack is missing)")
    if upto < start:
        raise FileNotFoundError(f"{out}/replay holds the first {upto} transitions, not the {start} the saved state "
                                "needs")
    try:
        check_state_bytes((out / "state.msgpack").read_bytes())
    except ValueError as e:
        raise ValueError(f"{out}: {e}") from None
    return run, saved, cfg


def discard_unstarted(out: Path) -> None:
    """Remove what a new run wrote in `out` before its first saved state (nothing there can be resumed), so that
    the same --out can start again; files of others in `out` stay."""
    if (out / "state.json").exists():
        return
    for name in ("run.json", "log.jsonl", "state.msgpack"):
        (out / name).unlink(missing_ok=True)
    for folder, pattern in (("checkpoints", "actor_*.msgpack"), ("replay", "*.npz")):
        for f in (out / folder).glob(pattern):
            f.unlink()
        if (out / folder).is_dir() and not any((out / folder).iterdir()):
            (out / folder).rmdir()
    if out.is_dir() and not any(out.iterdir()):
        out.rmdir()
