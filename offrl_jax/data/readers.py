"""Readers for offline RL data on disk -> a validated `Dataset` (float32 arrays, terminals/timeouts in {0, 1}).

Formats:
  * D4RL HDF5 (`read_d4rl_hdf5`): flat arrays observations (T, obs_dim), actions (T, act_dim), rewards (T,),
    terminals (T,), optional timeouts (T,) and next_observations (T, obs_dim); gzip-compressed files work as is.
  * Minari (`read_minari`): a dataset directory (`data/main_data.hdf5` + `data/metadata.json`) or a dataset id under
    $MINARI_DATASETS_PATH; one group `episode_N` per episode with T+1 observations and T of everything else.
  * Adroit demonstrations (`read_door_npz`): concatenated trajectories plus `episode_lengths` (E,).

Every reader ends with `validate`, which raises `DatasetError` with a one-line message "<path>: <problem>".
One file for the three formats (about 420 lines): they share `validate` and the path and key checks, and a
reader looking for how a file on disk becomes a `Dataset` finds every format here.
"""
from __future__ import annotations

import json
import os
import warnings
import zipfile
from pathlib import Path

import h5py
import numpy as np

from offrl_jax.data.dataset import Dataset, DatasetError
from offrl_jax.envs.registry import ENVS

FILE_SUFFIXES = (".hdf5", ".h5", ".npz")  # a dataset file: D4RL's HDF5, or an .npz of arrays

ACTION_BOUND = 1.0  # every env in `ENVS` has the action box [-1, 1]
FINITE_FIELDS = ("observations", "actions", "rewards", "next_observations")
D4RL_REQUIRED = ("observations", "actions", "rewards", "terminals")


# ----------------------------------------------------------------------------------------------------- validation
def check_lengths(path, arrays: dict[str, np.ndarray]) -> None:
    """Raise unless every array has the same number of rows (naming each array and its length)."""
    lengths = {k: (np.shape(v) or (1,))[0] for k, v in arrays.items()}
    if len(set(lengths.values())) > 1:
        listed = ", ".join(f"{k}={n}" for k, n in lengths.items())
        raise DatasetError(f"{path}: arrays have different lengths: {listed}")


def _as_float32(path, name: str, x: np.ndarray, ndim: int) -> np.ndarray:
    """Cast to float32 with `ndim` dims; (T, 1) columns are accepted for the (T,) fields."""
    x = np.asarray(x)
    if ndim == 1 and x.ndim == 2 and x.shape[1] == 1:
        x = x[:, 0]
    if x.ndim != ndim:
        raise DatasetError(f"{path}: {name} has shape {x.shape}, expected {ndim} dimension(s)")
    if x.dtype.kind not in "biuf":  # strings, bytes, objects: not numbers, whatever they would parse to
        raise DatasetError(f"{path}: {name} holds {x.dtype} values, not numbers")
    with np.errstate(over="ignore", invalid="ignore"):  # beyond float32's range: inf, refused as non-finite
        return x.astype(np.float32)


def _check_env(path, ds: Dataset, env: str) -> None:
    if env not in ENVS:
        raise DatasetError(f"{path}: unknown env '{env}'; valid: {', '.join(ENVS)}")
    spec = ENVS[env]
    if ds.obs_dim != spec.obs_dim or ds.act_dim != spec.act_dim:
        raise DatasetError(
            f"{path}: obs_dim={ds.obs_dim}, act_dim={ds.act_dim} do not match env '{env}' "
            f"(obs_dim={spec.obs_dim}, act_dim={spec.act_dim})"
        )


def _check_action_bounds(path, actions: np.ndarray, env: str, clip_actions: bool) -> np.ndarray:
    """Actions outside [-1, 1]: an error, or with `clip_actions` clipped in place of the error (with a warning)."""
    outside = int(np.count_nonzero(np.abs(actions) > ACTION_BOUND))
    if outside == 0:
        return actions
    worst = float(np.abs(actions).max())
    if not clip_actions:
        raise DatasetError(
            f"{path}: {outside} action values lie outside env '{env}' bounds [-1, 1] (max |a| = {worst:.4g}); "
            "pass clip_actions=True (CLI: --clip-actions) to clip them"
        )
    warnings.warn(f"{path}: clipped {outside} action values to [-1, 1] (max |a| was {worst:.4g})", stacklevel=3)
    return np.clip(actions, -ACTION_BOUND, ACTION_BOUND)


def validate(ds: Dataset, path, env: str | None = None, clip_actions: bool = False) -> Dataset:
    """Check a freshly read dataset and return it with float32 arrays (actions clipped if asked).

    Checks: equal lengths, non-empty, 2-D observations/actions, finite observations/actions/rewards/
    next_observations, terminals and timeouts exactly 0 or 1, obs/act dims against `ENVS[env]` and actions in
    [-1, 1] (both only when `env` is known).
    """
    arrays = {f: np.asarray(getattr(ds, f)) for f in
              ("observations", "actions", "rewards", "next_observations", "terminals", "timeouts")}
    check_lengths(path, arrays)
    if len(arrays["rewards"]) == 0:
        raise DatasetError(f"{path}: dataset is empty (0 transitions)")
    out = {}
    for name, x in arrays.items():
        out[name] = _as_float32(path, name, x, 2 if name in ("observations", "actions", "next_observations") else 1)
    if out["next_observations"].shape != out["observations"].shape:
        raise DatasetError(f"{path}: next_observations has shape {out['next_observations'].shape}, "
                           f"observations {out['observations'].shape}")
    for name in FINITE_FIELDS:
        bad = int(np.count_nonzero(~np.isfinite(out[name])))
        if bad:
            raise DatasetError(f"{path}: {name} contains {bad} non-finite values (NaN, inf, or beyond float32's "
                               "range of 3.4e38)")
    for name in ("terminals", "timeouts"):  # flags: exactly 0 or 1 (a NaN or a 2 is a broken file, not a flag)
        bad = ~np.isin(out[name], (0.0, 1.0))
        if bad.any():
            raise DatasetError(f"{path}: {name} must be 0 or 1, but {int(bad.sum())} values are not (e.g. "
                               f"{float(out[name][bad][0])})")
    ds = Dataset(**out, env=env, name=ds.name, source=ds.source)
    if env is not None:
        _check_env(path, ds, env)
        ds.actions = _check_action_bounds(path, ds.actions, env, clip_actions)
    return ds


def infer_env(obs_dim: int, act_dim: int, hints: tuple[str, ...] = ()) -> str | None:
    """The env of `ENVS` these dims belong to: the first hint (a name, gym id or path part) whose env has these
    dims, else the only env with these dims, else None (e.g. halfcheetah and walker2d share 17/6)."""
    by_gym_base = {spec.gym_id.split("-v")[0].lower(): name for name, spec in ENVS.items()}
    for hint in hints:
        for token in str(hint).replace("\\", "/").lower().split("/"):
            base = token.split("-v")[0]
            name = by_gym_base.get(base) or (base.split("-")[0] if base.split("-")[0] in ENVS else None)
            if name and (ENVS[name].obs_dim, ENVS[name].act_dim) == (obs_dim, act_dim):
                return name
    matches = [n for n, s in ENVS.items() if (s.obs_dim, s.act_dim) == (obs_dim, act_dim)]
    return matches[0] if len(matches) == 1 else None


def next_within_episode(observations: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """(T, obs_dim) successor of every row: the next row, except at episode ends (`ends` (T,) bool; the last row is
    always an end), where no successor was recorded and the row's own observation is used (see dataset.py)."""
    nxt = np.empty_like(observations)
    nxt[:-1] = observations[1:]
    ends = ends.copy()
    ends[-1] = True
    nxt[ends] = observations[ends]
    return nxt


def _require_file(path: Path) -> None:
    if not path.exists():
        raise DatasetError(f"{path}: no such file")


# ------------------------------------------------------------------------------------------------------ D4RL hdf5
def _read_h5_arrays(path: Path) -> dict[str, np.ndarray]:
    """All top-level datasets of an HDF5 file (groups such as infos/ or metadata/ are skipped)."""
    try:
        with h5py.File(path, "r") as f:
            return {k: f[k][()] for k in f.keys() if isinstance(f[k], h5py.Dataset)}
    except OSError as e:
        raise DatasetError(f"{path}: not a readable HDF5 file ({str(e).splitlines()[0]})") from None


def read_d4rl_hdf5(path, env: str | None = None, clip_actions: bool = False) -> Dataset:
    """A D4RL-layout HDF5 file: observations (T, o), actions (T, a), rewards (T,), terminals (T,), optional timeouts
    (T,) (zeros if absent) and next_observations (T, o) (if absent: the next row within the episode, the row itself at
    an episode end).  `env` None: inferred from the file name and dims when unambiguous."""
    path = Path(path)
    _require_file(path)
    return d4rl_arrays_to_dataset(path, _read_h5_arrays(path), env, clip_actions)


def d4rl_arrays_to_dataset(path: Path, data: dict, env: str | None = None, clip_actions: bool = False) -> Dataset:
    """D4RL's keys (from an HDF5 file or an .npz) as a validated `Dataset`; see `read_d4rl_hdf5`."""
    for key in D4RL_REQUIRED:
        if key not in data:
            raise DatasetError(f"{path}: missing key '{key}' (found: {', '.join(sorted(data)) or 'none'})")
    for key in ("rewards", "terminals", "timeouts"):  # shapes and kinds first: episode ends are computed below
        if key in data:
            data[key] = _as_float32(path, key, data[key], 1)
    for key in ("observations", "actions", "next_observations"):
        if key in data:
            data[key] = _as_float32(path, key, data[key], 2)
    if env is None:
        env = infer_env(data["observations"].shape[1], data["actions"].shape[1], hints=(path.stem,))
    if "timeouts" not in data:
        data["timeouts"] = infer_timeouts(path, np.ravel(data["terminals"]), env)
    check_lengths(path, {k: data[k] for k in (*D4RL_REQUIRED, "timeouts", "next_observations") if k in data})
    if "next_observations" not in data and len(data["rewards"]) > 0:
        ends = (np.ravel(data["terminals"]) != 0) | (np.ravel(data["timeouts"]) != 0)
        data["next_observations"] = next_within_episode(np.asarray(data["observations"]), ends)
        if not ends[-1]:  # the file stops inside an episode and its last step has no successor: mark the cut
            data["timeouts"] = np.asarray(data["timeouts"], np.float32).copy()
            data["timeouts"][-1] = 1.0
    data.setdefault("next_observations", data["observations"])  # empty: validate reports it
    ds = Dataset(**{k: data[k] for k in ("observations", "actions", "rewards", "next_observations", "terminals",
                                         "timeouts")}, name=path.stem, source=str(path))
    return validate(ds, path, env=env, clip_actions=clip_actions)


def infer_timeouts(path, terminals: np.ndarray, env: str | None) -> np.ndarray:
    """Time-outs for a file without a `timeouts` key (D4RL v0/v1 files): a time-out after every `max_episode_steps`
    rows without a terminal, as D4RL's own `get_dataset` users did (CORL's `return_reward_range`).  Without a known
    env there is no time limit to use: all zeros, with a warning that episodes may then run into each other."""
    timeouts = np.zeros(len(terminals), np.float32)
    if env is None:
        warnings.warn(f"{path}: no 'timeouts' key and the env is unknown: episodes end only at terminals", stacklevel=3)
        return timeouts
    limit = ENVS[env].max_episode_steps
    steps = 0
    for i, terminal in enumerate(terminals != 0):
        steps += 1
        if terminal:
            steps = 0
        elif steps == limit:
            timeouts[i], steps = 1.0, 0
    warnings.warn(f"{path}: no 'timeouts' key: inferred {int(timeouts.sum())} time-outs at {env}'s {limit}-step "
                  "limit", stacklevel=3)
    return timeouts


# ------------------------------------------------------------------------------------------------------- Minari
def minari_root() -> Path:
    """Where Minari keeps datasets: $MINARI_DATASETS_PATH, else ~/.minari/datasets."""
    return Path(os.environ.get("MINARI_DATASETS_PATH") or Path.home() / ".minari" / "datasets")


def minari_data_dir(path_or_id) -> Path:
    """The `data/` folder of a Minari dataset given as a directory (the dataset's or its `data/`) or as an id
    ("mujoco/hopper/medium-v0" -> <minari_root()>/mujoco/hopper/medium-v0/data)."""
    path = Path(path_or_id)
    if not path.exists():
        by_id = minari_root() / str(path_or_id)
        if not by_id.is_dir():
            raise DatasetError(f"{path}: no such file, directory or Minari dataset id (looked in {minari_root()})")
        path = by_id
    if not path.is_dir():
        raise DatasetError(f"{path}: not a Minari dataset directory")
    data_dir = path / "data" if (path / "data").is_dir() else path
    if not (data_dir / "metadata.json").is_file():
        raise DatasetError(f"{path}: Minari dataset directory without data/metadata.json")
    if not (data_dir / "main_data.hdf5").is_file():
        raise DatasetError(f"{path}: Minari dataset directory without data/main_data.hdf5")
    return data_dir


def _read_minari_metadata(path: Path, data_dir: Path) -> dict:
    """metadata.json, with its JSON-encoded spaces and env_spec decoded; Box spaces and hdf5 format only."""
    try:
        meta = json.loads((data_dir / "metadata.json").read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise DatasetError(f"{path}: unreadable data/metadata.json ({e})") from None
    if not isinstance(meta, dict):
        raise DatasetError(f"{path}: data/metadata.json is not a JSON object")
    if meta.get("data_format", "hdf5") != "hdf5":
        raise DatasetError(f"{path}: Minari data_format '{meta['data_format']}' is not supported (only hdf5)")
    for key in ("observation_space", "action_space", "env_spec"):
        if isinstance(meta.get(key), str):
            try:
                meta[key] = json.loads(meta[key])
            except json.JSONDecodeError as e:
                raise DatasetError(f"{path}: data/metadata.json: {key} is not valid JSON ({e})") from None
        if meta.get(key) is not None and not isinstance(meta[key], dict):
            raise DatasetError(f"{path}: data/metadata.json: {key} is not an object")
    for key in ("observation_space", "action_space"):
        kind = (meta.get(key) or {}).get("type", "Box")
        if kind != "Box":
            raise DatasetError(f"{path}: {key} is a {kind} space; only Box (flat array) spaces are supported")
    return meta


def _read_minari_episode(path: Path, name: str, group) -> dict[str, np.ndarray]:
    """One `episode_N` group -> per-step arrays (T rows each); observations hold T+1 rows (s_0 .. s_T)."""
    for key in ("observations", "actions", "rewards", "terminations", "truncations"):
        if key not in group:
            raise DatasetError(f"{path}: {name} is missing key '{key}'")
        if not isinstance(group[key], h5py.Dataset):
            raise DatasetError(f"{path}: {name}/{key} is a group (Dict/Tuple space); only Box spaces are supported")
    obs = group["observations"][()]
    steps = {k: group[k][()] for k in ("actions", "rewards", "terminations", "truncations")}
    for key, x in {"observations": obs, **steps}.items():
        if np.ndim(x) == 0:
            raise DatasetError(f"{path}: {name}/{key} is a single value, not one row per step")
    if len(steps["actions"]) == 0:
        raise DatasetError(f"{path}: {name} has length 0 (no steps)")
    check_lengths(f"{path}: {name}", steps)
    if len(obs) != len(steps["actions"]) + 1:
        raise DatasetError(f"{path}: {name} has {len(obs)} observations for {len(steps['actions'])} actions "
                           f"(expected {len(steps['actions']) + 1})")
    for key in ("terminations", "truncations"):  # flags: 0 or 1, and set at the last step only
        x = np.asarray(steps[key])
        with np.errstate(invalid="ignore"):
            ok = x.ndim == 1 and x.dtype.kind in "biuf" and bool(np.isin(x, (0, 1)).all())
        if not ok:
            raise DatasetError(f"{path}: {name}/{key} must be one flag per step, each 0 or 1")
        if x[:-1].any():
            raise DatasetError(f"{path}: {name}/{key} is set at step {int(np.argmax(x[:-1] != 0))} of "
                               f"{len(x)}: a Minari episode ends at its last step only")
    terminals = np.asarray(steps["terminations"], bool)
    timeouts = np.asarray(steps["truncations"], bool).copy()
    timeouts[-1] |= not terminals[-1]  # an episode stored without an end flag was cut: mark the cut
    return dict(observations=obs[:-1], next_observations=obs[1:], actions=steps["actions"],
                rewards=steps["rewards"], terminals=terminals, timeouts=timeouts)


def read_minari(path_or_id, env: str | None = None, clip_actions: bool = False) -> Dataset:
    """A Minari dataset (directory or id) with Box spaces, episodes concatenated in id order.

    Episode `episode_N` has observations (T+1, o) and actions (T, a), rewards/terminations/truncations (T,):
    rows are s_t = observations[:-1], s_{t+1} = observations[1:].  `env` None: inferred from the metadata's env_spec
    id / dataset id when the dims agree, else from the dims alone when unambiguous."""
    data_dir = minari_data_dir(path_or_id)
    path = data_dir.parent if data_dir.name == "data" else data_dir
    meta = _read_minari_metadata(path, data_dir)
    try:
        with h5py.File(data_dir / "main_data.hdf5", "r") as f:
            names = [k for k in f.keys() if k.startswith("episode_")]
            if odd := [k for k in names if not k.split("_", 1)[1].isdigit()]:
                raise DatasetError(f"{path}: data/main_data.hdf5 has a group {odd[0]!r}; Minari names its episode "
                                   "groups episode_0, episode_1, ...")
            names.sort(key=lambda k: int(k.split("_", 1)[1]))
            for k in names:
                if not isinstance(f[k], h5py.Group):
                    raise DatasetError(f"{path}: {k} is not an episode group")
            episodes = [_read_minari_episode(path, k, f[k]) for k in names]
    except OSError as e:
        raise DatasetError(f"{path}: data/main_data.hdf5 is not a readable HDF5 file "
                           f"({str(e).splitlines()[0]})") from None
    if not episodes:
        raise DatasetError(f"{path}: dataset is empty (no episodes)")
    try:
        arrays = {k: np.concatenate([ep[k] for ep in episodes]) for k in episodes[0]}
    except ValueError as e:
        raise DatasetError(f"{path}: episodes have inconsistent shapes ({e})") from None
    ds = Dataset(**arrays, name=str(meta.get("dataset_id") or path.name), source=str(path))
    if env is None and arrays["observations"].ndim == 2 and arrays["actions"].ndim == 2:
        hints = ((meta.get("env_spec") or {}).get("id", ""), str(meta.get("dataset_id", "")), path.name)
        env = infer_env(arrays["observations"].shape[1], arrays["actions"].shape[1], hints)
    return validate(ds, path, env=env, clip_actions=clip_actions)


# ------------------------------------------------------------------------------------------------- Adroit npz
def read_door_npz(path, env: str | None = None, clip_actions: bool | None = None) -> Dataset:
    """Adroit demonstrations as .npz: observations (T, o), actions (T, a), rewards (T,), episode_lengths (E,) with
    sum T, checked against `env` (None: door).  An .npz with D4RL's keys instead (observations, actions, rewards,
    terminals, optional timeouts and next_observations) is read as a D4RL file (`d4rl_arrays_to_dataset`), checked
    against `env`, or with `env` None against the env its dims name when they name one.  The last step of each
    trajectory is a time-out with no recorded successor, so next_observations is the next row within a trajectory
    and the row itself at its end; there are no terminals.

    `clip_actions` None means True for demonstrations and False for an .npz with D4RL's keys.  The door human
    demonstrations (the same transitions as D4RL's door-human) contain ~10k action values slightly beyond [-1, 1]
    (max |a| ~ 1.37), and the Adroit envs clip every action to [-1, 1] before applying it, so clipping changes no
    transition; a warning states how many values were clipped.
    """
    path = Path(path)
    _require_file(path)
    if not zipfile.is_zipfile(path):  # np.load would try it as a pickle and say so
        raise DatasetError(f"{path}: not a .npz file (a .npz is a zip archive of arrays; this file is not one)")
    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except ValueError as e:
        if "pickle" in str(e):
            raise DatasetError(f"{path}: holds object arrays, which are not read (only numeric arrays are)") from None
        raise DatasetError(f"{path}: not a readable .npz file ({e})") from None
    except (OSError, EOFError, zipfile.BadZipFile) as e:
        raise DatasetError(f"{path}: not a readable .npz file ({e or type(e).__name__})") from None
    if "episode_lengths" not in data and all(k in data for k in D4RL_REQUIRED):  # an .npz with D4RL's keys
        return d4rl_arrays_to_dataset(path, data, env, clip_actions=bool(clip_actions))
    found = ', '.join(sorted(data)) or 'none'
    if "episode_lengths" not in data and any(k in data for k in ("terminals", "timeouts", "next_observations")):
        key = next(k for k in D4RL_REQUIRED if k not in data)  # D4RL's keys, one missing: as the .hdf5 reader says
        raise DatasetError(f"{path}: missing key '{key}' (found: {found})")
    for key in ("observations", "actions", "rewards"):
        if key not in data:
            raise DatasetError(f"{path}: missing key '{key}' (found: {found})")
    if "episode_lengths" not in data:
        raise DatasetError(f"{path}: missing key 'episode_lengths' (Adroit's demonstrations) or 'terminals' (D4RL's "
                           f"keys) (found: {found})")
    for key, ndim in (("observations", 2), ("actions", 2), ("rewards", 1)):
        data[key] = _as_float32(path, key, data[key], ndim)
    check_lengths(path, {k: data[k] for k in ("observations", "actions", "rewards")})
    if len(data["rewards"]) == 0:
        raise DatasetError(f"{path}: dataset is empty (0 transitions)")
    raw = np.asarray(data["episode_lengths"]).ravel()
    if raw.dtype.kind not in "iuf":
        raise DatasetError(f"{path}: episode_lengths must be whole numbers of steps, not {raw.dtype}")
    if raw.dtype.kind == "f":
        with np.errstate(invalid="ignore"):
            bad = ~(np.isfinite(raw) & (raw == np.round(raw)) & (np.abs(raw) < 2**62))
        if bad.any():
            raise DatasetError(f"{path}: episode_lengths must be whole numbers of steps "
                               f"({float(raw[bad][0]):g} at index {int(np.argmax(bad))})")
    lengths = raw.astype(np.int64)
    if np.any(lengths <= 0):
        raise DatasetError(f"{path}: episode_lengths has {int(np.sum(lengths <= 0))} episode(s) of length 0 or less "
                           f"(first at index {int(np.argmax(lengths <= 0))})")
    if lengths.sum() != len(data["rewards"]):
        raise DatasetError(f"{path}: episode_lengths sum to {int(lengths.sum())} but there are "
                           f"{len(data['rewards'])} transitions")
    timeouts = np.zeros(len(data["rewards"]), np.float32)
    timeouts[np.cumsum(lengths) - 1] = 1.0
    obs = data["observations"]
    ds = Dataset(obs, data["actions"], data["rewards"], next_within_episode(obs, timeouts > 0),
                 np.zeros_like(timeouts), timeouts, name=path.stem, source=str(path))
    return validate(ds, path, env=env or "door", clip_actions=True if clip_actions is None else clip_actions)


# ------------------------------------------------------------------------------------------------------ dispatch
def load_dataset_path(path, env: str | None = None, clip_actions: bool | None = None) -> Dataset:
    """Read whatever `path` is: a .hdf5/.h5 file (D4RL layout), a .npz (Adroit demonstrations), a Minari dataset
    directory, or a Minari dataset id.  `clip_actions` None: the reader's default (clip only for .npz demos)."""
    p = Path(path)
    kw = {} if clip_actions is None else {"clip_actions": clip_actions}
    if p.is_dir():
        return read_minari(p, env=env, **kw)
    if p.suffix.lower() in (".hdf5", ".h5"):
        return read_d4rl_hdf5(p, env=env, **kw)
    if p.suffix.lower() == ".npz":
        return read_door_npz(p, env=env, **kw)
    if p.exists():
        raise DatasetError(f"{p}: unknown dataset format (expected .hdf5/.h5, .npz or a Minari directory)")
    return read_minari(str(path), env=env, **kw)  # a Minari id, or a clear "no such file" error
