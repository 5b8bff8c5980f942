"""One variant of S seeds on both cores: how its updates per second scale with S, on 1 core and on 2.

Each case trains TD3+BC offline RL (hopper-shaped synthetic data, batch 256, 2x256 LayerNorm nets, alpha 2.5) with
S seeds (the member axis) through the driver, times `--chunks` chunks of `--updates` updates after one warm-up chunk,
and reports the updates per second summed over the seeds:

    1core         one process pinned to one core, single-threaded XLA (the unit: what one core does)
    default       one process, XLA's default thread pool, not pinned (what a single variant gets today)
    2devices      one process, 2 forced host devices (the seeds split between them), single-threaded XLA
    2processes    2 processes joined by jax.distributed (gloo), each pinned to its core, single-threaded XLA,
                  the seeds split between them (`--coordinator/--num-processes/--process-id`)

    python -m benchmarks.scaling                                  # S = 1, 2, 4, 8, every case, a table
    python -m benchmarks.scaling --seeds 4 --cases 1core 2processes --json

Run it on an idle machine (each case has the machine to itself).  The 2-device and 2-process cases pad an odd S with
a copy of the last seed, as the driver does; the copy's updates are not counted.  `--members vmap` batches each
device's seeds (`jax.vmap`) instead of running them one after another (the CPU's default, `lax.map`).
"""
from __future__ import annotations

import argparse
import json
import os
import socket
import subprocess
import sys
import time

from offrl_jax.system.cli import OneLineParser, int_at_least, positive_int
from offrl_jax.system.workers import SINGLE_THREAD_XLA

CASES = ("1core", "default", "2devices", "2processes")


def _measure(seeds: int, updates: int, chunks: int, members: str | None = None) -> dict:
    """In this process (already set up for its case): the seed-summed updates per second of the timed chunks."""
    import jax

    from benchmarks.common import ACT_DIM, OBS_DIM, synthetic_data
    from offrl_jax.algos import make_algorithm, make_config
    from offrl_jax.driver import Driver

    transitions = 100_000
    config = make_config("td3bc", "hopper", alpha=2.5, pretrain="none")
    algo = make_algorithm(config, OBS_DIM, ACT_DIM, transitions)
    driver = Driver(algo, synthetic_data(transitions), tuple(range(seeds)), members=members)
    times = []
    for chunk in driver.run(algo.phases(updates * (chunks + 1)), updates):
        jax.block_until_ready(chunk.states)
        times.append(time.perf_counter())
    elapsed = times[-1] - times[0]
    return {"seeds": seeds, "updates_per_s": seeds * updates * chunks / elapsed,
            "devices": jax.device_count(), "processes": jax.process_count()}


def _worker(args) -> None:
    if args.process_id is not None:
        from offrl_jax.system import distributed
        distributed.initialize(f"localhost:{args.port}", 2, args.process_id)
    result = _measure(args.seeds[0], args.updates, args.chunks, args.members)
    if args.process_id in (None, 0):
        print(json.dumps(result), flush=True)


def _env(case: str) -> dict:
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    flags = {"1core": SINGLE_THREAD_XLA, "default": "", "2processes": SINGLE_THREAD_XLA,
             "2devices": f"{SINGLE_THREAD_XLA} --xla_force_host_platform_device_count=2"}[case]
    env["XLA_FLAGS"] = f"{flags} {env.get('XLA_FLAGS', '')}".strip()
    return env


def run_case(case: str, seeds: int, updates: int, chunks: int, members: str | None = None) -> dict:
    base = [sys.executable, "-m", "benchmarks.scaling", "--worker", "--seeds", str(seeds), "--updates", str(updates),
            "--chunks", str(chunks)] + (["--members", members] if members else [])
    pin = {"1core": [["taskset", "-c", "0"]], "default": [[]], "2devices": [[]],
           "2processes": [["taskset", "-c", "0"], ["taskset", "-c", "1"]]}[case]
    port = ""
    if case == "2processes":
        with socket.socket() as s:
            s.bind(("localhost", 0))
            port = str(s.getsockname()[1])
    procs = [subprocess.Popen(prefix + base + ([] if case != "2processes" else
                                               ["--port", port, "--process-id", str(i)]),
                              env=_env(case), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for i, prefix in enumerate(pin)]
    outs = [p.communicate(timeout=900) for p in procs]
    if any(p.returncode for p in procs):
        raise RuntimeError(f"{case} with {seeds} seeds failed: {outs[0][1].strip().splitlines()[-1:]}")
    return {"case": case, "members": members or "default", **json.loads(outs[0][0].strip().splitlines()[-1])}


def main(argv=None) -> int:
    p = OneLineParser(prog="python -m benchmarks.scaling", description=__doc__.split("\n\n")[0],
                      epilog="cases: " + ", ".join(CASES))
    p.add_argument("--seeds", type=positive_int, nargs="+", default=[1, 2, 4, 8],
                   help="seed counts S to time, each in every case (default: 1 2 4 8)")
    p.add_argument("--cases", nargs="+", choices=CASES, default=list(CASES),
                   help="which cases to run (default: all): 1core, one pinned process; default, XLA's own threads; "
                        "2devices, two host devices; 2processes, two pinned processes joined by jax.distributed")
    p.add_argument("--updates", type=positive_int, default=300, help="updates per timed chunk (default %(default)s)")
    p.add_argument("--chunks", type=positive_int, default=3,
                   help="timed chunks after the warm-up (default %(default)s)")
    p.add_argument("--members", choices=("map", "vmap"), default=None,
                   help="how a device runs its seeds (default: the driver's, map on the CPU)")
    p.add_argument("--json", action="store_true", help="one JSON line per measurement instead of a table")
    p.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--port", default=None, help=argparse.SUPPRESS)
    p.add_argument("--process-id", type=int_at_least(0), default=None, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker:
        _worker(args)
        return 0
    rows = []
    for seeds in args.seeds:
        for case in args.cases:
            try:
                rows.append(run_case(case, seeds, args.updates, args.chunks, args.members))
            except (RuntimeError, subprocess.TimeoutExpired) as e:
                print(f"warning: {e}", file=sys.stderr)
                continue
            if args.json:
                print(json.dumps(rows[-1]), flush=True)
            else:
                print(f"S = {seeds}: {case} {rows[-1]['updates_per_s']:.0f} updates/s", file=sys.stderr, flush=True)
    if not rows:
        print("error: no case could be measured (see the warnings above)", file=sys.stderr)
        return 2
    if not args.json:
        unit = {r["seeds"]: r["updates_per_s"] for r in rows if r["case"] == "1core"}
        print("| S | case | updates/s (summed over seeds) | x 1-core |\n|--:|---|--:|--:|")
        for r in rows:
            ratio = f"{r['updates_per_s'] / unit[r['seeds']]:.2f}" if r["seeds"] in unit else ""
            print(f"| {r['seeds']} | {r['case']} | {r['updates_per_s']:.0f} | {ratio} |")
    return 0


if __name__ == "__main__":
    from offrl_jax.system.cli import run_main

    run_main(main)
