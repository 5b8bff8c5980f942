"""The dataset catalogue: datasets by name or path, and its command (`offrl_jax/data/__main__.py`).

    python -m offrl_jax.data list                      # known names, and which are cached
    python -m offrl_jax.data info door-human           # one JSON object: transitions, episodes, dims, scores
    python -m offrl_jax.data info path/to/file.hdf5    # any D4RL HDF5, Minari directory/id or Adroit .npz
    python -m offrl_jax.data generate hopper-medium --transitions 100000

Generated names ("hopper-medium", ...) live as Minari-format directories in `cache_dir()/"datasets"/<name>` and are
generated on first use; "door-human" is the 25 human demonstrations shipped with the package (DAPG, Apache-2.0;
`offrl_jax/data/adroit/README.md`), or the copy in `$OFFRL_JAX_SHARED` when that is set.  Errors exit with status 2
and one line "error: ..." on stderr.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import tempfile
import warnings
from pathlib import Path

from offrl_jax.data.dataset import (
    DATASET_VERSIONS,
    LOCOMOTION_ENVS,
    LOCOMOTION_LEVELS,
    Dataset,
    DatasetError,
    dataset_dir,
    is_current,
    split_version,
)
from offrl_jax.data.readers import FILE_SUFFIXES, load_dataset_path, minari_root, read_door_npz, read_minari
from offrl_jax.envs.registry import get_env_spec, normalized_score
from offrl_jax.system.cli import (
    OneLineParser,
    check_writable_dir,
    one_line_warnings,
    positive_int,
    print_error,
    seed_int,
)

_LOCOMOTION_KINDS = {
    "medium": "a policy at about 1/3 of expert return",
    "medium-replay": "the replay buffer of training up to the medium policy",
    "full-replay": "the whole replay buffer of the SAC run that trained the expert policy",
    "medium-expert": "medium and expert halves concatenated",
    "expert": "the expert policy",
    "random": "uniformly random actions",
}
KNOWN: dict[str, str] = {
    **{f"{env}-{level}": f"generated: {env}, {_LOCOMOTION_KINDS[level]}" for env in LOCOMOTION_ENVS
       for level in LOCOMOTION_LEVELS},
    "door-human": "shipped: 25 human demonstrations of Adroit door (6,729 transitions; DAPG, Apache-2.0)",
    "door-cloned": "generated: Adroit door, a behaviour-cloned policy mixed with the human demonstrations",
}
# the earlier versions of generated datasets whose making changed, each by its Minari id (docs/datasets.md)
KNOWN |= {f"{name}-v{v}": f"{KNOWN[name]}; version {v}, made before version {current}"
          for name, current in DATASET_VERSIONS.items() for v in range(current)}
SHARED_NAMES = {"door-human": Path("data/adroit/door-human-demos.npz")}


def shared_dir() -> Path:
    """The shared data folder: $OFFRL_JAX_SHARED, else `shared/` beside the repository root (found from this file,
    or from the working directory when the package is installed elsewhere)."""
    if os.environ.get("OFFRL_JAX_SHARED"):
        return Path(os.environ["OFFRL_JAX_SHARED"])
    beside_repo = Path(__file__).resolve().parents[3] / "shared"
    beside_cwd = Path.cwd().resolve().parent / "shared"
    return beside_repo if beside_repo.is_dir() or not beside_cwd.is_dir() else beside_cwd


PACKAGED = Path(__file__).resolve().parent / "adroit" / "door-human-demos.npz"


def door_human_path() -> Path:
    """The door-human demonstrations: `$OFFRL_JAX_SHARED`'s copy when that is set, else the package's own
    (`offrl_jax/data/adroit/`, DAPG, Apache-2.0; README there)."""
    if os.environ.get("OFFRL_JAX_SHARED"):
        return shared_dir() / SHARED_NAMES["door-human"]
    return PACKAGED


def cached_path(name: str) -> Path:
    """Where a generated dataset is cached (a Minari dataset directory, `<cache>/datasets/<name>-v0`)."""
    return dataset_dir(name)


def is_cached(name: str) -> bool:
    path = cached_path(name)
    return (path / "data" / "metadata.json").is_file() or (path / "metadata.json").is_file()


def _unknown(name_or_path) -> DatasetError:
    return DatasetError(f"{name_or_path}: unknown dataset name and no such file; known names: {', '.join(KNOWN)}")


def generate(name: str, *, transitions: int | None = None, out_dir=None, seed: int = 0,
             overwrite: bool = False, shown_as: str | None = None) -> Path:
    """Generate a known dataset with `offrl_jax.data.generate` and return its Minari directory (an existing one is
    refused unless `overwrite`)."""
    if name not in KNOWN or name in SHARED_NAMES:
        generated = [n for n in KNOWN if n not in SHARED_NAMES]
        raise DatasetError(f"{name}: not a generated dataset; generated names: {', '.join(generated)}")
    try:
        from offrl_jax.data.generate import generate as _generate
    except ImportError as e:
        raise DatasetError(f"{name}: the dataset generator is not available ({e})") from None
    kw = ({"overwrite": True} if overwrite else {}) | ({"shown_as": shown_as} if shown_as else {})
    if name == "door-cloned":  # made from the human demonstrations, which the catalogue hands over
        kw["demos"] = load("door-human")
    return Path(_generate(name, transitions=transitions, out_dir=out_dir, seed=seed, **kw))


def _generation_cap(path: Path) -> int | None:
    """The `generate --transitions` cap a cached dataset was made with (None: full size, or not recorded)."""
    try:
        return json.loads((Path(path) / "offrl_jax.json").read_text()).get("transitions_cap")
    except (OSError, ValueError):
        return None


def _load_generated(name: str, max_transitions, clip_actions, generate_if_missing: bool) -> Dataset:
    """A generated dataset from the cache (generated in full first if missing).  With `max_transitions` and no cached
    copy, only that many transitions are generated, into a temporary directory that is deleted after reading: a
    capped run never writes the cache, so the name always stands for the full dataset."""
    path = cached_path(name)
    kw = {} if clip_actions is None else {"clip_actions": clip_actions}
    if not is_cached(name):
        if not generate_if_missing:
            raise DatasetError(f"{path}: '{name}' is not generated yet; run: python -m offrl_jax.data generate "
                               f"{name}")
        if max_transitions is not None:
            print(f"{name} is not cached: generating only the {max_transitions:,} transitions this run uses, not "
                  f"cached (python -m offrl_jax.data generate {name} caches the full dataset)", file=sys.stderr)
            with tempfile.TemporaryDirectory(prefix=f"offrl-{name}-") as tmp:
                made = generate(name, transitions=max_transitions, out_dir=Path(tmp) / name,
                                shown_as="memory, for this run only (not cached)")
                ds = read_minari(made, env=get_env_spec(name).name, **kw)
            return dataclasses.replace(ds, name=name)
        path = generate(name)
    ds = read_minari(path, env=get_env_spec(name).name, **kw)
    if _generation_cap(path) is not None:  # cached capped by `datasets generate --transitions`
        warnings.warn(f"{path}: cached '{name}' was generated capped at {_generation_cap(path):,} transitions "
                      "(datasets generate --transitions), not at full size; delete the directory to generate it in "
                      "full", stacklevel=3)
    return dataclasses.replace(ds, name=name)


def check_there(name_or_path) -> None:
    """Raise DatasetError (what `load` would) unless `name_or_path` is a known dataset, an existing file or folder,
    or a Minari id in `minari_root()`; nothing is read (`--dry-run`'s check of the data it names)."""
    name = str(name_or_path)
    if name in SHARED_NAMES or name in KNOWN or split_version(name)[0] in KNOWN or Path(name).exists():
        return
    if (minari_root() / name).is_dir():
        return
    looks_like_path = Path(name).suffix.lower() in FILE_SUFFIXES or "/" in name
    if not looks_like_path:
        raise _unknown(name)
    raise DatasetError(f"{name}: no such file, directory or Minari dataset id (looked in {minari_root()})")


def load(name_or_path, *, max_transitions: int | None = None, clip_actions: bool | None = None,
         generate_if_missing: bool = True, env: str | None = None) -> Dataset:
    """A validated `Dataset` from a known name (see `KNOWN`) or a path / Minari id (see `load_dataset_path`).

    max_transitions: use only the first N transitions; a generated name that is not cached is then generated at
      that size for this call only, never into the cache.
    clip_actions: clip out-of-range actions with a warning instead of failing; None: the reader's default (True
      for the door human demonstrations, whose out-of-range values the env clips anyway; False otherwise).
    env: the env the data must fit (a file's observation/action dims and action bounds are checked against it).
    """
    name = str(name_or_path)
    if not name.strip():
        raise DatasetError(f"{name_or_path!r}: expected a dataset name or path, got an empty string")
    base = split_version(name)[0]
    if base != name and base in KNOWN and is_current(name) and not (minari_root() / name).is_dir() \
            and not Path(name).exists():
        name = base  # the Minari id of a generated dataset's current version (its cache directory's name)
    if max_transitions is not None and max_transitions <= 0:
        raise DatasetError(f"max_transitions = {max_transitions} must be positive")
    if name in SHARED_NAMES:
        kw = {} if clip_actions is None else {"clip_actions": clip_actions}
        ds = dataclasses.replace(read_door_npz(door_human_path(), **kw), name=name)
    elif name in KNOWN:
        ds = _load_generated(name, max_transitions, clip_actions, generate_if_missing)
    else:
        looks_like_path = (Path(name).exists() or Path(name).suffix.lower() in FILE_SUFFIXES
                           or "/" in name or (minari_root() / name).is_dir())
        if not looks_like_path:
            raise _unknown(name)
        ds = load_dataset_path(name, env=env, clip_actions=clip_actions)
    if max_transitions is None or len(ds) <= max_transitions:
        return ds
    # a generated dataset's first N rows are what generating N transitions gives (its cut episode a time-out), so a
    # run on them reads the same data before and after the full dataset is cached; other data is cut as it is
    return ds.first(max_transitions) if name in KNOWN else ds.select(slice(0, max_transitions))


def summary(ds: Dataset) -> dict:
    """Size, dims and mean episode return (normalised when the env is known) of a dataset, JSON-ready."""
    returns = ds.episode_returns()
    mean_return = float(returns.mean())
    return {
        "name": ds.name,
        "env": ds.env,
        "source": ds.source,
        "transitions": len(ds),
        "episodes": int(len(returns)),
        "obs_dim": ds.obs_dim,
        "act_dim": ds.act_dim,
        "terminals": int(ds.terminals.sum()),
        "timeouts": int(ds.timeouts.sum()),
        "mean_episode_return": mean_return,
        "normalized_score": float(normalized_score(ds.env, mean_return)) if ds.env else None,
    }


# ------------------------------------------------------------------------------------------------------------ CLI
def _parser() -> argparse.ArgumentParser:
    parser = OneLineParser(prog="python -m offrl_jax.data",
                           description="Offline RL datasets: list, inspect, generate.")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=OneLineParser)
    sub.add_parser("list", help="known dataset names and which are cached")
    info = sub.add_parser("info", help="one JSON line describing a dataset (name, file, directory or Minari id)")
    info.add_argument("dataset", help="a known name (hopper-medium, door-human, ...), a D4RL .hdf5 file, a Minari "
                      "dataset directory or id, or the door .npz")
    info.add_argument("--clip-actions", action="store_true", default=None, help="clip actions outside [-1, 1]")
    gen = sub.add_parser("generate", help="generate a known dataset into the cache (or --out)")
    gen.add_argument("name", help="a generated name from `list` (e.g. hopper-medium, walker2d-expert, door-cloned)")
    gen.add_argument("--transitions", type=positive_int, default=None,
                     help="cap on the number of transitions (default: 1M per policy; the whole run for replay "
                          "levels); a capped dataset in the cache is reported as such whenever it is loaded")
    gen.add_argument("--out", type=Path, default=None, help="dataset directory (default: the cache, see `list`)")
    gen.add_argument("--seed", type=seed_int, default=0, help="seed of the rollouts (envs and action noise)")
    gen.add_argument("--overwrite", action="store_true",
                     help="replace a dataset already generated there (only a directory `generate` wrote)")
    return parser


def _list() -> None:
    print(f"cache: {cached_path('x').parent}  ($OFFRL_JAX_CACHE or $XDG_CACHE_HOME move it)")
    for name, text in KNOWN.items():
        if name in SHARED_NAMES:
            where = door_human_path()
            state = f"shipped {where}" if where.is_file() else f"missing {where}"
        else:
            state = f"cached  {cached_path(name)}" if is_cached(name) else "not cached"
        print(f"{name:26s} {state:60s} {text}")


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    one_line_warnings()
    try:
        if args.command == "list":
            _list()
        elif args.command == "info":
            ds = load(args.dataset, clip_actions=args.clip_actions, generate_if_missing=False)
            print(json.dumps(summary(ds)))
        else:
            target = Path(args.out) if args.out is not None else cached_path(args.name)
            if args.name in KNOWN and args.name not in SHARED_NAMES:
                if target.exists() and not target.is_dir():
                    raise DatasetError(f"{target} is a file, not a dataset directory")
                if target.exists() and not args.overwrite:
                    raise DatasetError(f"{target} exists; pass --overwrite to generate '{args.name}' again")
                check_writable_dir(target.parent)
            print(generate(args.name, transitions=args.transitions, out_dir=args.out, seed=args.seed,
                           overwrite=args.overwrite))
    except (DatasetError, ValueError, OSError) as e:
        print_error(e)
        return 2
    return 0

