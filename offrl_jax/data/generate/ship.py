"""Choosing a behaviour policy from a SAC run and shipping it in `offrl_jax/data/policies/`.

    python -m offrl_jax.data.generate.ship --run ~/.cache/offrl_jax/sac/hopper-seed0 --level medium [--step N]

medium: the checkpoint whose (5-episode, deterministic) eval normalised score during training is closest to D4RL's
medium behaviour score (`MEDIUM_TARGET_SCORE`).  expert: the `--candidates` checkpoints with the best training eval
return are re-evaluated with `--episodes` *stochastic* episodes each, and the best of those is shipped (a 5-episode
deterministic eval overrates some checkpoints: hopper's best three scored 72-86 stochastically).  The chosen actor is
re-evaluated with more episodes, deterministic and stochastic (the stochastic score is what the dataset will show),
copied to `policies/<env>-<level>.msgpack` and described in `policies/policies.json`.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from offrl_jax.data.generate.collect import MEDIUM_TARGET_SCORE, POLICY_DIR, POLICY_INDEX, evaluate, load_policy
from offrl_jax.envs.registry import get_env_spec, normalized_score
from offrl_jax.system.checkpoint import atomic_write_bytes, atomic_write_text
from offrl_jax.system.cli import OneLineParser, check_writable_dir, positive_int


def read_run(run_dir: str | Path) -> dict[str, Any]:
    """run.json of a SAC run; FileNotFoundError or ValueError (one line) for a directory that is not one."""
    path = Path(run_dir) / "run.json"
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file (--run takes a SAC run directory)")
    try:
        run = json.loads(path.read_text())
        if not (isinstance(run, dict) and isinstance(run.get("env"), str) and isinstance(run.get("seed"), int)
                and "gym_id" in run):
            raise ValueError("it needs env, gym_id and seed")
        get_env_spec(run["env"])
    except ValueError as e:
        raise ValueError(f"{path}: not the run.json of a SAC run ({e})") from None
    return run


def read_log(run_dir: str | Path) -> list[dict[str, Any]]:
    """The evaluations in log.jsonl; FileNotFoundError or ValueError (one line) for a missing or damaged log."""
    path = Path(run_dir) / "log.jsonl"
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file (--run takes a SAC run directory)")
    log = []
    for i, line in enumerate(path.read_text().splitlines(), 1):
        if not line.strip():
            continue
        try:
            e = json.loads(line)
            ok = (isinstance(e["step"], int) and isinstance(e["checkpoint"], str)
                  and all(isinstance(e[k], (int, float)) for k in ("eval_return", "normalized_score")))
        except (ValueError, KeyError, TypeError):
            ok = False
        if not ok:
            raise ValueError(f"{path}, line {i}: not an evaluation of a SAC run")
        log.append(e)
    return log


def check_checkpoint(path: Path, env: str) -> None:
    """Raise ValueError (one line) unless `path` holds an actor for `env`."""
    spec = get_env_spec(env)
    try:
        _, meta = load_policy(path)
    except (OSError, ValueError, KeyError, TypeError, AttributeError, IndexError) as e:
        raise ValueError(f"{path}: not an actor checkpoint ({type(e).__name__}: {e})") from None
    if (meta["obs_dim"], meta["act_dim"]) != (spec.obs_dim, spec.act_dim):
        raise ValueError(f"{path}: an actor for {meta['obs_dim']} observations and {meta['act_dim']} actions, not "
                         f"{env}'s {spec.obs_dim} and {spec.act_dim}")


def evaluated_checkpoints(run_dir: str | Path) -> list[dict[str, Any]]:
    """The log entries of a run whose checkpoint file exists."""
    log = [e for e in read_log(run_dir) if (Path(run_dir) / e["checkpoint"]).exists()]
    if not log:
        raise FileNotFoundError(f"no evaluated checkpoints in {run_dir}")
    return log


def select_medium(run_dir: str | Path, env: str) -> dict[str, Any]:
    """The log entry whose training eval normalised score is closest to D4RL's medium level for `env`."""
    return min(evaluated_checkpoints(run_dir), key=lambda e: abs(e["normalized_score"] - MEDIUM_TARGET_SCORE[env]))


def expert_candidates(run_dir: str | Path, candidates: int = 5) -> list[dict[str, Any]]:
    """The `candidates` log entries with the best training eval return, best first."""
    return sorted(evaluated_checkpoints(run_dir), key=lambda e: e["eval_return"], reverse=True)[:candidates]


def rank_expert_candidates(run_dir: str | Path, env: str, candidates: int = 5, episodes: int = 20,
                           seed: int = 321) -> list[dict[str, Any]]:
    """The `candidates` log entries with the best training eval return, each with "stochastic_return" (mean of
    `episodes` stochastic episodes) added, best stochastic return first."""
    ranked = []
    for e in expert_candidates(run_dir, candidates):
        params, meta = load_policy(Path(run_dir) / e["checkpoint"])
        sto = evaluate(env, params, episodes, seed=seed, deterministic=False, hidden=tuple(meta["hidden"]),
                       num_envs=10)
        ranked.append({**e, "stochastic_return": float(sto.mean())})
    return sorted(ranked, key=lambda e: e["stochastic_return"], reverse=True)


def ship(run_dir: str | Path, level: str, step: int | None = None, episodes: int = 20, seed: int = 123,
         dest: Path = POLICY_DIR, note: str | None = None, candidates: int = 5) -> dict[str, Any]:
    """Copy the chosen checkpoint of `run_dir` to `dest/<env>-<level>.msgpack` and record it in policies.json."""
    run_dir = Path(run_dir)
    run = read_run(run_dir)
    env = run["env"]
    index_path = dest / POLICY_INDEX.name
    index = json.loads(index_path.read_text()) if index_path.exists() else {}
    if step is None and level == "expert":
        ranked = rank_expert_candidates(run_dir, env, candidates, episodes)
        entry = ranked[0]
        selection = (f"best stochastic return ({episodes} episodes) of the {len(ranked)} checkpoints with the best "
                     "train-eval return: " + ", ".join(f"{e['step'] // 1000}k {e['stochastic_return']:.0f}"
                                                       for e in ranked))
    elif step is None:
        entry = select_medium(run_dir, env)
        selection = f"closest train-eval score to D4RL medium target {MEDIUM_TARGET_SCORE[env]}"
    else:
        entry = next((e for e in evaluated_checkpoints(run_dir) if e["step"] == step), None)
        if entry is None:
            raise ValueError(f"{run_dir} has no evaluated checkpoint at step {step}")
        selection = "chosen by hand"
    src = run_dir / entry["checkpoint"]
    params, meta = load_policy(src)
    hidden = tuple(meta["hidden"])
    # verified on other seeds than the expert ranking's (321): the winner's ranking score is biased upwards
    det = evaluate(env, params, episodes, seed=seed, deterministic=True, hidden=hidden, num_envs=10)
    sto = evaluate(env, params, episodes, seed=seed, deterministic=False, hidden=hidden, num_envs=10)
    name = f"{env}-{level}"
    atomic_write_bytes(dest / f"{name}.msgpack", src.read_bytes())
    record = {
        "file": f"{name}.msgpack", "env": env, "gym_id": run["gym_id"], "level": level,
        "sac_step": int(entry["step"]), "sac_seed": int(run["seed"]),
        "sac_run_steps": int(run.get("steps_done", entry["step"])),  # full-replay takes the whole run
        "obs_dim": meta["obs_dim"], "act_dim": meta["act_dim"], "hidden": list(hidden), "layer_norm": False,
        "train_eval_return": round(float(entry["eval_return"]), 1),
        "train_eval_normalized_score": round(float(entry["normalized_score"]), 2),
        "verify_episodes": episodes,
        "deterministic_return": round(float(det.mean()), 1),
        "deterministic_normalized_score": round(float(normalized_score(env, det.mean())), 2),
        "stochastic_return": round(float(sto.mean()), 1),
        "stochastic_return_std": round(float(sto.std()), 1),
        "stochastic_normalized_score": round(float(normalized_score(env, sto.mean())), 2),
        "selection": selection + (f"; {note}" if note else ""),
        "size_bytes": (dest / f"{name}.msgpack").stat().st_size,
    }
    index[name] = record
    atomic_write_text(index_path, json.dumps(dict(sorted(index.items())), indent=1) + "\n")
    return record


def main(argv: list[str] | None = None) -> int:
    p = OneLineParser(prog="offrl_jax.data.generate.ship", description=__doc__,
                      formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--run", type=Path, required=True, help="SAC run directory")
    p.add_argument("--level", required=True, choices=["medium", "expert"],
                   help="which behaviour policy to choose and ship (the rules above)")
    p.add_argument("--step", type=positive_int, default=None,
                   help="ship this checkpoint instead of the automatic choice")
    p.add_argument("--episodes", type=positive_int, default=20, help="verification episodes")
    p.add_argument("--candidates", type=positive_int, default=5,
                   help="expert: how many of the best train-eval checkpoints to re-evaluate stochastically")
    p.add_argument("--note", default=None, help="why this checkpoint (recorded in policies.json)")
    p.add_argument("--list", action="store_true", help="only print the run's evaluations and the automatic choice")
    p.add_argument("--overwrite", action="store_true", help="replace a policy already shipped for this env and level")
    a = p.parse_args(argv)
    try:
        run = read_run(a.run)
        env = run["env"]
        log = evaluated_checkpoints(a.run)
        if a.level == "medium" and a.step is None and env not in MEDIUM_TARGET_SCORE:
            raise ValueError(f"no medium target score for {env} (there is one for {', '.join(MEDIUM_TARGET_SCORE)}); "
                             "choose the checkpoint with --step")
        if a.list:
            for e in read_log(a.run):
                print(f"{e['step']:>8d}  eval {e['eval_return']:8.1f}  norm {e['normalized_score']:6.1f}  "
                      f"returns {np.round(e.get('eval_returns', [])).astype(int).tolist()}")
            if a.level == "expert":  # the choice needs the stochastic re-evaluation that `ship` runs
                print("candidates (ship re-evaluates them stochastically):",
                      [e["step"] for e in expert_candidates(a.run, a.candidates)])
            else:
                print("choice:", select_medium(a.run, env)["step"])
            return 0
        if a.step is not None:
            chosen = [e for e in log if e["step"] == a.step]
            if not chosen:
                raise ValueError(f"--step {a.step}: {a.run} has no evaluated checkpoint there (its {len(log)} are at "
                                 f"steps {log[0]['step']} to {log[-1]['step']}; --list shows them)")
        else:
            chosen = expert_candidates(a.run, a.candidates) if a.level == "expert" else [select_medium(a.run, env)]
        for e in chosen:
            check_checkpoint(a.run / e["checkpoint"], env)
        target = POLICY_DIR / f"{env}-{a.level}.msgpack"
        if target.exists() and not a.overwrite:
            raise ValueError(f"{target} is already shipped; pass --overwrite to replace it")
        check_writable_dir(POLICY_DIR)
        index = POLICY_DIR / POLICY_INDEX.name
        try:
            if index.exists():
                json.loads(index.read_text())
        except ValueError as e:
            raise ValueError(f"{index}: not readable ({e})") from None
    except (OSError, ValueError) as e:
        p.error(str(e))
    print(json.dumps(ship(a.run, a.level, a.step, a.episodes, dest=POLICY_DIR, note=a.note, candidates=a.candidates),
                     indent=1))
    return 0


if __name__ == "__main__":
    from offrl_jax.system.cli import run_main

    run_main(main)
