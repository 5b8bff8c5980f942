"""Updates/s of every algorithm and phase through the real driver chunk function, against the machine's matmul rate.

    python -m benchmarks.throughput [--algo A ...] [--seeds S ...] [--json] [--quick] [--out NAME]

For each case (algorithm, phase, ensemble size) and each S seeds (the member axis): `offrl_jax.driver.make_chunk_fn` on
a synthetic 100k-transition hopper-shaped dataset (obs 11, act 3), batch 256, default network sizes; compile time
(trace + lower + XLA compile) reported separately; one warm-up chunk, then the median of a few timed chunks.

    updates_per_s       gradient updates per second summed over the S seeds (one TD3 call = policy_delay updates)
    gflop_per_update    analytic matmul GFLOPs of one update of one seed (benchmarks/flops.py)
    achieved_gflops     updates_per_s * gflop_per_update
    peak_gflops         this run's rate of a jitted chain of 256-wide dense layers at batch 256, measured right
                        before the case (the background load changes); `matmul1024_gflops` is a 1024^2 matmul
    pct_of_peak         100 * achieved_gflops / peak_gflops

Seeds are placed as `Driver` places them (`offrl_jax.driver.member_layout`): split over the devices (padded with copies
of the last seed when they do not divide; the copies' updates are not counted), the dataset replicated, and on each
device run one after another (`--members map`, the CPU's default) or batched (`--members vmap`, elsewhere).  E.g.
XLA_FLAGS="--xla_cpu_multi_thread_eigen=false --xla_force_host_platform_device_count=2" gives 2 single-threaded CPU
devices, as the command line gives a process on 2 cores (`offrl_jax.system.workers.cpu_flags`).

Progress goes to stderr, results to stdout (a table, or one JSON object per line with --json).  `--out NAME` also
appends them to results/benchmarks/NAME.jsonl (a run's first line: {"meta": {command, date, machine, load}}); an
existing file that is not JSON lines is refused, never overwritten (`benchmarks.common.results_path`).
"""
from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from benchmarks.common import (
    ACT_DIM,
    BATCH,
    OBS_DIM,
    append_results,
    chain_rate,
    log,
    machine,
    matmul_rate,
    results_path,
    synthetic_data,
)
from benchmarks.flops import update_flops
from offrl_jax.algos import make_algorithm, make_config
from offrl_jax.data.device import for_updates
from offrl_jax.driver import CHUNK, INIT, make_chunk_fn, member_layout, seed_keys
from offrl_jax.system.cli import OneLineParser, number, positive_int


@dataclasses.dataclass(frozen=True)
class Case:
    algo: str  # registry name
    phase: str  # label reported in the JSON
    phase_name: str  # `Phase.name` inside algo.phases(...)
    overrides: tuple[tuple[str, Any], ...] = ()
    tag: str = ""  # told apart in the label: the same algorithm and phase with other overrides

    @property
    def config(self):
        return make_config(self.algo, "hopper", **dict(self.overrides))

    @property
    def label(self) -> str:
        n = self.config.num_critics
        return (f"{self.algo}/{self.phase}" + (f"/N={n}" if self.algo in ("edac", "sacn", "edac_bc") else "")
                + (f"/{self.tag}" if self.tag else ""))


CASES: list[Case] = [
    Case("bc", "bc", "actor_pretrain"),
    Case("td3bc", "mc_critic_pretrain", "pretrain", (("pretrain", "critic"),)),
    Case("td3bc", "offline_rl", "offline_rl"),
    Case("td3bc_cql", "offline_rl", "offline_rl"),
    Case("rebrac", "offline_rl", "offline_rl"),
    Case("edac", "soft_bc_pretrain", "actor_pretrain", (("num_critics", 10),)),
    Case("edac", "soft_return_critic_pretrain", "critic_pretrain", (("num_critics", 10),)),
    Case("edac", "offline_rl", "offline_rl", (("num_critics", 10),)),
    Case("edac", "offline_rl", "offline_rl", (("num_critics", 50),)),
    Case("sacn", "offline_rl", "offline_rl", (("num_critics", 10),)),
    Case("sacn", "offline_rl", "offline_rl", (("num_critics", 50),)),
    Case("edac_bc", "offline_rl", "offline_rl", (("num_critics", 10),)),
    Case("cql", "offline_rl", "offline_rl"),
    Case("calql", "offline_rl", "offline_rl"),
    # Cal-QL with CORL's cal_ql.py networks: critics 2x256, actor 3x256, no LayerNorm
    Case("calql", "offline_rl", "offline_rl", (("hidden", (256, 256)), ("actor_hidden", (256, 256, 256)),
                                               ("actor_layer_norm", False), ("critic_layer_norm", False)), "corl-net"),
]
QUICK_CASE = Case("bc", "bc", "actor_pretrain")


_INIT_CACHE: dict[tuple, Any] = {}


def init_states(case: Case, max_seeds: int, n_rows: int):
    """Agent states for seeds 0..max_seeds-1, as `Driver.init` makes them but jitted (the eager vmap of the flax
    initialisers takes seconds); the first S of them are exactly S-seed `Driver.init` states.  Cached across cases
    whose networks are the same (e.g. TD3+BC and TD3+BC+CQL)."""
    config = case.config
    key = (type(config).__name__, config.num_critics, tuple(config.hidden), getattr(config, "actor_hidden", None),
           config.actor_layer_norm,
           config.critic_layer_norm, getattr(config, "init_alpha", None), max_seeds, n_rows)
    if key not in _INIT_CACHE:
        algo = make_algorithm(config, OBS_DIM, ACT_DIM, n_rows)
        _INIT_CACHE[key] = jax.jit(jax.vmap(algo.init))(seed_keys(tuple(range(max_seeds)), INIT, 0))
    return _INIT_CACHE[key]


def time_case(case: Case, seeds: int, data: dict[str, jax.Array], all_states, peak: float, expect_gflops: float,
              target_s: float, max_reps: int, heavy_s: float, mode: str | None = None) -> dict[str, Any]:
    """Compile and time the chunk function of `case` for `seeds` seeds on the member axis.

    Chunk length: about `target_s` seconds at `expect_gflops`.  One warm-up chunk, then the median of `max_reps`
    timed chunks; a chunk predicted to take more than `heavy_s` seconds (at least one update call for every seed
    is always run) is timed once, with no warm-up (the first-call overhead is small against it).
    """
    config = case.config
    n_rows = int(data["rewards"].shape[0])
    algo = make_algorithm(config, OBS_DIM, ACT_DIM, n_rows)
    total = getattr(config, "pretrain_updates", 0) + 1000
    phase = next(p for p in algo.phases(total) if p.name == case.phase_name)
    per_update, _ = update_flops(config, case.phase_name, OBS_DIM, ACT_DIM, BATCH)
    per_call = per_update * phase.updates_per_call
    calls = int(np.clip(round(target_s * expect_gflops * 1e9 / (per_call * seeds)), 1, 2000))
    predicted_s = calls * per_call * seeds / (expect_gflops * 1e9)

    layout = member_layout(seeds, mode=mode)  # as `Driver` places them; padded with copies of the last seed
    states = layout.place(jax.tree.map(lambda x: x[:seeds], all_states))  # own buffers (donated)
    keys = layout.place(seed_keys(tuple(range(seeds)), CHUNK))
    data = jax.device_put(for_updates(data, config.needs()), layout.replicated)  # e.g. ReBRAC's next actions
    tic = time.perf_counter()
    compiled = make_chunk_fn(phase, BATCH, calls, layout=layout).lower(states, data, keys, jnp.int32(0)).compile()
    compile_s = time.perf_counter() - tic

    def run_chunk(states, index):
        tic = time.perf_counter()
        states, metrics = compiled(states, data, keys, jnp.int32(index * calls * phase.updates_per_call))
        jax.block_until_ready((states, metrics))
        return states, time.perf_counter() - tic, bool(np.all(metrics["finite"]))

    warmup = predicted_s <= heavy_s
    reps = max_reps
    if warmup:
        states, warm_s, _ = run_chunk(states, 1)
        if warm_s > heavy_s:
            reps = 1
    else:
        reps = 1
    times, finite = [], True
    for r in range(reps):
        states, dt, ok = run_chunk(states, 2 + r)
        times.append(dt)
        finite &= ok
    chunk_s = float(np.median(times))
    updates_per_s = calls * phase.updates_per_call * seeds / chunk_s
    achieved = updates_per_s * per_update / 1e9
    return {
        "algo": case.algo,
        "phase": case.phase,
        "tag": case.tag,
        "seeds": seeds,
        "updates_per_s": round(updates_per_s, 2),
        "compile_s": round(compile_s, 2),
        "gflop_per_update": round(per_update / 1e9, 4),
        "achieved_gflops": round(achieved, 2),
        "peak_gflops": round(peak, 2),
        "pct_of_peak": round(100 * achieved / peak, 1),
        "num_critics": config.num_critics,
        "devices": layout.mesh.size,
        "members_mode": layout.mode,
        "padded_members": layout.padded,
        "updates_per_chunk": calls * phase.updates_per_call,
        "timed_chunks": reps,
        "warmup": warmup,
        "chunk_s": round(chunk_s, 4),
        "finite": finite,
        "load1": round(os.getloadavg()[0], 2),
    }


def shown_algo(r: dict[str, Any]) -> str:
    """The algorithm's name, with the case's tag where it has one (e.g. calql/corl-net)."""
    return r["algo"] + (f"/{r['tag']}" if r.get("tag") else "")


def format_row(r: dict[str, Any]) -> str:
    return (f"{shown_algo(r):<10} {r['phase']:<28} {r['num_critics']:>3} {r['seeds']:>2} {r['updates_per_s']:>9.1f} "
            f"{r['compile_s']:>7.1f} {r['gflop_per_update']:>8.4f} {r['achieved_gflops']:>8.1f} "
            f"{r['peak_gflops']:>7.1f} {r['pct_of_peak']:>6.1f} {r['load1']:>5.2f}")


HEADER = (f"{'algo':<10} {'phase':<28} {'N':>3} {'S':>2} {'upd/s':>9} {'comp_s':>7} {'GF/upd':>8} {'GF/s':>8} "
          f"{'peak':>7} {'%peak':>6} {'load':>5}")


def markdown(records: list[dict[str, Any]]) -> str:
    """A README table of JSON records (`--markdown FILE`)."""
    rows = ["| algo | phase | N | S | updates/s | compile s | GFLOP/update | GFLOP/s | peak GFLOP/s | % of peak "
            "| load |",
            "|---|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|"]
    for r in records:
        rows.append(f"| {shown_algo(r)} | {r['phase']} | {r['num_critics']} | {r['seeds']} | "
                    f"{r['updates_per_s']:.1f} | {r['compile_s']:.1f} | {r['gflop_per_update']:.3f} | "
                    f"{r['achieved_gflops']:.1f} | "
                    f"{r['peak_gflops']:.0f} | {r['pct_of_peak']:.0f} | {r['load1']:.1f} |")
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    p = OneLineParser(prog="python -m benchmarks.throughput", description=__doc__.split("\n\n")[0],
                      formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--algo", nargs="+", choices=sorted({c.algo for c in CASES}), metavar="ALGO",
                   help="only these registry names: %(choices)s (default: all)")
    p.add_argument("--seeds", nargs="+", type=positive_int, default=None,
                   help="seed counts on the member axis (default 1 2 4 8)")
    p.add_argument("--phase", nargs="+", choices=sorted({c.phase for c in CASES}), metavar="PHASE",
                   help="only these phase labels: %(choices)s (default: all)")
    p.add_argument("--num-critics", nargs="+", type=positive_int, help="only cases with these ensemble sizes")
    p.add_argument("--members", choices=("map", "vmap"), default=None,
                   help="how a device runs its seeds: one after another (map) or batched (vmap); default: map on the "
                        "CPU, vmap elsewhere, as the driver does")
    p.add_argument("--json", action="store_true", help="one JSON object per case on stdout")
    p.add_argument("--quick", action="store_true", help="one tiny case (BC, S=1, at most 10k rows, 2 short timed "
                   "chunks): a smoke test; takes none of the case-selection and timing flags")
    p.add_argument("--transitions", type=positive_int, default=100_000, help="rows of the synthetic dataset")
    p.add_argument("--target-s", type=number(0, low_open=True), default=None,
                   help="aimed-for seconds per timed chunk (default 0.25)")
    p.add_argument("--reps", type=positive_int, default=None,
                   help="timed chunks per case after a warm-up, median reported (default 3)")
    p.add_argument("--heavy-s", type=number(0, low_open=True), default=1.5,
                   help="chunks longer than this (one call per seed) are timed once without warm-up")
    p.add_argument("--markdown", metavar="FILE", help="print a markdown table of a results .jsonl file and exit")
    p.add_argument("--out", help="also append the JSON lines to results/benchmarks/OUT.jsonl (or OUT if it is a path)")
    args = p.parse_args(argv)

    if args.markdown is not None:  # an input: the results file to render
        source = Path(args.markdown)
        if source.is_dir():
            p.error(f"{source} is a directory; --markdown reads a results .jsonl file")
        try:
            raw = source.read_bytes()
        except FileNotFoundError:
            p.error(f"{source}: no such file (--markdown reads a results .jsonl file)")
        except OSError as e:
            p.error(f"{source}: cannot be read ({e.strerror or e})")
        try:
            lines = [json.loads(line) for line in raw.decode().splitlines() if line.strip()]
            if not all(isinstance(line, dict) for line in lines):
                raise ValueError("not one JSON object per line")
        except ValueError as e:
            p.error(f"{source}: not a results file of this benchmark ({e})")
        runs = []  # a file that --out appended to several times: a table per run, after its meta line
        for line in lines:
            if "meta" in line or not runs:
                runs.append((line.get("meta"), []))
            if "meta" not in line:
                runs[-1][1].append(line)
        try:
            text = []
            for m, rows in runs or [(None, [])]:
                if m is not None:
                    text.append(f"`{m['command']}` — {m['date']}, {m['machine']}, load average at start "
                                f"{m['load_avg']}, {m.get('seconds', '?')} s, 1024² matmul "
                                f"{m.get('matmul1024_gflops', '?')} GFLOP/s")
                text.append(markdown(rows))
            print("\n\n".join(text))
        except (KeyError, TypeError) as e:
            p.error(f"{args.markdown}: not a results file of this benchmark (missing {e})")
        return [r for _, rows in runs for r in rows]
    if args.quick:
        fixed = [flag for flag, value in (("--algo", args.algo), ("--phase", args.phase), ("--seeds", args.seeds),
                                          ("--num-critics", args.num_critics), ("--target-s", args.target_s),
                                          ("--reps", args.reps), ("--members", args.members))
                 if value is not None]
        if fixed:
            p.error(f"--quick runs one fixed case (BC, S=1, 2 short timed chunks), so it takes no {', '.join(fixed)}; "
                    "drop --quick to choose the cases and timing")
        cases, seed_counts = [QUICK_CASE], [1]
        args.transitions, args.target_s, args.reps = min(args.transitions, 10_000), 0.1, 2
    else:
        cases = [c for c in CASES if (not args.algo or c.algo in args.algo)
                 and (not args.phase or c.phase in args.phase)
                 and (not args.num_critics or c.config.num_critics in args.num_critics)]
        seed_counts = args.seeds or [1, 2, 4, 8]
        args.target_s = 0.25 if args.target_s is None else args.target_s
        args.reps = 3 if args.reps is None else args.reps
        if not cases:
            chosen = [f"{flag} {' '.join(map(str, v))}" for flag, v in
                      (("--algo", args.algo), ("--phase", args.phase), ("--num-critics", args.num_critics)) if v]
            p.error(f"no case matches {' '.join(chosen)} (the cases: {', '.join(c.label for c in CASES)})")
    out_path = results_path(p, args.out)

    meta = {"command": " ".join([Path(sys.executable).name, "-m", "benchmarks.throughput", *sys.argv[1:]]),
            "date": datetime.datetime.now().isoformat(timespec="seconds"), "machine": machine(),
            "load_avg": [round(x, 2) for x in os.getloadavg()], "xla_flags": os.environ.get("XLA_FLAGS", "")}
    log(f"# {meta['date']}  {meta['machine']}  load {meta['load_avg']}  XLA_FLAGS={meta['xla_flags']!r}")
    start = time.perf_counter()
    data = synthetic_data(args.transitions)
    matmul = matmul_rate()
    log(f"# 1024^2 matmul: {matmul:.1f} GFLOP/s")
    if jax.default_backend() != "cpu":
        log("# note: on a GPU the 256-wide chain ('peak') is launch-bound and a scan of whole updates beats it; "
            "read updates/s, not % of peak")
    if not args.json:
        print(HEADER, flush=True)
    results = []
    for case in cases:
        peak = chain_rate()
        log(f"[{time.perf_counter() - start:6.1f}s] {case.label}: 256-wide chain {peak:.1f} GFLOP/s")
        all_states = init_states(case, max(seed_counts), int(data["rewards"].shape[0]))
        expect = 0.4 * peak  # achieved-rate guess for sizing chunks; then the previous seed count's rate
        for s in sorted(seed_counts):
            r = time_case(case, s, data, all_states, peak, expect, args.target_s, args.reps, args.heavy_s,
                          args.members)
            expect = max(r["achieved_gflops"], 1.0)
            r["matmul1024_gflops"] = round(matmul, 2)
            results.append(r)
            log(f"[{time.perf_counter() - start:6.1f}s]   S={s}: {r['updates_per_s']:.1f} updates/s "
                f"({r['pct_of_peak']:.1f} % of peak), compile {r['compile_s']:.1f}s, load {r['load1']}")
            print(json.dumps(r) if args.json else format_row(r), flush=True)
    meta["seconds"] = round(time.perf_counter() - start, 1)
    meta["matmul1024_gflops"] = round(matmul, 2)
    log(f"# done in {meta['seconds']}s")
    if out_path is not None:
        append_results(out_path, [{"meta": meta}, *results])
        log(f"# appended to {out_path}")
    return results


if __name__ == "__main__":
    from offrl_jax.system.cli import run_main

    run_main(main)
