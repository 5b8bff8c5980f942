"""Our update against another library's own training loop: each in its own process, in turn, on one core.

    python -m benchmarks.libraries LIBRARY --python PATH [--source PATH] [--pairs P] [--core C] [--json] [--out NAME]

  LIBRARY  algorithm  theirs, as their own loop runs it                            ours (benchmarks.throughput)
  d3rlpy   TD3+BC     d3rlpy 2.8.1: fit's loop body, sample a batch + update       td3bc offline_rl
  ajax-rl  TD3+BC     ajax-rl 0.4.0: TD3 + ImitationLoss in its jitted scan        td3bc offline_rl
  fql      ReBRAC     fql's agents/rebrac.py: main.py's loop, sample + update      rebrac offline_rl

Their side runs `benchmarks/adapters/<library>.py` with their interpreter (`--python`: a virtual environment where
their package is installed, made as `INSTALL` below says); fql is not a package: `--source` names a checkout, whose
`agents/` and `utils/` are imported from there, never copied.  Our side runs `python -m benchmarks.throughput` for
the matching case with this interpreter.  Each pair runs both, each a fresh process pinned to core `--core` with
one thread (XLA_FLAGS=--xla_cpu_multi_thread_eigen=false, OMP/MKL 1, torch.set_num_threads(1)), so
both see the same background load; compile time and set-up are excluded from both rates.

Matched: hopper shapes (obs 11, act 3), a synthetic dataset of `--transitions` rows, batch 256, twin critics, the
actor and targets updated every 2nd critic update, Adam; TD3+BC 2x256 with LayerNorm before every ReLU in actor and
critic (d3rlpy has no such option: its adapter builds the encoder from torch modules; ajax-rl's from its layer
strings); ReBRAC 3x256 with ReLU, LayerNorm in the critic only (fql's own defaults: 4x512, GELU).  Not matched,
each library's own way, kept: how a batch is drawn (theirs: numpy or flashbax; ours: an index draw inside the jitted
scan); ajax-rl's observation normalisation inside every network call; d3rlpy's critics run one after the other, and
its and ajax-rl's actor losses evaluate both critics where ours evaluates the first (d3rlpy's backward also computes
the critics' weight gradients, then drops them); fql's one Adam steps every parameter each update, targets too.

Reported: critic updates per second (one gradient step of the twin critics; ours = `updates_per_s`, theirs
`critic_updates_per_s`), each side's median over its 3 timed repeats (ours: ~2 s chunks after a warm-up one; theirs:
after a warm-up), per pair, the medians over pairs, and the median of the pairs' ratios ours / theirs; pairs
alternate which side runs first.  A table goes to stdout (with --json: one JSON object), progress to stderr;
`--out NAME` appends the object to results/benchmarks/NAME.jsonl (or NAME if a path; `common.results_path`).
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import shutil
import statistics
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from benchmarks.common import append_results, machine, results_path
from offrl_jax.system.cli import OneLineParser, positive_int

ADAPTERS = Path(__file__).parent / "adapters"
ONE_THREAD = {"XLA_FLAGS": "--xla_cpu_multi_thread_eigen=false", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


@dataclass(frozen=True)
class Library:
    algo: str  # our registry name, a case of benchmarks.throughput (phase offline_rl)
    adapter: str  # file in benchmarks/adapters/
    updates: int  # their critic updates per timed repeat: about 10-20 s on one core
    install: str
    extra: tuple[str, ...] = ()  # adapter flags that match our case
    source: bool = False  # needs --source (a checkout, not a package)


LIBRARIES = {
    "d3rlpy": Library("td3bc", "d3rlpy_td3bc.py", 500, "python3.11 -m venv V && V/bin/pip install torch==2.13.0 "
                      "--index-url https://download.pytorch.org/whl/cpu && V/bin/pip install d3rlpy==2.8.1",
                      ("--threads", "1")),
    "ajax-rl": Library("td3bc", "ajax_rl_td3bc.py", 2000, "python3.12 -m venv V && V/bin/pip install ajax-rl==0.4.0 "
                       "jax==0.10.2 jaxlib==0.10.2 flax==0.12.8   # our jax, so one XLA times both"),
    "fql": Library("rebrac", "fql_rebrac.py", 1000, "python3.11 -m venv V && V/bin/pip install jax==0.10.2 "
                   "flax==0.12.8 optax==0.2.8 distrax ml_collections; git clone https://github.com/seohongpark/fql "
                   "(--source)",
                   source=True),
}


def log(*args) -> None:
    print(*args, file=sys.stderr, flush=True)


def run_json(cmd: list[str], core: int | None, what: str, key: str) -> tuple[list[float], list[dict]]:
    """Run `cmd` pinned to `core` (None: unpinned) with one thread; the rates (`key`) of its stdout's JSON lines, and
    the lines (one line and exit 1 if it fails or prints none)."""
    pin = [] if core is None else ["taskset", "-c", str(core)]  # no fork-time hook: JAX has threads
    proc = subprocess.run(pin + cmd, capture_output=True, text=True, env=os.environ | ONE_THREAD)
    try:
        lines = [json.loads(line) for line in proc.stdout.splitlines() if line.startswith("{")]
        rates = [float(line[key]) for line in lines]
    except (ValueError, KeyError, TypeError) as e:
        sys.exit(f"error: {what} printed a line that is not its JSON result ({type(e).__name__}: {e})")
    if proc.returncode or not rates:
        tail = (proc.stderr.strip().splitlines() or ["(no output)"])[-1]
        sys.exit(f"error: {what} failed (exit {proc.returncode}): {tail}")
    return rates, lines


def ours(lib: Library, transitions: int, core: int | None) -> float:
    """The median of 3 timed ~2 s chunks after a warm-up one (no chunk is 'heavy' here: `--heavy-s` out of reach)."""
    rates, _ = run_json([sys.executable, "-m", "benchmarks.throughput", "--algo", lib.algo, "--phase", "offline_rl",
                         "--seeds", "1", "--json", "--transitions", str(transitions), "--target-s", "2", "--reps",
                         "3", "--heavy-s", "1e9"], core, f"ours ({lib.algo})", "updates_per_s")
    return rates[0]


def theirs(lib: Library, python: str, source: Path | None, transitions: int, core: int | None) -> tuple[float, dict]:
    """The median of their adapter's 3 repeats, and its last line (versions, compile and set-up times)."""
    cmd = [python, str(ADAPTERS / lib.adapter), "--transitions", str(transitions), "--updates", str(lib.updates),
           "--repeats", "3", *lib.extra, *(["--source", str(source)] if source else [])]
    rates, lines = run_json(cmd, core, f"theirs ({lib.adapter})", "critic_updates_per_s")
    return statistics.median(rates), lines[-1]


def main(argv: list[str] | None = None) -> dict:
    p = OneLineParser(prog="python -m benchmarks.libraries", description=__doc__.split("\n\n")[0],
                      epilog="INSTALL (V: a new virtual environment):\n" + "\n".join(
                          f"  {name}: {lib.install}" for name, lib in LIBRARIES.items()),
                      formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("library", choices=sorted(LIBRARIES), help="whose training loop to time against ours")
    p.add_argument("--python", required=True, metavar="PATH", help="the interpreter that has their library")
    p.add_argument("--source", type=Path, metavar="PATH", help="fql only: a checkout of github.com/seohongpark/fql")
    p.add_argument("--pairs", type=positive_int, default=3,
                   help="pairs of runs, alternately ours or theirs first (%(default)s)")
    p.add_argument("--transitions", type=positive_int, default=100_000, help="synthetic dataset rows (%(default)s)")
    p.add_argument("--core", type=int, help="the core both sides are pinned to (default: this process's first)")
    p.add_argument("--json", action="store_true", help="one JSON object on stdout instead of a table")
    p.add_argument("--out", help="also append the JSON object to results/benchmarks/OUT.jsonl (or OUT if a path)")
    args = p.parse_args(argv)
    lib = LIBRARIES[args.library]
    if not (os.path.isfile(args.python) and os.access(args.python, os.X_OK)):
        p.error(f"--python {args.python}: not an executable file (their interpreter; see INSTALL in --help)")
    if lib.source and (args.source is None or not (args.source / "agents" / "rebrac.py").is_file()):
        p.error(f"{args.library} needs --source, a checkout of github.com/seohongpark/fql (agents/rebrac.py)")
    if not lib.source and args.source is not None:
        p.error(f"--source is for fql; {args.library} is imported from --python's environment")
    cores = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else [0]
    args.core = cores[0] if args.core is None else args.core
    if args.core not in cores:
        p.error(f"--core {args.core}: not one of this process's cores {cores}")
    out_path = results_path(p, args.out)

    core = args.core if shutil.which("taskset") else None
    if core is None:
        log("warning: no taskset here: both sides run unpinned")
    start = datetime.datetime.now()
    pairs, info = [], {}
    for i in range(args.pairs):  # ours first in even pairs, theirs first in odd ones: a drift hits both
        if i % 2:
            b, info = theirs(lib, args.python, args.source, args.transitions, core)
            a = ours(lib, args.transitions, core)
        else:
            a = ours(lib, args.transitions, core)
            b, info = theirs(lib, args.python, args.source, args.transitions, core)
        pairs.append({"ours": a, "theirs": b, "ratio": round(a / b, 3)})
        log(f"pair {i + 1}/{args.pairs}: ours {a:.1f}, {args.library} {b:.1f} critic updates/s, ratio {a / b:.2f}")
    result = {
        "library": args.library, "algo": lib.algo, "adapter": lib.adapter, "python": args.python,
        "ours_critic_updates_per_s": round(statistics.median(x["ours"] for x in pairs), 2),
        "theirs_critic_updates_per_s": round(statistics.median(x["theirs"] for x in pairs), 2),
        "ratio": round(statistics.median(x["ratio"] for x in pairs), 3), "pairs": pairs,
        "theirs_last_line": info, "transitions": args.transitions, "core": core,
        "date": start.isoformat(timespec="seconds"),
        "machine": machine(), "load_avg": [round(x, 2) for x in os.getloadavg()],
        "command": " ".join(["python", "-m", "benchmarks.libraries", *(argv if argv is not None else sys.argv[1:])]),
    }
    if args.json:
        print(json.dumps(result))
    else:
        print(f"{args.library} ({lib.algo}), one core, critic updates/s, median of {args.pairs} pairs:")
        print(f"  ours {result['ours_critic_updates_per_s']:.1f}   theirs {result['theirs_critic_updates_per_s']:.1f}"
              f"   ours / theirs {result['ratio']:.2f}x (pairs: "
              + ", ".join(f"{x['ratio']:.2f}" for x in pairs) + "; the ratio is the median of the pairs' ratios)")
    if out_path is not None:
        append_results(out_path, [result])
        log(f"appended to {out_path}")
    return result


if __name__ == "__main__":
    from offrl_jax.system.cli import run_main

    run_main(main)
