"""Where an update's time goes: one chunk of the real driver traced with `jax.profiler`, every XLA CPU op attributed.

    python -m benchmarks.profile                          # TD3+BC offline RL, S = 1, a table on stdout
    python -m benchmarks.profile --algo edac --json --out profile-edac
    taskset -c 0 env XLA_FLAGS=--xla_cpu_multi_thread_eigen=false python -m benchmarks.profile   # one core

The chunk function (`offrl_jax.driver.make_chunk_fn`, S = 1, synthetic hopper-shaped data of
`benchmarks/common.py`) is compiled, run once, then run again under `jax.profiler.trace`.  The trace's XLA CPU
op events (thunks: a matmul, a fused element-wise loop, a reduction, ...) are matched by name to the optimised HLO,
whose metadata says which part of the program made each op (`op_name`, e.g.
`transpose(jvp(CriticEnsemble))/vmap(VmapCritic_0)/MLP_0/LayerNorm_0/...`).  Each op goes to one part:

    matmul        a dot (or a fusion around one): Dense layers forward, backward and their weight gradients
    layernorm     the rest of a LayerNorm (mean, variance, normalise, and their gradients)
    activation    ReLU / tanh and their gradients
    sampling      minibatch indices and gathers, target-policy noise, key splitting (threefry)
    loss          the rest of the losses and their gradients (TD targets, BC term, means)
    update        element-wise work outside the gradients: Adam, Polyak averaging of the targets, metrics
    other         ops with no metadata (copies, loop bookkeeping)

The table gives, per part, milliseconds per update, the share of the traced op time, and for the matmuls the rate
they ran at (FLOPs from the dot shapes).  The share of time outside the matmuls is what keeps an update from the
chain rate of `benchmarks/common.py`.
"""
from __future__ import annotations

import argparse
import collections
import gzip
import json
import math
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from offrl_jax.system.cli import OneLineParser, positive_int

PARTS = ("matmul", "layernorm", "activation", "sampling", "loss", "update", "other")
_DEF = re.compile(r"^\s*(?:ROOT )?%([\w.\-]+) = (\w+)\[([\d,]*)\]\S* (\w[\w\-]*)\((.*)$")
_CALLS = re.compile(r"calls=%([\w.\-]+)")
_OPNAME = re.compile(r'op_name="([^"]*)"')
_CONTRACT = re.compile(r"lhs_contracting_dims=\{([\d,]*)\}")


def parse_hlo(text: str) -> dict[str, dict]:
    """Every instruction of the optimised HLO: name -> {op, shape, operands, calls, op_name, computation}."""
    out, computation = {}, None
    for line in text.splitlines():
        if line and not line.startswith(" ") and "{" in line:
            computation = line.split()[0 if not line.startswith("ENTRY") else 1].lstrip("%")
            continue
        m = _DEF.match(line)
        if not m:
            continue
        name, _, dims, op, rest = m.groups()
        operands = re.findall(r"%([\w.\-]+)", rest.split("),")[0])
        calls = _CALLS.search(rest)
        op_name = _OPNAME.search(rest)
        contract = _CONTRACT.search(rest)
        out[name] = {"op": op, "shape": [int(d) for d in dims.split(",") if d], "operands": operands,
                     "calls": calls.group(1) if calls else None, "op_name": op_name.group(1) if op_name else "",
                     "contract": [int(d) for d in contract.group(1).split(",") if d] if contract else None,
                     "computation": computation}
    return out


def dot_flops(hlo: dict[str, dict], name: str) -> float:
    """FLOPs of the dots in instruction `name` (itself a dot, or a fusion calling a computation with dots)."""
    ins = hlo[name]
    dots = [ins] if ins["op"] == "dot" else [i for i in hlo.values()
                                              if i["op"] == "dot" and i["computation"] == ins["calls"]]
    flops = 0.0
    for d in dots:
        lhs = hlo.get(d["operands"][0]) if d["operands"] else None
        k = math.prod(lhs["shape"][c] for c in d["contract"]) if lhs and d["contract"] is not None else 0
        flops += 2.0 * math.prod(d["shape"]) * k
    return flops


def part_of(hlo: dict[str, dict], name: str) -> str:
    """The part of the update an op belongs to (see the module doc), from its HLO and its metadata."""
    ins = hlo.get(name)
    if ins is None:
        return "other"
    if dot_flops(hlo, name) > 0:
        return "matmul"
    inner = [i for i in hlo.values() if i["computation"] == ins["calls"]] if ins["calls"] else []
    names = " ".join([ins["op_name"]] + [i["op_name"] for i in inner])
    ops = {ins["op"]} | {i["op"] for i in inner}
    if "LayerNorm" in names:
        return "layernorm"
    if re.search(r"threefry|random|_randint|_normal|_uniform", names) or ops & {"gather", "dynamic-slice"}:
        return "sampling"
    if re.search(r"/(relu|tanh|max)\b", names):
        return "activation"
    if "jvp(" in names or "loss" in names.lower():
        return "loss"
    return "update" if names.strip() else "other"


def program(algo_name: str, num_critics: int, transitions: int, updates: int):
    """(compiled chunk, its arguments, update calls per chunk, updates per call) for S = 1."""
    import jax
    import jax.numpy as jnp

    from benchmarks.common import ACT_DIM, OBS_DIM, synthetic_data
    from offrl_jax.algos import make_algorithm, make_config
    from offrl_jax.driver import Driver, make_chunk_fn

    extra = {"num_critics": num_critics} if algo_name == "edac" else {"alpha": 2.5}
    config = make_config(algo_name, "hopper", pretrain="none", **extra)
    algo = make_algorithm(config, OBS_DIM, ACT_DIM, transitions)
    driver = Driver(algo, synthetic_data(transitions), (0,))
    phase = next(p for p in algo.phases(updates * 4) if p.name == "offline_rl")
    calls = max(1, updates // phase.updates_per_call)
    states = driver.layout.place(driver.init())
    fn = make_chunk_fn(phase, 256, calls, layout=driver.layout)
    compiled = fn.lower(states, driver.data, driver.run_keys, jnp.int32(0)).compile()
    return compiled, (states, driver.data, driver.run_keys), calls, phase.updates_per_call, jax


def profile(algo_name: str = "td3bc", num_critics: int = 10, transitions: int = 100_000, updates: int = 1000) -> dict:
    compiled, (states, data, keys), calls, per_call, jax = program(algo_name, num_critics, transitions, updates)
    import jax.numpy as jnp

    hlo = parse_hlo(compiled.as_text())
    states, _ = compiled(states, data, keys, jnp.int32(0))  # warm-up
    jax.block_until_ready(states)
    with tempfile.TemporaryDirectory() as tmp:
        tic = time.perf_counter()
        with jax.profiler.trace(tmp, create_perfetto_trace=True):
            states, _ = compiled(states, data, keys, jnp.int32(calls * per_call))
            jax.block_until_ready(states)
        wall = time.perf_counter() - tic
        trace = next(Path(tmp).rglob("*.trace.json.gz"))
        events = json.load(gzip.open(trace))
    events = events["traceEvents"] if isinstance(events, dict) else events
    time_us, flops, count = collections.Counter(), collections.Counter(), collections.Counter()
    for e in events:
        if e.get("ph") != "X" or e.get("name") not in hlo or hlo[e["name"]]["op"] in ("while", "call", "conditional"):
            continue
        part = part_of(hlo, e["name"])
        time_us[part] += e.get("dur", 0)
        count[part] += 1
        if part == "matmul":
            flops[part] += dot_flops(hlo, e["name"])
    n_updates = calls * per_call
    total = sum(time_us.values())
    rows = []
    for part in PARTS:
        if count[part]:
            rows.append({"part": part, "ms_per_update": time_us[part] / 1e3 / n_updates,
                         "share": time_us[part] / total, "ops_per_update": count[part] / n_updates,
                         "gflops": flops[part] / time_us[part] / 1e3 if flops[part] else None})
    return {"algo": algo_name, "num_critics": num_critics if algo_name == "edac" else 2, "updates": n_updates,
            "wall_s": wall, "traced_op_ms_per_update": total / 1e3 / n_updates,
            "updates_per_s_traced": n_updates / wall, "parts": rows}


def table(result: dict) -> str:
    lines = [f"{result['algo']} (N = {result['num_critics']}), {result['updates']} updates traced: "
             f"{result['updates_per_s_traced']:.1f} updates/s under the profiler, "
             f"{result['traced_op_ms_per_update']:.2f} ms of XLA ops per update",
             "| part | ms / update | share | ops / update | GFLOP/s |", "|---|--:|--:|--:|--:|"]
    for r in result["parts"]:
        rate = f"{r['gflops']:.0f}" if r["gflops"] else ""
        lines.append(f"| {r['part']} | {r['ms_per_update']:.3f} | {100 * r['share']:.0f} % | "
                     f"{r['ops_per_update']:.0f} | {rate} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = OneLineParser(prog="python -m benchmarks.profile", description=__doc__.split("\n\n")[0],
                      formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--algo", choices=("td3bc", "edac"), default="td3bc",
                   help="algorithm whose offline-RL update is traced (default %(default)s)")
    p.add_argument("--num-critics", type=positive_int, default=10, help="EDAC's ensemble size (default 10)")
    p.add_argument("--updates", type=positive_int, default=1000, help="updates in the traced chunk (default 1000)")
    p.add_argument("--transitions", type=positive_int, default=100_000, help="rows of the synthetic dataset")
    p.add_argument("--json", action="store_true", help="one JSON object on stdout instead of the table")
    p.add_argument("--out", help="also append the JSON object to results/benchmarks/OUT.jsonl (or OUT if a path)")
    args = p.parse_args(argv)
    if args.num_critics != 10 and args.algo != "edac":
        p.error("--num-critics is EDAC's ensemble size; TD3+BC has two critics")
    from benchmarks.common import append_results, results_path

    out_path = results_path(p, args.out)  # checked writable before the work
    print(f"compiling and tracing {args.algo} ...", file=sys.stderr, flush=True)
    result = profile(args.algo, args.num_critics, args.transitions, args.updates)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    result |= {"xla_flags": os.environ.get("XLA_FLAGS", ""), "command": "python -m benchmarks.profile " +
               " ".join(sys.argv[1:] if argv is None else argv), "commit": commit or None,
               "date": time.strftime("%Y-%m-%dT%H:%M:%S")}
    print(json.dumps(result) if args.json else table(result))
    if out_path is not None:
        append_results(out_path, [result])
        print(f"appended to {out_path}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    from offrl_jax.system.cli import run_main

    run_main(main)
