"""Generate D4RL-style MuJoCo datasets on gymnasium v5 (the D4RL recipe), written in Minari's format.

    from offrl_jax.data.generate import generate
    path = generate("hopper-medium")                 # -> cache_dir()/"datasets"/"hopper-medium"
    path = generate("hopper-medium", transitions=2000, out_dir="/tmp/hm")

Levels (D4RL's definitions, our SAC behaviour policies; see docs/datasets.md):
    random          uniform random actions in [-1, 1], 1M transitions
    medium          the shipped medium SAC actor (eval score ~1/3 of expert), stochastic actions, 1M
    expert          the shipped expert SAC actor, stochastic actions, 1M
    medium-expert   medium ++ expert (same seeds, so it is the two datasets concatenated), 2M
    medium-replay   every transition the SAC run saw up to the medium checkpoint's step
    full-replay     every transition of the whole SAC run that produced the expert checkpoint (D4RL: the final replay
                    buffer of a policy trained to completion, 1M steps)

The replay levels read the SAC run directory `cache_dir()/"sac"/<env>-seed<sac_seed>` (the run that produced the
shipped checkpoints, if present); if it is missing it is trained there first (progress bar), up to the needed step.

On disk: `out_dir/data/{main_data.hdf5, metadata.json}` written by `minari.create_dataset_from_buffers` (dataset id
`<name>-v<version>`), plus `out_dir/offrl_jax.json` (env, policy checkpoint, seeds, D4RL reference scores, statistics).
Load with `minari.load_dataset(out_dir.name)` under `MINARI_DATASETS_PATH=out_dir.parent`, or
`MinariDataset(out_dir/"data")`.
"""
from __future__ import annotations

import hashlib
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from offrl_jax.data.dataset import (
    LOCOMOTION_ENVS,
    LOCOMOTION_LEVELS,
    Dataset,
    dataset_dir,
    is_current,
    split_version,
)
from offrl_jax.data.generate.collect import (
    MEDIUM_TARGET_SCORE,
    POLICY_DIR,
    collect,
    load_policy,
    shipped_policies,
    summarize,
)
from offrl_jax.data.generate.reference import D4RL_V2
from offrl_jax.data.generate.write import check_replaceable, write_minari
from offrl_jax.envs.registry import get_env_spec
from offrl_jax.system.cache import cache_dir
from offrl_jax.system.checkpoint import atomic_write_text

GEN_ENVS, LEVELS = LOCOMOTION_ENVS, LOCOMOTION_LEVELS  # the generated locomotion datasets
DATASET_NAMES = tuple(f"{e}-{lvl}" for e in GEN_ENVS for lvl in LEVELS)
DEFAULT_TRANSITIONS = 1_000_000

# D4RL v2 statistics for comparison (transitions, episodes, mean normalised behaviour score), from `reference`.
D4RL_V2_STATS: dict[str, dict[str, float]] = {
    name: {k: ref[k] for k in ("transitions", "episodes", "normalized_score")} for name, ref in D4RL_V2.items()}


def parse_name(name: str) -> tuple[str, str]:
    """"hopper-medium-replay" -> ("hopper", "medium-replay"), "hopper-medium-v0" -> ("hopper", "medium"); raises
    ValueError for unknown names."""
    env, _, level = split_version(name)[0].partition("-")
    if env not in GEN_ENVS or level not in LEVELS:
        raise ValueError(f"unknown dataset '{name}'; valid: {', '.join(DATASET_NAMES)}")
    return env, level


def default_dir(name: str) -> Path:
    """Where `generate(name)` writes by default: cache_dir()/"datasets"/<name>-v<version> (`dataset_dir`)."""
    return dataset_dir(name)


def sac_run_dir(env: str, sac_seed: int = 0) -> Path:
    """The cached SAC training run of an env (its checkpoints and every transition it saw)."""
    return cache_dir() / "sac" / f"{env}-seed{sac_seed}"


def policy_name(env: str, level: str, version: int | None = None) -> str:
    """The shipped policy a dataset version is made from: "<env>-<level>" for the current version of
    <env>-<level>, "<env>-<level>-v<N>" for an earlier one (`DATASET_VERSIONS`)."""
    name = f"{env}-{level}"
    return name if version is None or is_current(f"{name}-v{version}") else f"{name}-v{version}"


def _policy(env: str, level: str, version: int | None = None) -> tuple[Any, dict[str, Any]]:
    name = policy_name(env, level, version)
    if name not in shipped_policies():
        raise FileNotFoundError(
            f"no shipped '{name}' policy in {POLICY_DIR}; train one with `python -m offrl_jax.data.generate.sac "
            f"--env {env} --out DIR` and ship a checkpoint with `python -m offrl_jax.data.generate.ship --run DIR "
            f"--level {level}` (see docs/datasets.md)"
        )
    params, meta = load_policy(name)
    meta["sha256"] = hashlib.sha256(Path(meta["path"]).read_bytes()).hexdigest()
    return params, meta


def _replay(env: str, level: str, n: int | None, progress: bool, run_dir: Path | None) -> tuple[Dataset, dict]:
    from offrl_jax.data.generate import sac
    from offrl_jax.data.generate.replay import load_replay

    policy_level = "medium" if level == "medium-replay" else "expert"
    # the replay levels keep the SAC run and step of the first shipped checkpoints (version 0): a later medium
    # version changes the data rolled out, not where the run that made the first one stopped
    meta = shipped_policies().get(policy_name(env, policy_level, 0))
    if meta is None:
        raise FileNotFoundError(f"{env}-{level} needs the shipped {env}-{policy_level} checkpoint "
                                "to know where to stop")
    sac_seed = int(meta.get("sac_seed", 0))
    # medium-replay stops at the medium checkpoint; full-replay is the whole run (recorded when the expert shipped)
    step = int(meta["sac_step"] if level == "medium-replay" else meta.get("sac_run_steps", meta["sac_step"]))
    run_dir = Path(run_dir) if run_dir is not None else sac_run_dir(env, sac_seed)
    if not (run_dir / "run.json").exists():
        print(f"[generate] no SAC run in {run_dir}: training {env} for {step} steps (seed {sac_seed})")
        sac.train(env, step, run_dir, seed=sac_seed, progress=progress)
    data = load_replay(run_dir, upto=step)
    if n is not None:
        data = {k: v[:n] for k, v in data.items()}
    if data["terminals"][-1] == 0:
        data["timeouts"][-1] = 1.0  # the run goes on past the cut
    source = {"sac_run": str(run_dir), "upto_step": step, "policy_checkpoint": meta["file"]}
    return Dataset(**data, env=env, name=f"{env}-{level}", source="generated"), source


def build(name: str, transitions: int | None = None, seed: int = 0, progress: bool = True, num_envs: int = 16,
          sac_run: str | Path | None = None) -> tuple[Dataset, dict[str, Any]]:
    """The in-memory dataset `name` and the provenance of its data (no writing)."""
    env, level = parse_name(name)
    version = split_version(name)[1]
    n = transitions or DEFAULT_TRANSITIONS
    kw = {"num_envs": num_envs, "progress": progress}
    if level == "random":
        return collect(env, "random", n, seed, name=name, **kw), {"policy": "uniform random"}
    if level in ("medium", "expert"):
        params, meta = _policy(env, level, version)
        ds = collect(env, params, n, seed, stochastic=True, hidden=tuple(meta["hidden"]), name=name, **kw)
        return ds, {"policy": {k: meta[k] for k in meta if k != "path"}, "stochastic": True}
    if level == "medium-expert":
        half = None if transitions is None else transitions // 2
        med, src_m = build(f"{env}-medium-v{version}", half, seed, progress, num_envs)  # same version as medium
        exp, src_e = build(f"{env}-expert", None if transitions is None else transitions - half, seed, progress,
                           num_envs)
        arrays = {f: np.concatenate([getattr(med, f), getattr(exp, f)]) for f in
                  ("observations", "actions", "rewards", "next_observations", "terminals", "timeouts")}
        arrays["timeouts"][len(med) - 1] = max(arrays["timeouts"][len(med) - 1], 1 - arrays["terminals"][len(med) - 1])
        return Dataset(**arrays, env=env, name=name, source="generated"), {"medium": src_m, "expert": src_e}
    return _replay(env, level, transitions, progress, None if sac_run is None else Path(sac_run))


def generate(name: str, transitions: int | None = None, out_dir: str | Path | None = None, seed: int = 0,
             overwrite: bool = False, progress: bool = True, num_envs: int = 16,
             sac_run: str | Path | None = None, demos: Dataset | None = None, shown_as: str | None = None) -> Path:
    """Generate dataset `name` (e.g. "hopper-medium") and write it with minari; returns its directory.

    transitions: cap on the number of rows (default 1M per policy; the replay levels default to the whole run).
    out_dir: the dataset directory (default `dataset_dir(name)`: `cache_dir()/"datasets"/<name>-v<version>`); an
        existing one raises unless overwrite, which replaces only a dataset directory written here
        (`check_replaceable`).
    seed: env / action-noise seed of the rollouts.  sac_run: SAC run directory for the replay levels.
    demos: the human demonstrations door-cloned is made from (`offrl_jax.data.catalogue.load("door-human")`).
    shown_as: what the closing `[generate]` line names as the destination (default: the directory written).
    """
    target = Path(out_dir) if out_dir is not None else default_dir(name)
    if overwrite and target.exists():
        check_replaceable(target)  # before any work
    if name == "door-cloned":
        from offrl_jax.data.generate.door_cloned import generate_door_cloned

        if demos is None:
            raise ValueError("door-cloned is made from the door-human demonstrations: pass demos=")
        return generate_door_cloned(demos, transitions, out_dir, seed, overwrite=overwrite, progress=progress,
                                    shown_as=shown_as)
    env, level = parse_name(name)
    out = Path(out_dir) if out_dir is not None else default_dir(name)
    if out.exists() and not overwrite:
        raise FileExistsError(f"{out} exists; pass overwrite=True to replace it")
    t0 = time.time()
    ds, source = build(name, transitions, seed, progress, num_envs, sac_run)
    t_collect = time.time() - t0
    spec = get_env_spec(env)
    info = {
        "name": name, "env": env, "gym_id": spec.gym_id, "level": level, "seed": seed,
        "transitions_cap": transitions, "source": source,
        "ref_min_score": spec.ref_min_score, "ref_max_score": spec.ref_max_score,
        "stats": summarize(ds), "d4rl_v2": D4RL_V2_STATS.get(name), "collect_s": round(t_collect, 1),
    }
    write_minari(ds, out, info, overwrite=overwrite)
    info["total_s"] = round(time.time() - t0, 1)
    atomic_write_text(out / "offrl_jax.json", json.dumps(info, indent=1))
    if progress:
        st = info["stats"]
        print(f"[generate] {name}: {st['transitions']} transitions, {st['episodes']} episodes, return "
              f"{st['return_mean']:.0f} (norm {st['normalized_score']:.1f}) in {info['total_s']:.0f}s -> "
              f"{shown_as or out}")
    return out


__all__ = ["generate", "check_replaceable", "build", "write_minari", "collect", "load_policy", "shipped_policies",
           "parse_name", "default_dir", "sac_run_dir", "DATASET_NAMES", "LEVELS", "GEN_ENVS", "D4RL_V2_STATS",
           "MEDIUM_TARGET_SCORE", "policy_name"]
