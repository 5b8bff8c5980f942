"""Ready for an accelerator in ten minutes: one command that measures what a GPU (or TPU) does with this code.

    python -m benchmarks.device_check                       # on the device machine, about 5-8 minutes
    python -m benchmarks.device_check --quick               # a CPU smoke test of the script itself (~1 minute)

It appends JSON lines to a results file (default results/benchmarks/device-<device kind>-<date>.jsonl, see
`benchmarks.common.results_path`): a {"meta": ...} line, one line per case, a {"main_job": ...} line, with
- the device, JAX version and backend (in the meta line);
- the float32 matmul rate (8192², precision "highest") and the TF32 / default-precision rate, in TFLOP/s;
- TD3+BC and EDAC (N = 10) offline-RL updates/s, summed over members, for members = 1, 8, 64, 256 (seeds or
  seeds x sweep values: one vmapped program, as the driver runs them), with compile time, achieved TFLOP/s from the
  analytic FLOP count, its fraction of each matmul rate, and the device's peak memory after each case;
- the main job (`python -m experiments.mujoco_medium`, its default) end to end: wall-clock and its final table,
  in the time left of --budget-s (hopper-medium must be cached; the file says so otherwise).
A line is appended after every case, so a check cut short keeps what it measured.
A member axis in the hundreds is what fills such a chip: compare updates/s at 1 and at 256.
"""
from __future__ import annotations

import argparse
import datetime
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import jax
import jax.numpy as jnp

from benchmarks.common import append_results, results_path, synthetic_data
from benchmarks.throughput import CASES, init_states, time_case
from offrl_jax.system.cli import OneLineParser, positive_int

ROOT = Path(__file__).resolve().parents[1]


def matmul_tflops(n: int, precision: str, reps: int = 5) -> float:
    a = jax.random.normal(jax.random.PRNGKey(0), (n, n), jnp.float32)
    f = jax.jit(lambda x, y: jnp.matmul(x, y, precision=precision))
    f(a, a).block_until_ready()
    times = []
    for _ in range(reps):
        tic = time.perf_counter()
        f(a, a).block_until_ready()
        times.append(time.perf_counter() - tic)
    return 2 * n**3 / sorted(times)[len(times) // 2] / 1e12


def peak_memory() -> int | None:
    stats = jax.devices()[0].memory_stats() or {}
    return stats.get("peak_bytes_in_use")


def main_job(timeout_s: float) -> dict:
    """The main job's default, timed; hopper-medium must be cached (generating it is CPU work, ~3 minutes)."""
    from offrl_jax.data import catalogue
    if not catalogue.is_cached("hopper-medium"):
        return {"skipped": "hopper-medium is not cached here: run `python -m offrl_jax.data generate "
                           "hopper-medium` first (CPU, ~3 minutes), then this check again"}
    with tempfile.TemporaryDirectory() as out:
        tic = time.perf_counter()
        try:
            result = subprocess.run([sys.executable, "-m", "experiments.mujoco_medium", "--out", f"{out}/run",
                                     "--no-progress"], cwd=ROOT, capture_output=True, text=True, timeout=timeout_s)
        except subprocess.TimeoutExpired:
            return {"timed_out_after_s": round(timeout_s, 1)}
        return {"seconds": round(time.perf_counter() - tic, 1), "returncode": result.returncode,
                "table": result.stdout.strip().splitlines()[-6:], "stderr_tail": result.stderr.strip()[-500:]}


def main(argv: list[str] | None = None) -> dict:
    p = OneLineParser(prog="python -m benchmarks.device_check", description=__doc__.split("\n\n")[0],
                      formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--members", nargs="+", type=positive_int, default=[1, 8, 64, 256],
                   help="member-axis sizes to time, one case each per algorithm (default: 1 8 64 256)")
    p.add_argument("--transitions", type=positive_int, default=1_000_000, help="rows of the synthetic dataset")
    p.add_argument("--matmul-n", type=positive_int, default=8192, help="side of the matmul timed for the peak")
    p.add_argument("--no-main-job", action="store_true", help="skip the main job end to end")
    p.add_argument("--budget-s", type=positive_int, default=540,
                   help="seconds for the whole check (default %(default)s); the main job gets what is left")
    p.add_argument("--quick", action="store_true", help="tiny budget, for testing the script on a CPU")
    p.add_argument("--out", default=None, help="append the JSON lines to results/benchmarks/OUT.jsonl (or OUT if a "
                   "path; default device-<device kind>-<date>)")
    args = p.parse_args(argv)
    if args.quick:
        args.members, args.transitions, args.matmul_n, args.no_main_job = [1, 2], 5_000, 256, True
    device = jax.devices()[0]
    kind = device.device_kind.replace(" ", "-").lower()
    default = ROOT / "results" / "benchmarks" / f"device-{kind}-{datetime.date.today():%Y%m%d}.jsonl"
    out = results_path(p, str(default) if args.out is None else args.out)
    report = {"date": datetime.datetime.now().isoformat(timespec="seconds"), "device_kind": device.device_kind,
              "platform": jax.default_backend(), "devices": jax.device_count(), "jax": jax.__version__,
              "command": " ".join(["python", "-m", "benchmarks.device_check", *(argv or sys.argv[1:])])}
    start = time.perf_counter()
    report["matmul_tflops"] = {precision: round(matmul_tflops(args.matmul_n, precision), 2)
                               for precision in ("highest", "default")}
    append_results(out, [{"meta": dict(report)}])
    print(f"matmul {args.matmul_n}²: {report['matmul_tflops']} TFLOP/s", file=sys.stderr, flush=True)
    data = synthetic_data(args.transitions)
    rows = int(data["rewards"].shape[0])
    report["cases"] = []
    for case in [c for c in CASES if c.phase == "offline_rl" and (c.algo, c.config.num_critics) in
                 (("td3bc", 2), ("edac", 10))]:
        states = init_states(case, max(args.members), rows)
        for members in args.members:
            r = time_case(case, members, data, states, peak=report["matmul_tflops"]["highest"] * 1e3,
                          expect_gflops=50.0 * members, target_s=0.5, max_reps=3, heavy_s=5.0)
            tflops = r["achieved_gflops"] / 1e3
            r |= {"achieved_tflops": round(tflops, 3), "peak_memory_bytes": peak_memory(),
                  "pct_of_fp32_matmul": round(100 * tflops / report["matmul_tflops"]["highest"], 2),
                  "pct_of_default_matmul": round(100 * tflops / report["matmul_tflops"]["default"], 2)}
            for key in ("peak_gflops", "pct_of_peak"):  # the CPU benchmark's 256-wide chain: not measured here
                r.pop(key, None)
            report["cases"].append(r)
            append_results(out, [r])
            print(f"{case.label} members={members}: {r['updates_per_s']:.0f} updates/s, "
                  f"{r['pct_of_fp32_matmul']:.1f} % of fp32 matmul, compile {r['compile_s']:.1f}s", file=sys.stderr,
                  flush=True)
    if not args.no_main_job:
        report["main_job"] = main_job(max(1.0, args.budget_s - (time.perf_counter() - start)))
        print(f"main job: {report['main_job']}", file=sys.stderr)
        append_results(out, [{"main_job": report["main_job"]}])
    print(f"appended to {out}", file=sys.stderr)
    return report


if __name__ == "__main__":
    from offrl_jax.system.cli import run_main

    run_main(main)
