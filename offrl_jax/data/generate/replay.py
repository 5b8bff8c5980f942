"""The replay of a SAC run: every transition it saw, in order (the medium-replay / full-replay levels).

In memory a `ReplayBuffer` with capacity = the run's total steps (nothing is overwritten); on disk one
`replay/<start>_<end>.npz` per evaluation period of the run directory, with the `Dataset` array fields.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np


class ReplayBuffer:
    """Numpy replay of every transition seen (capacity = total steps, nothing is ever overwritten)."""

    def __init__(self, obs_dim: int, act_dim: int, capacity: int):
        self.data = {
            "observations": np.zeros((capacity, obs_dim), np.float32),
            "actions": np.zeros((capacity, act_dim), np.float32),
            "rewards": np.zeros(capacity, np.float32),
            "next_observations": np.zeros((capacity, obs_dim), np.float32),
            "terminals": np.zeros(capacity, np.float32),
            "timeouts": np.zeros(capacity, np.float32),
        }
        self.size = 0

    def add(self, obs, action, reward, next_obs, terminal: bool, timeout: bool) -> None:
        i = self.size
        d = self.data
        d["observations"][i] = obs
        d["actions"][i] = action
        d["rewards"][i] = reward
        d["next_observations"][i] = next_obs
        d["terminals"][i] = terminal
        d["timeouts"][i] = timeout
        self.size += 1

    def sample(self, rng: np.random.Generator, batch_size: int) -> dict[str, np.ndarray]:
        idx = rng.integers(0, self.size, batch_size)
        return {k: v[idx] for k, v in self.data.items()}

    def save_range(self, path: Path, start: int, end: int) -> None:
        np.savez(path, **{k: v[start:end] for k, v in self.data.items()})


def chunk_range(path: Path) -> tuple[int, int]:
    """(start, end) env steps of a `replay/<start>_<end>.npz` chunk."""
    start, end = path.stem.split("_")
    return int(start), int(end)


def load_replay(run_dir: str | Path, upto: int | None = None) -> dict[str, np.ndarray]:
    """Every transition of a run, in order, up to env step `upto` (all if None).  Dataset field arrays."""
    files = sorted((Path(run_dir) / "replay").glob("*.npz"))
    if not files:
        raise FileNotFoundError(f"no replay chunks in {run_dir}/replay")
    parts: dict[str, list[np.ndarray]] = {}
    for f in files:
        start, _ = chunk_range(f)
        if upto is not None and start >= upto:
            break
        with np.load(f) as z:
            for k in z.files:
                parts.setdefault(k, []).append(z[k])
    data = {k: np.concatenate(v) for k, v in parts.items()}
    if upto is not None:
        if len(data["rewards"]) < upto:
            raise ValueError(f"{run_dir} holds {len(data['rewards'])} transitions, fewer than the {upto} asked for")
        data = {k: v[:upto] for k, v in data.items()}
    return data


def reload_replay(run_dir: Path, buffer: ReplayBuffer, start: int) -> None:
    """Refill `buffer` with the first `start` transitions of the run in `run_dir`, delete the chunks of later steps, and
    end the episode cut at `start` with a time-out (rewriting its chunk): a run resumed at `start` goes on from a
    valid sequence of episodes."""
    for f in (run_dir / "replay").glob("*.npz"):
        if chunk_range(f)[0] >= start:
            f.unlink()
    if start == 0:
        return
    data = load_replay(run_dir, upto=start)
    for k, v in data.items():
        buffer.data[k][:start] = v
    buffer.size = start
    if not (buffer.data["terminals"][start - 1] or buffer.data["timeouts"][start - 1]):
        buffer.data["timeouts"][start - 1] = 1.0  # the interrupted episode ends here; rewrite its chunk
        last = max((run_dir / "replay").glob("*.npz"), key=lambda f: chunk_range(f)[1])
        lo, hi = chunk_range(last)
        if hi > start:  # the last chunk runs past the saved state: cut it there
            last.unlink()
            last = run_dir / "replay" / f"{lo:07d}_{start:07d}.npz"
        buffer.save_range(last, lo, start)
