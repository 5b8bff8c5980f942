"""The one in-memory dataset type every reader and generator produces.

Episode boundaries: a row ends its episode when `terminals` (a true terminal: no bootstrapping past it) or `timeouts`
(a time limit or a cut: the task goes on) is set, or when it is the last row of the dataset.  A row whose successor was
never recorded (the last step of a time-out without a next observation, e.g. the door demonstrations) gets
`next_observations = observations` of that row: bootstrapping Q(s_T, pi(s_T)) there is the same "last reward repeated
forever" assumption as the r_T / (1 - gamma) tail of the returns-to-go.
"""
from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np

from offrl_jax.system.cache import cache_dir

ARRAY_FIELDS = ("observations", "actions", "rewards", "next_observations", "terminals", "timeouts")
NORMALIZE_EPS = 1e-3


class DatasetError(ValueError):
    """A dataset could not be read or failed validation.  The message is one line naming the file and the problem."""


@dataclasses.dataclass
class Dataset:
    observations: np.ndarray  # (T, obs_dim) float32
    actions: np.ndarray  # (T, act_dim) float32
    rewards: np.ndarray  # (T,) float32
    next_observations: np.ndarray  # (T, obs_dim) float32
    terminals: np.ndarray  # (T,) float32 in {0, 1}
    timeouts: np.ndarray  # (T,) float32 in {0, 1}: episode ends that are not terminals
    env: str | None = None  # short env name from `offrl_jax.envs.registry.ENVS` (e.g. "hopper"), if known
    name: str = "dataset"  # e.g. "hopper-medium" or the file name
    source: str = ""  # where it came from (path, "generated", ...)

    def __len__(self) -> int:
        return int(self.rewards.shape[0])

    @property
    def obs_dim(self) -> int:
        return int(self.observations.shape[1])

    @property
    def act_dim(self) -> int:
        return int(self.actions.shape[1])

    @property
    def episode_ends(self) -> np.ndarray:
        """(T,) bool: the row ends an episode (terminal, time-out or dataset end)."""
        ends = (self.terminals > 0) | (self.timeouts > 0)
        ends[-1] = True
        return ends

    @property
    def episode_ids(self) -> np.ndarray:
        """(T,) int32 episode index of every row."""
        ends = self.episode_ends
        return np.concatenate([[0], np.cumsum(ends[:-1])]).astype(np.int32)

    def episode_returns(self) -> np.ndarray:
        """(E,) undiscounted return of every episode."""
        return np.bincount(self.episode_ids, weights=self.rewards).astype(np.float64)

    def reward_scale(self, steps: int = 1000) -> float:
        """`steps` / (max - min episode return): the factor that gives the dataset's episode returns a range of
        `steps` (CORL's reward normalisation for MuJoCo; 1 when every episode has the same return).  As CORL's, it
        leaves out a last episode that the data cuts off (no terminal or time-out on its last row, as after
        --max-transitions)."""
        returns = self.episode_returns()
        if returns.size > 1 and not (self.terminals[-1] or self.timeouts[-1]):
            returns = returns[:-1]
        spread = float(returns.max() - returns.min()) if returns.size else 0.0
        return steps / spread if spread > 0 else 1.0

    def obs_stats(self) -> tuple[np.ndarray, np.ndarray]:
        """Mean and std (+1e-3) of the observations, for state normalisation (applied identically at evaluation)."""
        mean = self.observations.mean(0).astype(np.float32)
        std = (self.observations.std(0) + NORMALIZE_EPS).astype(np.float32)
        return mean, std

    def select(self, rows: np.ndarray | slice) -> Dataset:
        """A sub-dataset of the given rows (keeps metadata)."""
        arrays = {f: getattr(self, f)[rows] for f in ARRAY_FIELDS}
        return dataclasses.replace(self, **arrays)

    def first(self, n: int) -> Dataset:
        """The first `n` rows, an episode they cut off ending in a time-out (not a terminal): the rows a generator
        asked for `n` transitions writes, so either way of getting them gives the same data."""
        head = self.select(slice(0, n))
        if n < len(self) and not head.terminals[-1]:
            timeouts = head.timeouts.copy()  # a slice is a view: the full dataset stays as it is
            timeouts[-1] = 1
            head = dataclasses.replace(head, timeouts=timeouts)
        return head


def rows_without_timeouts(timeouts) -> np.ndarray:
    """(K,) indices of the rows that are not time-outs: the only rows sampled when time-out rows are dropped
    (`timeouts = "drop"`, as CORL's loader does)."""
    return np.flatnonzero(np.asarray(timeouts) == 0)


def normalize_obs(obs: np.ndarray, mean: np.ndarray, std: np.ndarray) -> np.ndarray:
    return (obs - mean) / std


# the generated locomotion datasets, <env>-<level> for each (the study flags offer the levels in this order; the
# catalogue describes them, `offrl_jax.data.generate` makes them)
LOCOMOTION_ENVS = ("hopper", "halfcheetah", "walker2d")
LOCOMOTION_LEVELS = ("medium", "medium-replay", "full-replay", "medium-expert", "expert", "random")

# Generated datasets whose making changed, with their current version (every other generated dataset is at 0).  An
# earlier version stays loadable by its Minari id, "<name>-v<N>" (docs/datasets.md, "Versions").
DATASET_VERSIONS: dict[str, int] = {"hopper-medium": 2, "hopper-medium-expert": 2}
_VERSION = re.compile(r"^(?P<base>.+)-v(?P<version>\d+)$")


def split_version(name: str) -> tuple[str, int]:
    """("hopper-medium", 0) for "hopper-medium-v0"; a name without a version is its current one."""
    m = _VERSION.match(name)
    if m:
        return m["base"], int(m["version"])
    return name, DATASET_VERSIONS.get(name, 0)


def is_current(name: str) -> bool:
    """Whether `name` (with or without a version) stands for the current version of its dataset."""
    base, version = split_version(name)
    return version == DATASET_VERSIONS.get(base, 0)


def dataset_dir(name: str) -> Path:
    """The cached Minari directory of generated dataset `name`: cache_dir()/datasets/<name>-v<version>, the current
    version unless `name` names one ("hopper-medium-v0").

    The `-v<N>` suffix is Minari's id convention, so `MINARI_DATASETS_PATH=<cache>/datasets minari list local` and
    `minari.load_dataset("hopper-medium-v2")` see our datasets.  A directory from before the suffix is renamed.
    """
    root = cache_dir() / "datasets"
    base, version = split_version(name)
    path, legacy = root / f"{base}-v{version}", root / base
    if version == 0 and not path.exists() and (legacy / "data" / "metadata.json").is_file():
        legacy.rename(path)
    return path
