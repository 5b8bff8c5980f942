"""Peak memory (RSS) of training on a 1M-transition dataset with S seeds (the member axis): the dataset lives once,
not per seed.

    python -m benchmarks.memory [--algos td3bc edac] [--seeds 1 8] [--transitions 1000000] [--json] [--out NAME]

Each (algorithm, S) runs in a fresh subprocess: build a synthetic hopper-shaped dataset of `--transitions` rows, put it
on the device (`offrl_jax.data.device`), initialise S seeds with the real `Driver`, and run 20 updates of every phase
(EDAC's soft-return computation over the whole dataset included); the child reports its peak resident set size
(`ru_maxrss`) and the bytes of the device arrays it holds.
The dataset (obs, next obs, actions, rewards, flags, returns: 111 MB at 1M hopper rows in float32) is passed to the
chunk function with `in_axes=None`, so S seeds share one copy; what grows with S is the agent state (parameters, Adam
moments, targets: ~3 MB per TD3+BC seed) and, for EDAC, each seed's own soft returns (4 bytes per transition).
"""
from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys

from offrl_jax.system.cli import OneLineParser, positive_int


def child(algo: str, seeds: int, transitions: int) -> dict:
    import jax
    import numpy as np

    from benchmarks.common import synthetic_data
    from offrl_jax.algos import make_algorithm, make_config
    from offrl_jax.driver import Driver

    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    data = synthetic_data(transitions)
    overrides = {"num_critics": 10, "pretrain_updates": 40} if algo.startswith("edac") else {"pretrain_updates": 20}
    config = make_config(algo, "hopper", **overrides)
    alg = make_algorithm(config, 11, 3, transitions)
    driver = Driver(alg, data, tuple(range(seeds)), batch_size=256)
    for chunk in driver.run(alg.phases(60), 20):
        jax.block_until_ready(chunk.states)
    data_bytes = sum(x.nbytes for x in jax.tree.leaves(driver.data))
    state_bytes = sum(x.nbytes for x in jax.tree.leaves(chunk.states))
    return {"algo": algo, "seeds": seeds, "transitions": transitions,
            "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
            "baseline_rss_mb": round(before / 1024, 1), "dataset_mb": round(data_bytes / 2**20, 1),
            "state_mb_all_seeds": round(state_bytes / 2**20, 2), "finite": bool(np.all(chunk.metrics["finite"]))}


def main(argv=None) -> int:
    p = OneLineParser(prog="benchmarks.memory", description=__doc__,
                      formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--algos", nargs="+", default=["td3bc", "edac"], choices=["td3bc", "edac", "td3bc_cql", "edac_bc"],
                   help="algorithms to measure, one case per seed count each (default: td3bc edac)")
    p.add_argument("--seeds", nargs="+", type=positive_int, default=[1, 8], help="seed counts (default 1 8)")
    p.add_argument("--transitions", type=positive_int, default=1_000_000, help="rows of the synthetic dataset")
    p.add_argument("--json", action="store_true", help="one JSON object per case on stdout")
    p.add_argument("--out", default=None,
                   help="also append the JSON lines to results/benchmarks/OUT.jsonl (or OUT if a path)")
    p.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.child:
        print(json.dumps(child(args.child[0], int(args.child[1]), int(args.child[2]))))
        return 0
    out_path = None
    if args.out is not None:
        from benchmarks.common import results_path

        out_path = results_path(p, args.out)  # checked before the work
    rows = []
    for algo in args.algos:
        for s in args.seeds:
            print(f"[memory] {algo}, {s} seed(s), {args.transitions:,} transitions ...", file=sys.stderr)
            out = subprocess.run([sys.executable, "-m", "benchmarks.memory", "--child", algo, str(s),
                                  str(args.transitions)], capture_output=True, text=True)
            if out.returncode != 0:
                print(f"error: {algo} with {s} seeds failed: {out.stderr.strip().splitlines()[-1:]}", file=sys.stderr)
                return 1
            rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
            r = rows[-1]
            if not args.json:
                print(f"{algo:8s} S={s:<3d} peak RSS {r['peak_rss_mb']:8.1f} MB   "
                      f"dataset on device {r['dataset_mb']:6.1f} MB (once)   "
                      f"agent states {r['state_mb_all_seeds']:7.2f} MB (all seeds)")
    if args.json:
        for r in rows:
            print(json.dumps(r))
    if out_path is not None:
        from benchmarks.common import append_results

        cmd = "python -m benchmarks.memory " + " ".join(sys.argv[1:] if argv is None else argv)
        append_results(out_path, [{"meta": {"command": cmd}}, *rows])
        print(f"appended to {out_path}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    from offrl_jax.system.cli import run_main

    run_main(main)
