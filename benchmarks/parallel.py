"""Two variants at once: threads of one process against worker processes pinned to their own cores.

What `--parallel 2` chooses between.  Each case trains `--variants` TD3+BC offline-RL programs of `--seeds`
seeds each on its member axis (the main job's shape: 3 seeds, hopper-shaped synthetic data, batch 256, LayerNorm)
at the same time, and reports the updates per second summed over every seed of every variant, timed from a common
start after each program has compiled and run one warm-up chunk:

    python -m benchmarks.parallel                       # every case, a table
    python -m benchmarks.parallel --json --calls 50     # JSON lines, shorter chunks

cases:
    threads           one process, one thread per variant, XLA's default thread pool (`--parallel 2` before)
    threads-1t        the same with single-threaded XLA
    processes         one process per variant, default XLA threads, not pinned
    pinned-1t         one process per variant pinned to its own core, single-threaded XLA (`--parallel 2` now)
    alone             one variant in one process, default XLA (how fast a variant runs with the machine to itself)
Run it on an idle machine: each case's processes share the machine only with each other.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import threading
import time

from offrl_jax.system.cli import OneLineParser, positive_int
from offrl_jax.system.workers import SINGLE_THREAD_XLA, core_sets

CASES = ("threads", "threads-1t", "processes", "pinned-1t", "alone")


def _time_programs(programs: int, seeds: int, calls: int, transitions: int, start_at: float) -> float:
    """In this process: compile `programs` chunk functions, wait for `start_at`, run 3 chunks of each in threads;
    the updates per second summed over programs and seeds."""
    import jax
    import jax.numpy as jnp

    from benchmarks.common import ACT_DIM, OBS_DIM, synthetic_data
    from offrl_jax.algos import make_algorithm, make_config
    from offrl_jax.driver import CHUNK, INIT, make_chunk_fn, seed_keys

    data = synthetic_data(transitions)
    config = make_config("td3bc", "hopper", alpha=2.5)
    algo = make_algorithm(config, OBS_DIM, ACT_DIM, transitions)
    phase = next(p for p in algo.phases(config.pretrain_updates + 2000) if p.name == "offline_rl")
    jobs = []
    for j in range(programs):
        states = jax.jit(jax.vmap(algo.init))(seed_keys(tuple(range(j * seeds, (j + 1) * seeds)), INIT, 0))
        states = jax.tree.map(lambda x: jnp.array(x, copy=True), states)
        chunk, keys = make_chunk_fn(phase, 256, calls), seed_keys(tuple(range(seeds)), CHUNK)
        states, _ = chunk(states, data, keys, jnp.int32(0))
        jobs.append([chunk, jax.block_until_ready(states), keys])

    def work(job):
        chunk, states, keys = job
        for r in range(3):
            states, _ = chunk(states, data, keys, jnp.int32((r + 1) * calls * phase.updates_per_call))
            jax.block_until_ready(states)

    if time.time() > start_at:
        print(f"warning: ready {time.time() - start_at:.0f} s after the common start; raise --start-after",
              file=sys.stderr)
    while time.time() < start_at:
        time.sleep(0.005)
    tic = time.perf_counter()
    threads = [threading.Thread(target=work, args=(job,)) for job in jobs]
    [t.start() for t in threads]
    [t.join() for t in threads]
    return programs * seeds * 3 * calls * phase.updates_per_call / (time.perf_counter() - tic)


def run_case(case: str, args) -> float:
    """Updates/s summed over every seed of every variant of `case`, each part in a fresh process."""
    single = {"XLA_FLAGS": f"{SINGLE_THREAD_XLA} {os.environ.get('XLA_FLAGS', '')}".strip()}
    threads = case.startswith("threads")
    procs = 1 if threads or case == "alone" else args.variants
    programs = 1 if case == "alone" else (args.variants if threads else 1)
    cores = core_sets(procs)
    start_at = time.time() + args.start_after
    children = []
    for i in range(procs):
        env = dict(os.environ) | (single if case.endswith("-1t") else {})
        command = [sys.executable, "-m", "benchmarks.parallel", "--child", str(programs), str(start_at),
                   "--seeds", str(args.seeds), "--calls", str(args.calls), "--transitions", str(args.transitions)]
        if case == "pinned-1t":
            command = ["taskset", "-c", ",".join(map(str, cores[i % len(cores)]))] + command
        children.append(subprocess.Popen(command, env=env, stdout=subprocess.PIPE, text=True))
    total = 0.0
    for child in children:
        out = child.communicate()[0].strip().splitlines()
        if child.returncode != 0 or not out:
            raise RuntimeError(f"case {case}: a timing process failed (exit code {child.returncode})")
        total += float(out[-1])
    return total


def main(argv: list[str] | None = None) -> None:
    p = OneLineParser(prog="python -m benchmarks.parallel", description=__doc__,
                      formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--cases", nargs="+", choices=CASES, default=list(CASES),
                   help="which cases to run, as listed above (default: all)")
    p.add_argument("--variants", type=positive_int, default=2, help="variants trained at once")
    p.add_argument("--seeds", type=positive_int, default=3, help="seeds per variant, on its member axis")
    p.add_argument("--calls", type=positive_int, default=250, help="update calls (2 updates each) per timed chunk")
    p.add_argument("--transitions", type=positive_int, default=1_000_000, help="rows of the synthetic dataset")
    p.add_argument("--start-after", type=positive_int, default=60,
                   help="seconds from launch to the common start (enough to compile and warm up)")
    p.add_argument("--json", action="store_true", help="one JSON object per case")
    p.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.child:
        print(_time_programs(int(args.child[0]), args.seeds, args.calls, args.transitions, float(args.child[1])))
        return
    for case in args.cases:
        try:
            rate = run_case(case, args)
        except RuntimeError as e:
            p.error(str(e))
        record = {"case": case, "variants": 1 if case == "alone" else args.variants, "seeds": args.seeds,
                  "updates_per_s": round(rate, 1), "load1": round(os.getloadavg()[0], 2)}
        print(json.dumps(record) if args.json else f"{case:12s} {record['variants']} x {args.seeds} seeds: "
              f"{rate:7.1f} updates/s", flush=True)


if __name__ == "__main__":
    from offrl_jax.system.cli import run_main

    run_main(main)
