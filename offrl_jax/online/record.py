"""The online phase's transitions as datasets: every member's env steps, as the env gave them (raw observations and
rewards, terminals and time-outs as offline), in D4RL's HDF5 layout, one file per member, which a later offline run
reads (`--dataset-path`, `offrl_jax.data.readers.read_d4rl_hdf5`).

    <run>/online/<env>-<variant>-seed<seed>.hdf5   observations, actions, rewards, terminals, timeouts,
                                                   next_observations; row t = the member's env step t of the phase

Rows are appended at every online evaluation, before the checkpoint.  A resumed phase cuts each file back to the env
step it goes on from (a stop between the two writes leaves rows the checkpoint does not know), so the files always
equal an uninterrupted run's.  The last episode of a file may be unfinished (no terminal or time-out on its last row),
as in D4RL's own files.  A member that diverged is not stepped after it (`MemberEnvs.step`): its rows from there on
have NaN next observations and rewards (and a time-out each), which a reader refuses.
"""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import h5py
import numpy as np

from offrl_jax.online.buffer import BLOCK_FIELDS

RECORD_DIR = "online"


def dataset_path(out_dir: Path, env: str, label: str, seed: int) -> Path:
    """Where a member's online transitions go: <out_dir>/online/<env>-<label>-seed<seed>.hdf5 (the env first, so
    that a reader infers it from the name)."""
    return Path(out_dir) / RECORD_DIR / f"{env}-{label}-seed{seed}.hdf5"


def record(paths: Sequence[Path], start: int, rows: dict[str, np.ndarray], attrs: dict | None = None) -> None:
    """Append member m's `rows` (`BLOCK_FIELDS`, each (S, n, ...)) to `paths[m]` as its env steps start..start+n-1:
    a file with more rows is cut back to `start` first (a resumed phase), one with fewer is refused (ValueError: its
    rows between would be missing).  `attrs` are written on a new file (env, variant, seed)."""
    n = rows["rewards"].shape[1]
    for path in paths:  # every file first: nothing is written unless all can go on
        have = _rows_in(path)
        if max(have, 0) < start:
            raise ValueError(f"{path}: missing, and the online phase is at env step {start}" if have < 0 else
                             f"{path}: holds {have} env steps, but the online phase goes on from {start}")
    for m, path in enumerate(paths):
        path.parent.mkdir(parents=True, exist_ok=True)
        with h5py.File(path, "a") as f:
            if "rewards" not in f:
                for name in BLOCK_FIELDS:
                    shape = rows[name].shape[2:]
                    f.create_dataset(name, shape=(0, *shape), maxshape=(None, *shape), dtype=np.float32,
                                     chunks=(min(n, 4096), *shape))
                f.attrs.update(attrs[m] if attrs else {})
            for name in BLOCK_FIELDS:
                f[name].resize(start + n, axis=0)
                f[name][start:] = np.asarray(rows[name][m], np.float32)


def _rows_in(path: Path) -> int:
    """The env steps a member's file holds; -1 where there is no file."""
    if not path.exists():
        return -1
    with h5py.File(path, "r") as f:
        return f["rewards"].shape[0] if "rewards" in f else 0


def record_chunk(out_dir: Path, env: str, members: Sequence[tuple[str, int]], end: int,
                 rows: dict[str, np.ndarray]) -> str | None:
    """`record` for the members (variant label, seed) of a run in `out_dir` whose online chunk ends at env step
    `end`: None, or the one line saying why their files cannot go on (nothing is written then)."""
    paths = [dataset_path(out_dir, env, label, seed) for label, seed in members]
    attrs = [{"env": env, "variant": label, "seed": seed} for label, seed in members]
    try:
        record(paths, end - rows["rewards"].shape[1], rows, attrs)
    except (ValueError, OSError) as e:  # OSError: a file another process holds, or one a kill left unreadable
        return f"online transitions not recorded: {e}"
    return None
