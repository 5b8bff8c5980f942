"""Env steps/s of the online phase at utd 1 against the same family's offline updates/s, in one process.

    python -m benchmarks.online [--algo A ...] [--seeds S ...] [--block K] [--steps N] [--json] [--quick] [--out NAME]

For each family and each S seeds (the member axis), on the synthetic hopper-shaped dataset of `benchmarks.throughput`
and S real hopper environments, back to back:

    offline   the family's offline-RL phase through `Driver.run` in chunks of K updates (a block's worth at utd 1);
              one warm-up chunk (compilation), then N / K - 1 timed chunks
    online    `run_online` at utd 1 for N env steps per member in blocks of K (no warm-up steps, no evaluation
              episodes); the first block (compilation) is not timed
    split     the same online phase again with timing shims around its pieces (this module only: the library runs
              unchanged), first block not timed
    offline   N / K - 1 more timed chunks: the offline rate is that of all timed chunks, before and after

At utd 1 one env step of a member is one update of that member, so the goal reads online_env_steps_per_s >= 70 % of
offline_updates_per_s (both summed over the S members).  The split, in microseconds per env step of one member (at
utd 1: per update; a cost paid once per step for all members, as the policy call, is divided by S):

    env_step     MuJoCo: the gymnasium env's `step`                  env_reset   its `reset`, when an episode ended
    policy       the jitted action call for all members (dispatch, S observations in, S actions out)
    bookkeeping  the rest of `MemberEnvs.step` (checks, copies, episode returns)
    stack        the rest of `collect` (its loop, stacking the block)
    insert       `device_rows` and the buffer `insert` (waited for)
    update       the scan of K updates per member (waited for)
    other        the rest of a block: placing the rows, the metrics to the host, the yield

Also: `policy_probe`, microseconds per policy call in a loop of calls alone: as `run_online` calls it (every leaf of
the agent state passed), given only the actor's parameters, and a trivial jitted function of the observations (the
floor); `compiles_in_timed_blocks`, XLA compilations after the first block of each online pass (0: nothing is
recompiled per block).
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import datetime
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import jax
import numpy as np

from benchmarks.common import ACT_DIM, BATCH, OBS_DIM, append_results, log, machine, results_path, synthetic_dataset
from offrl_jax.algos import ALGOS, make_algorithm, make_config
from offrl_jax.data.device import device_data
from offrl_jax.driver import Driver
from offrl_jax.envs.registry import make_env
from offrl_jax.online import loop
from offrl_jax.online.config import OnlineConfig
from offrl_jax.online.envs import exploration_keys, exploration_policy
from offrl_jax.system.cli import OneLineParser, positive_int

ENV = "hopper"
PIECES = ("env_step", "env_reset", "policy", "bookkeeping", "stack", "insert", "update", "other")
ONLINE_ALGOS = sorted(a for a in ALGOS if a != "bc")  # bc has no critic to fine-tune
COMPILES = [0]  # XLA compilations in this process so far (`count_compiles`)


def count_compiles() -> None:
    """Count every XLA compilation into COMPILES (once per process): a timed block must have none."""
    if not getattr(count_compiles, "on", False):
        jax.monitoring.register_event_duration_secs_listener(
            lambda event, _, **__: COMPILES.__setitem__(0, COMPILES[0] + (event.endswith("backend_compile_duration"))))
        count_compiles.on = True


class TimedEnv(gym.Wrapper):
    """The env, its `step` and `reset` timed into `timers`."""

    def __init__(self, env, timers: dict[str, float]):
        super().__init__(env)
        self.timers = timers

    def step(self, action):
        tic = time.perf_counter()
        out = self.env.step(action)
        self.timers["env_step"] += time.perf_counter() - tic
        return out

    def reset(self, **kwargs):
        tic = time.perf_counter()
        out = self.env.reset(**kwargs)
        self.timers["env_reset"] += time.perf_counter() - tic
        return out


def _timed(timers: dict[str, float], name: str, fn, wait: bool = False):
    def call(*args, **kwargs):
        tic = time.perf_counter()
        out = fn(*args, **kwargs)
        if wait:
            out = jax.block_until_ready(out)
        timers[name] += time.perf_counter() - tic
        return out

    call.untimed = fn
    return call


@contextlib.contextmanager
def shims(driver: Driver, timers: dict[str, float]):
    """`run_online`'s pieces timed into `timers` (seconds, accumulated) while inside; everything restored after.
    `collect` and `MemberEnvs.step` are timed whole: their own share is what is left after the pieces inside them."""
    names = ("collect", "exploration_policy", "device_rows", "insert", "MemberEnvs")
    real = {n: getattr(loop, n) for n in names}

    class TimedMemberEnvs(real["MemberEnvs"]):
        step = _timed(timers, "member_step", real["MemberEnvs"].step)

    def policy(*args, **kwargs):
        act = real["exploration_policy"](*args, **kwargs)
        return _timed(timers, "policy", lambda *a: np.asarray(act(*a)))

    loop.collect = _timed(timers, "collect", real["collect"])
    loop.exploration_policy = policy
    loop.device_rows = _timed(timers, "insert", real["device_rows"])
    loop.insert = _timed(timers, "insert", real["insert"], wait=True)
    loop.MemberEnvs = TimedMemberEnvs
    for key, fn in driver._chunk_fns.items():  # the online scan compiled by an earlier pass
        if key[0] == "online":
            driver._chunk_fns[key] = _timed(timers, "update", fn, wait=True)
    try:
        yield
    finally:
        for n, fn in real.items():
            setattr(loop, n, fn)
        for key, fn in driver._chunk_fns.items():
            driver._chunk_fns[key] = getattr(fn, "untimed", fn)


def offline_chunks(driver: Driver, algo, states, block: int, chunks: int) -> tuple[Any, list[float]]:
    """`chunks` chunks of `block` offline-RL updates through `Driver.run`: (states, each chunk's seconds)."""
    phase = dataclasses.replace(algo.phases(block)[-1], steps=block * chunks)
    seconds, last = [], None
    for chunk in driver.run([phase], block, states=states):
        seconds.append(block / chunk.updates_per_s)
        last = chunk
    return jax.device_get(last.states), seconds


def online_blocks(driver: Driver, algo, form, states, online: OnlineConfig, offline_updates: int,
                  make=None, timers: dict[str, float] | None = None) -> tuple[Any, list[dict[str, float]]]:
    """`run_online` at `online`: (states, per block its seconds, its ended episodes and, with `timers`, the pieces'
    seconds in it)."""
    blocks, before, last = [], dict(timers or {}), None
    for chunk in loop.run_online(driver, algo, online, ENV, form, states, offline_updates, 0.0, make_env=make):
        row = {"seconds": online.block / chunk.updates_per_s, "episodes": float(chunk.metrics["train_episodes"].sum()),
               "compiles": COMPILES[0]}
        if timers is not None:
            row |= {k: timers[k] - before.get(k, 0.0) for k in timers}
            before = dict(timers)
        blocks.append(row)
        last = chunk
    return jax.device_get(last.states), blocks


def policy_probe(driver: Driver, algo, form, states, calls: int = 300, rounds: int = 3) -> dict[str, Any]:
    """Microseconds per call, the median of `rounds` alternated runs of `calls`: the online policy as `run_online`
    calls it (every leaf of the agent state passed), the same given only the actor's parameters (None where the
    family's policy reads more), and a trivial jitted function of the observations (the floor: dispatch, S
    observations in and S actions out)."""
    members = len(driver.members)
    explore = exploration_policy(algo.act, form.obs_mean, form.obs_std, algo.cfg.explore_noise,
                                 algo.explore)
    keys, obs = exploration_keys(driver.members), np.zeros((members, OBS_DIM), np.float32)
    placed = driver.layout.place(states)
    actor = placed.replace(**{f.name: None for f in dataclasses.fields(placed) if f.name != "actor"},
                           actor=placed.actor.replace(opt_state=None, target=None))
    floor = jax.jit(lambda o: o[:, :ACT_DIM])
    calls_of = {"policy_us": lambda t: explore(placed, keys, obs, t),
                "policy_actor_only_us": lambda t: explore(actor, keys, obs, t), "floor_us": lambda t: floor(obs)}
    try:
        same = np.asarray(explore(actor, keys, obs, 0)), np.asarray(explore(placed, keys, obs, 0))
        np.testing.assert_array_equal(*same)
    except (AttributeError, TypeError, AssertionError):  # the family's policy reads more than the actor's parameters
        del calls_of["policy_actor_only_us"]
    times = {k: [] for k in calls_of}
    for _ in range(rounds):
        for k, call in calls_of.items():
            np.asarray(call(0))
            tic = time.perf_counter()
            for t in range(calls):
                np.asarray(call(t))
            times[k].append(1e6 * (time.perf_counter() - tic) / calls)
    return {k: round(float(np.median(times[k])), 1) if k in times else None for k in
            ("policy_us", "policy_actor_only_us", "floor_us")} | {"state_leaves": len(jax.tree.leaves(placed))}


def split(blocks: list[dict[str, float]], steps: int) -> dict[str, float]:
    """Microseconds per env step of one member of every piece, summed over `blocks` (`steps`: env steps of all
    members in them)."""
    total = {k: sum(b[k] for b in blocks) for k in blocks[0]}
    us = {"env_step": total["env_step"], "env_reset": total["env_reset"], "policy": total["policy"],
          "bookkeeping": total["member_step"] - total["env_step"] - total["env_reset"],
          "stack": total["collect"] - total["member_step"] - total["policy"],
          "insert": total["insert"], "update": total["update"]}
    us["other"] = total["seconds"] - sum(us.values())
    return {k: round(1e6 * us[k] / steps, 1) for k in PIECES}


def run_case(name: str, seeds: int, dataset, block: int, steps: int) -> dict[str, Any]:
    config = make_config(name, ENV, pretrain="none")
    form = device_data(dataset, config.gamma)
    algo = make_algorithm(config, OBS_DIM, ACT_DIM, int(form.arrays["rewards"].shape[0]))
    driver = Driver(algo, form.arrays, tuple(range(seeds)), batch_size=BATCH)
    chunks = steps // block - 1
    online = OnlineConfig(steps=steps, block=block, utd=1, eval_every=block)
    states, before = offline_chunks(driver, algo, None, block, chunks + 1)
    done = block * (chunks + 1)
    states, plain = online_blocks(driver, algo, form, states, online, done)
    timers = dict.fromkeys(("env_step", "env_reset", "policy", "member_step", "collect", "insert", "update"), 0.0)
    make = lambda: TimedEnv(make_env(ENV, disable_env_checker=True), timers)  # noqa: E731
    with shims(driver, timers):
        states, shimmed = online_blocks(driver, algo, form, states, online, done, make, timers)
    states, after = offline_chunks(driver, algo, states, block, chunks)
    probe = policy_probe(driver, algo, form, states)
    offline_s = before[1:] + after
    timed_steps = seeds * block * chunks
    offline = seeds * block * len(offline_s) / sum(offline_s)
    online_rate = timed_steps / sum(b["seconds"] for b in plain[1:])
    us = split(shimmed[1:], timed_steps)
    total_us = sum(us.values())
    return {
        "algo": name, "seeds": seeds, "block": block, "steps": steps, "timed_blocks": chunks,
        "offline_updates_per_s": round(offline, 2),
        "offline_before_updates_per_s": round(seeds * block * chunks / sum(before[1:]), 2),
        "offline_after_updates_per_s": round(seeds * block * chunks / sum(after), 2),
        "online_env_steps_per_s": round(online_rate, 2),
        "pct_of_offline": round(100 * online_rate / offline, 1),
        "split_env_steps_per_s": round(timed_steps / sum(b["seconds"] for b in shimmed[1:]), 2),
        "scan_updates_per_s": round(1e6 / us["update"], 2),
        "split_us_per_step": us,
        "split_pct": {k: round(100 * v / total_us, 1) for k, v in us.items()},
        "host_us_per_step": round(total_us - us["update"], 1),
        "episodes_per_1000_steps": round(1000 * sum(b["episodes"] for b in plain[1:]) / timed_steps, 2),
        "policy_probe": probe,
        "compile_block_s": round(plain[0]["seconds"], 2),
        "block_s": [round(b["seconds"], 2) for b in plain[1:]],
        "split_block_s": [round(b["seconds"], 2) for b in shimmed[1:]],
        "compiles_in_timed_blocks": plain[-1]["compiles"] - plain[0]["compiles"] + shimmed[-1]["compiles"]
        - shimmed[0]["compiles"],
        "devices": driver.layout.mesh.size, "members_mode": driver.layout.mode,
        "load1": round(os.getloadavg()[0], 2),
    }


def format_row(r: dict[str, Any]) -> str:
    us = r["split_us_per_step"]
    return (f"{r['algo']:<8} {r['seeds']:>2} {r['offline_updates_per_s']:>9.1f} {r['online_env_steps_per_s']:>9.1f} "
            f"{r['pct_of_offline']:>6.1f} " + " ".join(f"{us[k]:>8.0f}" for k in PIECES) + f" {r['load1']:>5.2f}")


HEADER = (f"{'algo':<8} {'S':>2} {'offl/s':>9} {'steps/s':>9} {'%offl':>6} "
          + " ".join(f"{k[:8]:>8}" for k in PIECES) + f" {'load':>5}     (split: us per env step of a member)")


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    p = OneLineParser(prog="python -m benchmarks.online", description=__doc__.split("\n\n")[0],
                      formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--algo", nargs="+", choices=ONLINE_ALGOS, metavar="ALGO",
                   help="registry names: %(choices)s (default: td3bc iql)")
    p.add_argument("--seeds", nargs="+", type=positive_int, help="seed counts on the member axis (default 1 5)")
    p.add_argument("--block", type=positive_int, help="env steps per block, and offline updates per chunk "
                   "(default 1000)")
    p.add_argument("--steps", type=positive_int, help="online env steps per member of each online pass, a multiple "
                   "of the block and at least 2 blocks: the first is not timed (default 5000)")
    p.add_argument("--transitions", type=positive_int, help="rows of the synthetic dataset (default 100000)")
    p.add_argument("--json", action="store_true", help="one JSON object per case on stdout")
    p.add_argument("--quick", action="store_true", help="a smoke test: TD3+BC, S=1, blocks of 100 steps, 300 steps, "
                   "10k rows; takes none of the case and size flags")
    p.add_argument("--cpu-sync-dispatch", action="store_true",
                   help="run CPU computations inline in the calling thread (jax_cpu_enable_async_dispatch = False; "
                        "takes effect in a fresh process only): the policy call per step then skips a hand-off to "
                        "XLA's thread")
    p.add_argument("--out", help="also append the JSON lines to results/benchmarks/OUT.jsonl (or OUT if it is a path)")
    args = p.parse_args(argv)
    sizes = {"--algo": args.algo, "--seeds": args.seeds, "--block": args.block, "--steps": args.steps,
             "--transitions": args.transitions}
    if args.quick:
        given = [flag for flag, value in sizes.items() if value is not None]
        if given:
            p.error(f"--quick runs one fixed tiny case, so it takes no {', '.join(given)}; drop --quick to choose")
        algos, seed_counts, block, steps, transitions = ["td3bc"], [1], 100, 300, 10_000
    else:
        algos, seed_counts = args.algo or ["td3bc", "iql"], args.seeds or [1, 5]
        block, steps, transitions = args.block or 1000, args.steps or 5000, args.transitions or 100_000
    if steps % block or steps < 2 * block:
        p.error(f"--steps ({steps}) must be a multiple of --block ({block}) and at least 2 blocks (the first one "
                "compiles and is not timed)")
    bad = [a for a in algos if block % make_algorithm(make_config(a, ENV, pretrain="none"), OBS_DIM, ACT_DIM, 1)
           .phases(2)[-1].updates_per_call]
    if bad:
        p.error(f"--block ({block}) must be a multiple of {', '.join(bad)}'s updates per call (the policy delay, 2)")
    out_path = results_path(p, args.out)
    if args.cpu_sync_dispatch:
        jax.config.update("jax_cpu_enable_async_dispatch", False)

    meta = {"command": " ".join([Path(sys.executable).name, "-m", "benchmarks.online", *sys.argv[1:]]),
            "date": datetime.datetime.now().isoformat(timespec="seconds"), "machine": machine(),
            "cores": sorted(os.sched_getaffinity(0)), "load_avg": [round(x, 2) for x in os.getloadavg()],
            "xla_flags": os.environ.get("XLA_FLAGS", ""),
            "cpu_async_dispatch": bool(jax.config.read("jax_cpu_enable_async_dispatch"))}
    log(f"# {meta['date']}  {meta['machine']}  cores {meta['cores']}  load {meta['load_avg']}  "
        f"XLA_FLAGS={meta['xla_flags']!r}")
    start = time.perf_counter()
    count_compiles()
    dataset = synthetic_dataset(transitions)
    if not args.json:
        print(HEADER, flush=True)
    results = []
    for name in algos:
        for s in seed_counts:
            r = run_case(name, s, dataset, block, steps)
            results.append(r)
            log(f"[{time.perf_counter() - start:6.1f}s] {name} S={s}: offline {r['offline_updates_per_s']:.1f} "
                f"updates/s, online {r['online_env_steps_per_s']:.1f} env steps/s = {r['pct_of_offline']:.1f} %, "
                f"load {r['load1']}")
            print(json.dumps(r) if args.json else format_row(r), flush=True)
    meta["seconds"] = round(time.perf_counter() - start, 1)
    log(f"# done in {meta['seconds']}s")
    if out_path is not None:
        append_results(out_path, [{"meta": meta}, *results])
        log(f"# appended to {out_path}")
    return results


if __name__ == "__main__":
    from offrl_jax.system.cli import run_main

    run_main(main)
