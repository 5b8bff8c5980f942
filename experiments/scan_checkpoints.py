"""Which checkpoint of a behaviour-policy SAC run makes a medium dataset like D4RL's: for each checkpoint, a sample
of its stochastic rollouts (the behaviour score) and behaviour cloning on it (`experiments.fidelity`'s BC, without
TD3+BC), one JSON line per checkpoint in `scan.jsonl` (the table in docs/datasets.md was made this way).

    python -m experiments.scan_checkpoints --run ~/.cache/offrl_jax/sac/hopper-seed2 --steps 150000 160000 170000
    python -m experiments.scan_checkpoints --run RUN --steps 170000 --transitions 1000000 --seeds 5 --bc-updates 20000

A screen (the defaults: 200k transitions, 3 seeds, 10k BC updates) takes ~3 minutes per checkpoint on a free core;
confirm a candidate at full size (the second line), then ship it with `python -m offrl_jax.data.generate.ship`.
"""
from __future__ import annotations

import json
from pathlib import Path

from experiments import fidelity
from offrl_jax.data.generate import summarize
from offrl_jax.data.generate.collect import collect, load_policy
from offrl_jax.data.generate.ship import read_run
from offrl_jax.data.generate.write import write_minari
from offrl_jax.system.cli import OneLineParser, UsageError, check_writable_dir, positive_int, print_error


def make_parser() -> OneLineParser:
    p = OneLineParser(prog="experiments.scan_checkpoints", description=__doc__)
    p.add_argument("--run", type=Path, required=True, help="SAC run directory (its checkpoints/actor_<step>.msgpack)")
    p.add_argument("--steps", type=positive_int, nargs="+", required=True, help="checkpoint steps to score")
    p.add_argument("--transitions", type=positive_int, default=200_000,
                   help="rollout sample size (default %(default)s)")
    p.add_argument("--seeds", type=positive_int, default=3, help="BC seeds (default %(default)s)")
    p.add_argument("--bc-updates", type=positive_int, default=10_000, help="BC updates (default %(default)s)")
    p.add_argument("--out", type=Path, default=Path("runs/scan"), help="where samples and BC runs go (default "
                   "%(default)s); scan.jsonl there gets one line per checkpoint")
    return p


def main(argv=None) -> int:
    args = make_parser().parse_args(argv)
    try:
        return scan(args)
    except (OSError, ValueError) as e:  # a run, checkpoint or --out that is not what it should be: one line
        print_error(e)
        return 2


def actors(run: Path, steps: list[int]) -> dict[int, tuple[Path, dict, dict]]:
    """{step: (path, params, meta)} of the run's actor checkpoints at `steps`, every one read before anything is
    written; one line (UsageError) for a step given twice, missing or unreadable."""
    if len(set(steps)) != len(steps):
        raise UsageError(f"--steps {' '.join(map(str, steps))}: a step is given twice")
    paths = {s: run / "checkpoints" / f"actor_{s:07d}.msgpack" for s in steps}
    missing = [str(s) for s, path in paths.items() if not path.is_file()]
    if missing:
        raise UsageError(f"{run}: no checkpoint at step {', '.join(missing)}")
    found = {}
    for step, path in paths.items():
        try:
            found[step] = (path, *load_policy(path))
        except Exception as e:  # noqa: BLE001 -- whatever a foreign or cut file raises, one line
            raise UsageError(f"{path}: not an actor checkpoint of a SAC run ({type(e).__name__})") from None
    return found


def scan(args) -> int:
    check_writable_dir(args.out)
    env = read_run(args.run)["env"]
    found = actors(args.run, args.steps)
    args.out.mkdir(parents=True, exist_ok=True)
    for step, (path, params, meta) in found.items():
        tag = f"{env}-{step}-n{args.transitions}"
        data = args.out / f"{tag}-data"
        if not data.exists():
            ds = collect(env, params, args.transitions, 0, stochastic=True, hidden=tuple(meta["hidden"]),
                         name=f"{env}-medium")
            write_minari(ds, data, {"name": f"{env}-medium", "env": env, "checkpoint": str(path),
                                    "stats": summarize(ds)})
        run = args.out / f"{tag}-bc-s{args.seeds}-u{args.bc_updates}"
        if not (run / "fidelity.json").exists():
            rc = fidelity.main(["--env", env, "--dataset-path", str(data), "--td3bc-updates", "0", "--seeds",
                                str(args.seeds), "--bc-updates", str(args.bc_updates), "--eval-episodes", "5",
                                "--out", str(run), "--no-progress", "--parallel", "1"])
            if rc:
                return rc
        rows = {r["measure"].split(",")[0]: r for r in json.loads((run / "fidelity.json").read_text())["rows"]}
        line = {"step": step, "transitions": args.transitions, "behaviour": round(rows["behaviour data"]["ours"], 1),
                "bc": round(rows["BC"]["ours"], 1), "bc_low": rows["BC"]["low"], "bc_high": rows["BC"]["high"]}
        with open(args.out / "scan.jsonl", "a") as f:
            f.write(json.dumps(line) + "\n")
        print(json.dumps(line), flush=True)
    return 0


if __name__ == "__main__":
    from offrl_jax.system.cli import run_main

    run_main(main)
