"""Re-compute the Adroit random (min) scores for the paper's longer time limits (Appendix H, Table 4) by running the
independent uniform random policy, and compare with the paper's figures.

    python -m experiments.adroit_random_scores [--episodes 100] [--envs door pen] [--out DIR]

Prints one row per env: time limit, episodes, mean return, its standard error, the paper's value and the difference
in standard errors, and the mean return under the installed env's own reward (gymnasium-robotics >= 1.2.1 changed
the door/hammer/relocate reward; the main columns use D4RL's original, `offrl_jax.envs.adroit`).  With --out, writes
scores.json and table.txt there.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from offrl_jax.app.outputs import refuse_existing
from offrl_jax.envs.registry import ENVS, make_env
from offrl_jax.system.checkpoint import atomic_write_text
from offrl_jax.system.cli import OneLineParser, check_writable_dir, int_at_least, seed_int

OUTPUTS = ("scores.json", "table.txt")  # what --out gets (--overwrite replaces only these)
PAPER_TABLE4 = {"pen": -162.09, "door": -84.52, "hammer": -856.83, "relocate": -37.95}


def random_returns(env_name: str, episodes: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(returns under the reward `make_env` gives, returns under the installed env's own reward), each (episodes,);
    the two are the same for pen."""
    env = make_env(env_name, disable_env_checker=True)
    env.action_space.seed(seed)
    returns, installed = np.zeros(episodes), np.zeros(episodes)
    for i in tqdm(range(episodes), desc=env_name, leave=False, file=sys.stderr):
        env.reset(seed=seed + i)
        done = False
        while not done:
            _, reward, terminated, truncated, info = env.step(env.action_space.sample())
            returns[i] += reward
            installed[i] += info.get("installed_reward", reward)
            done = terminated or truncated
    env.close()
    return returns, installed


def main(argv=None) -> int:
    ap = OneLineParser(prog="experiments.adroit_random_scores", description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--episodes", type=int_at_least(2, 1_000_000), default=100,
                    help="episodes per env (2 to 1e6: 2 for a standard error; default %(default)s)")
    ap.add_argument("--envs", nargs="+", choices=tuple(PAPER_TABLE4), default=list(PAPER_TABLE4),
                    help="Adroit tasks, one row each (default: pen door hammer relocate)")
    ap.add_argument("--seed", type=seed_int, default=0,
                    help="seed of the random actions; episode i resets with seed + i (default %(default)s)")
    ap.add_argument("--out", type=Path, default=None, help="also write scores.json and table.txt here")
    ap.add_argument("--overwrite", action="store_true", help="replace the files of an earlier run in --out")
    args = ap.parse_args(argv)
    refuse_existing(ap, args.out, args.overwrite, OUTPUTS)
    if args.out is not None:
        try:
            check_writable_dir(args.out)
        except OSError as e:
            ap.error(str(e))
    rows = []
    lines = [f"{'env':<9} {'limit':>5} {'episodes':>8} {'mean':>10} {'s.e.':>7} {'paper':>9} {'diff/s.e.':>9} "
             f"{'installed':>10}"]
    print(lines[0])
    for name in args.envs:
        r, installed = random_returns(name, args.episodes, args.seed)
        mean, se = float(r.mean()), float(r.std(ddof=1) / np.sqrt(len(r)))
        row = {"env": name, "time_limit": ENVS[name].max_episode_steps, "episodes": args.episodes, "mean": mean,
               "standard_error": se, "paper": PAPER_TABLE4[name], "diff_in_se": (mean - PAPER_TABLE4[name]) / se,
               "installed_reward_mean": float(installed.mean())}
        rows.append(row)
        lines.append(f"{name:<9} {row['time_limit']:>5} {args.episodes:>8} {mean:>10.2f} {se:>7.2f} "
                     f"{row['paper']:>9.2f} {row['diff_in_se']:>9.1f} {row['installed_reward_mean']:>10.2f}")
        print(lines[-1], flush=True)
    if args.out:
        args.out.mkdir(parents=True, exist_ok=True)
        atomic_write_text(args.out / "scores.json", json.dumps(rows, indent=2))
        atomic_write_text(args.out / "table.txt", "\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    from offrl_jax.system.cli import run_main

    run_main(main)
