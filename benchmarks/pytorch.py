"""TD3+BC and EDAC written the way PyTorch users write them (tests/torch_reference.py, after CORL) against the JAX
driver: updates/s on the same machine, and with `--compare` the two timed alternately so both see the same load.

    python -m benchmarks.pytorch [--algo td3bc edac] [--json]     PyTorch alone
    python -m benchmarks.pytorch --compare --threads 1            JAX and PyTorch interleaved, with ratios

Same shapes as benchmarks.throughput: hopper (obs 11, act 3), 100k random transitions, batch 256, default sizes,
one seed.  PyTorch is an optional extra (`pip install -e .[torch]`, CPU build).
"""
from __future__ import annotations

import json
import os
import sys
import time

import numpy as np

from offrl_jax.system.cli import OneLineParser, positive_int, print_error

try:
    import torch

    from tests.torch_reference import EDAC, ROWS, TD3BC, Replay
except ModuleNotFoundError:
    print_error("benchmarks.pytorch needs PyTorch: pip install -e .[torch]")
    sys.exit(2)

def make(algo: str):
    agent = TD3BC() if algo == "td3bc" else EDAC(num_critics=10)
    return agent.train if algo == "td3bc" else agent.update


def time_torch(step, replay: Replay, updates: int) -> float:
    """Seconds per update over `updates` updates (sampling included, as in the JAX scan)."""
    tic = time.perf_counter()
    for _ in range(updates):
        step(replay.sample())
    return (time.perf_counter() - tic) / updates


def torch_updates(algo: str, target_s: float = 1.0) -> int:
    return max(2, int(target_s * {"td3bc": 100, "edac": 3}[algo]) // 2 * 2)


def run_torch(algos: list[str], reps: int, as_json: bool) -> None:
    replay = Replay()
    for algo in algos:
        step = make(algo)
        n = torch_updates(algo)
        time_torch(step, replay, n)  # warm-up
        t = float(np.median([time_torch(step, replay, n) for _ in range(reps)]))
        r = {"algo": algo, "phase": "offline_rl", "impl": "torch", "seeds": 1, "updates_per_s": round(1 / t, 2),
             "torch_threads": torch.get_num_threads(), "torch": torch.__version__,
             "load1": round(os.getloadavg()[0], 2)}
        print(json.dumps(r) if as_json else f"{algo:<6} torch {r['updates_per_s']:8.2f} updates/s "
              f"({r['torch_threads']} threads, load {r['load1']})", flush=True)


def compare(algos: list[str], rounds: int) -> None:
    """JAX (driver chunk function, S = 1) and PyTorch timed alternately, so both see the same background load."""
    from benchmarks.common import chain_rate, synthetic_data
    from benchmarks.throughput import CASES, init_states, time_case

    data = synthetic_data(ROWS)
    replay = Replay()
    peak = chain_rate()
    for algo in algos:
        case = next(c for c in CASES if c.algo == algo and c.phase == "offline_rl"
                    and c.config.num_critics == (2 if algo == "td3bc" else 10))
        states = init_states(case, 1, ROWS)
        step = make(algo)
        n = torch_updates(algo)
        time_torch(step, replay, n)
        jax_rates, torch_rates = [], []
        for _ in range(rounds):
            r = time_case(case, 1, data, states, peak, 0.25 * peak, 1.0, 1, 1e9)
            jax_rates.append(r["updates_per_s"])
            torch_rates.append(1 / time_torch(step, replay, n))
        j, t = float(np.median(jax_rates)), float(np.median(torch_rates))
        print(json.dumps({"algo": algo, "phase": "offline_rl", "seeds": 1, "jax_updates_per_s": round(j, 2),
                          "torch_updates_per_s": round(t, 2), "ratio": round(j / t, 2), "rounds": rounds,
                          "jax_rates": jax_rates, "torch_rates": [round(x, 2) for x in torch_rates],
                          "torch_threads": torch.get_num_threads(), "load1": round(os.getloadavg()[0], 2)}),
              flush=True)


def main(argv: list[str] | None = None) -> None:
    p = OneLineParser(prog="benchmarks.pytorch", description=__doc__.split("\n\n")[0])
    p.add_argument("--algo", nargs="+", default=["td3bc", "edac"], choices=["td3bc", "edac"],
                   help="algorithms to time (default: td3bc edac)")
    p.add_argument("--json", action="store_true", help="one JSON object per algorithm instead of a line of text")
    p.add_argument("--reps", type=positive_int, default=3,
                   help="timed rounds, median reported (default %(default)s)")
    p.add_argument("--compare", action="store_true", help="interleave JAX and PyTorch timings; print the ratio")
    p.add_argument("--threads", type=positive_int, help="torch.set_num_threads (default: PyTorch's choice)")
    args = p.parse_args(argv)
    if args.threads is not None:
        torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    print(f"# torch {torch.__version__}, {torch.get_num_threads()} threads, load {os.getloadavg()}", file=sys.stderr)
    if args.compare:
        compare(args.algo, args.reps)
    else:
        run_torch(args.algo, args.reps, args.json)


if __name__ == "__main__":
    from offrl_jax.system.cli import run_main

    run_main(main)
