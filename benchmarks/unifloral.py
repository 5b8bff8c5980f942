"""Our TD3+BC update against unifloral's TD3+BC train step, timed alternately in one process.

    python -m benchmarks.unifloral --unifloral PATH [--transitions N] [--updates K] [--pairs P] [--json] [--out NAME]

PATH is a checkout of github.com/EmptyJackson/unifloral; its `algorithms/td3_bc.py` is imported from there, never
copied here.  It needs `pip install distrax`; `d4rl` and `gym` (used only by its `__main__` block and its evaluation)
get empty stand-in modules for the import, as do `wandb` and `tyro` when they are not installed, and the XLA_FLAGS
that their module sets at import are put back to the caller's.

Matched settings:
  * theirs: their `Args()` defaults unchanged (batch 256, lr 3e-4, alpha 2.5, gamma 0.99, 2 critic updates per
    step), their `DualQNetwork`, `DeterministicTanhActor`, `create_train_state` and `make_train_step`, run as their
    main loop runs it, `lax.scan` of `_train_step` over the steps of a chunk, jitted (state donated; the dataset is
    an argument of the jitted function rather than a closed-over constant).  One of their steps = 2 critic updates
    + 1 actor update + the target updates;
  * ours: `make_config("td3bc", "hopper", alpha=2.5)` offline RL through the driver's own chunk function
    (`make_chunk_fn`, S = 1, placed by `member_layout` as `Driver` does); one call = policy_delay (2) critic
    updates + 1 actor update + the target updates, the same work as one of their steps;
  * both: 2x256 actor and twin critics, LayerNorm after every hidden Dense, before the ReLU (ours by default;
    theirs by swapping their module's global `nn` for a proxy of flax.linen whose `relu` is LayerNorm then ReLU,
    their file untouched); `--no-layer-norm` times both without it;
  * the same synthetic hopper-shaped dataset (obs 11, act 3, `--transitions` rows, `benchmarks.throughput`);
  * the same K = `--updates` critic updates per timed chunk.  Both are compiled and run once first, then timed
    alternately (ours, theirs, ours, ...) for `--pairs` pairs, so both see the same background load.

Reported: critic updates per second (theirs 2 x steps/s, ours 2 x calls/s), the median of each over the pairs, and
the ratio ours / unifloral.  The caller chooses the cores; the two canonical runs:

    taskset -c 0 env XLA_FLAGS=--xla_cpu_multi_thread_eigen=false python -m benchmarks.unifloral --unifloral PATH
    python -m benchmarks.unifloral --unifloral PATH                        # every core, XLA's default threads

A table goes to stdout (with --json: one JSON object), progress to stderr; `--out NAME` also appends the JSON object
to results/benchmarks/NAME.jsonl (or to NAME if it is a path).
"""
from __future__ import annotations

import importlib.util
import json
import os
import statistics
import subprocess
import sys
import time
import types
from pathlib import Path

import flax.linen
import jax
import jax.numpy as jnp

from benchmarks.common import ACT_DIM, BATCH, OBS_DIM, append_results, results_path, synthetic_data
from offrl_jax.algos import make_algorithm, make_config
from offrl_jax.driver import CHUNK, INIT, make_chunk_fn, member_layout, seed_keys
from offrl_jax.system.cli import OneLineParser, positive_int

MODULE = "unifloral_td3_bc"  # the name their imported td3_bc.py gets in sys.modules


def log(*args) -> None:
    print(*args, file=sys.stderr, flush=True)


class _LinenWithLayerNorm:
    """flax.linen, except that `relu(x)` is `relu(LayerNorm()(x))`: our networks' hidden layers, in their modules."""

    def __init__(self, linen):
        self._linen = linen

    def __getattr__(self, name):
        return getattr(self._linen, name)

    def relu(self, x):
        return self._linen.relu(self._linen.LayerNorm()(x))


def load_unifloral(path: Path, layer_norm: bool) -> types.ModuleType:
    """Import `path`/algorithms/td3_bc.py with stand-ins for the imports only its `__main__` block and evaluation use;
    the caller's XLA_FLAGS and sys.modules are restored afterwards."""
    stand_ins = {name: types.ModuleType(name) for name in ("d4rl", "gym")}
    stand_ins |= {name: types.ModuleType(name) for name in ("wandb", "tyro") if importlib.util.find_spec(name) is None}
    saved_modules = {name: sys.modules.get(name) for name in stand_ins}
    saved_flags = os.environ.get("XLA_FLAGS")
    sys.modules.update(stand_ins)
    spec = importlib.util.spec_from_file_location(MODULE, path / "algorithms" / "td3_bc.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[MODULE] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[MODULE]
        raise
    finally:
        for name, old in saved_modules.items():
            if old is None:
                del sys.modules[name]
            else:
                sys.modules[name] = old
        if saved_flags is None:
            os.environ.pop("XLA_FLAGS", None)
        else:
            os.environ["XLA_FLAGS"] = saved_flags
    missing = [name for name in ("Args", "AgentTrainState", "Transition", "DualQNetwork", "DeterministicTanhActor",
                                 "create_train_state", "make_train_step") if not hasattr(module, name)]
    if missing:
        raise ImportError(f"it has no {', '.join(missing)} (a different version of unifloral?)")
    if layer_norm:
        module.nn = _LinenWithLayerNorm(flax.linen)
    return module


def ours(data, updates: int, layer_norm: bool):
    """A function that runs and times one chunk of `updates` critic updates of our TD3+BC (S = 1, driver chunk fn)."""
    config = make_config("td3bc", "hopper", alpha=2.5, pretrain="none", actor_layer_norm=layer_norm,
                         critic_layer_norm=layer_norm)
    algo = make_algorithm(config, OBS_DIM, ACT_DIM, int(data["rewards"].shape[0]))
    (phase,) = algo.phases(updates)
    calls = updates // phase.updates_per_call
    layout = member_layout(1)
    state = {"s": layout.place(jax.jit(jax.vmap(algo.init))(seed_keys((0,), INIT))), "i": 0}
    keys = layout.place(seed_keys((0,), CHUNK))
    data = jax.device_put(data, layout.replicated)
    compiled = make_chunk_fn(phase, BATCH, calls, layout=layout).lower(state["s"], data, keys, jnp.int32(0)).compile()

    def run() -> float:
        tic = time.perf_counter()
        state["s"], metrics = compiled(state["s"], data, keys, jnp.int32(state["i"] * updates))
        jax.block_until_ready((state["s"], metrics))
        state["i"] += 1
        return time.perf_counter() - tic

    return run


def theirs(module, data, updates: int):
    """The same for unifloral: jit(lax.scan of their `_train_step`) over updates / 2 steps, their runner state."""
    args = module.Args()
    steps = updates // args.num_critic_updates_per_step
    dataset = module.Transition(obs=data["observations"], action=data["actions"], reward=data["rewards"],
                                next_obs=data["next_observations"], done=data["terminals"])
    obs_mean, obs_std = dataset.obs.mean(axis=0), jnp.nan_to_num(dataset.obs.std(axis=0), nan=1.0)
    actor_net = module.DeterministicTanhActor(ACT_DIM, obs_mean, obs_std)
    q_net = module.DualQNetwork(obs_mean, obs_std)
    rng, rng_actor, rng_q = jax.random.split(jax.random.PRNGKey(args.seed), 3)
    obs, act = jnp.zeros(OBS_DIM), jnp.zeros(ACT_DIM)
    agent_state = module.AgentTrainState(
        actor=module.create_train_state(args, rng_actor, actor_net, [obs]),
        actor_target=module.create_train_state(args, rng_actor, actor_net, [obs]),
        dual_q=module.create_train_state(args, rng_q, q_net, [obs, act]),
        dual_q_target=module.create_train_state(args, rng_q, q_net, [obs, act]),
    )

    def chunk(runner_state, dataset):
        train_step = module.make_train_step(args, actor_net.apply, q_net.apply, dataset)
        return jax.lax.scan(train_step, runner_state, None, length=steps)

    state = {"s": (rng, agent_state)}
    compiled = jax.jit(chunk, donate_argnums=0).lower(state["s"], dataset).compile()

    def run() -> float:
        tic = time.perf_counter()
        state["s"], losses = compiled(state["s"], dataset)
        jax.block_until_ready((state["s"], losses))
        return time.perf_counter() - tic

    return run


def _commit(path: Path) -> str | None:
    """The checkout's commit (None when it is not a git checkout)."""
    try:
        out = subprocess.run(["git", "-C", str(path), "rev-parse", "HEAD"], capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.TimeoutExpired):
        return None
    return (out.stdout.strip() or None) if out.returncode == 0 else None


def main(argv: list[str] | None = None) -> dict:
    p = OneLineParser(prog="python -m benchmarks.unifloral", description=__doc__.split("\n\n")[0])
    p.add_argument("--unifloral", required=True, type=Path, metavar="PATH",
                   help="a checkout of github.com/EmptyJackson/unifloral (its algorithms/td3_bc.py is imported)")
    p.add_argument("--transitions", type=positive_int, default=1_000_000, help="synthetic dataset rows (%(default)s)")
    p.add_argument("--updates", type=positive_int, default=2000, help="critic updates per timed chunk, even "
                   "(default %(default)s)")
    p.add_argument("--pairs", type=positive_int, default=5, help="timed chunks of each, alternated (%(default)s)")
    p.add_argument("--no-layer-norm", dest="layer_norm", action="store_false",
                   help="both without LayerNorm (default: LayerNorm after every hidden layer of both)")
    p.add_argument("--json", action="store_true", help="one JSON object on stdout instead of a table")
    p.add_argument("--out", help="also append the JSON object to results/benchmarks/OUT.jsonl (or OUT if a path)")
    args = p.parse_args(argv)

    if not (args.unifloral / "algorithms" / "td3_bc.py").is_file():
        p.error(f"{args.unifloral}: no algorithms/td3_bc.py there (--unifloral takes a checkout of "
                "github.com/EmptyJackson/unifloral)")
    if args.updates % 2:
        p.error(f"--updates {args.updates} must be even (one TD3+BC step = 2 critic updates)")
    if not (args.unifloral / "algorithms" / "td3_bc.py").is_file():
        p.error(f"{args.unifloral}: not a unifloral checkout (no algorithms/td3_bc.py)")
    if importlib.util.find_spec("distrax") is None:
        p.error("unifloral's td3_bc.py imports distrax, which is not installed: pip install distrax")
    out_path = results_path(p, args.out)

    jax.devices()  # the backend starts now, with the caller's XLA_FLAGS, whatever their import sets
    try:
        module = load_unifloral(args.unifloral, args.layer_norm)
    except (Exception, SystemExit) as e:  # whatever their import raises (or exits with): one line
        p.error(f"{args.unifloral / 'algorithms' / 'td3_bc.py'}: cannot be imported ({type(e).__name__}: {e})")
    if module.Args().num_critic_updates_per_step != 2:
        p.error(f"their Args().num_critic_updates_per_step is {module.Args().num_critic_updates_per_step}, not 2: "
                "this benchmark matches it to our policy_delay 2")

    xla_flags = os.environ.get("XLA_FLAGS", "")
    cores = len(os.sched_getaffinity(0))
    ln = "on" if args.layer_norm else "off"
    log(f"# jax {jax.__version__}, {cores} cores, XLA_FLAGS={xla_flags!r}, LayerNorm {ln}")
    data = synthetic_data(args.transitions)
    runners = {}
    for name, make in (("ours", lambda: ours(data, args.updates, args.layer_norm)),
                       ("unifloral", lambda: theirs(module, data, args.updates))):
        tic = time.perf_counter()
        runners[name] = make()
        compile_s = time.perf_counter() - tic
        log(f"# {name}: compiled in {compile_s:.1f} s, warm-up chunk {runners[name]():.2f} s")
    rates = {name: [] for name in runners}
    for i in range(args.pairs):
        for name, run in runners.items():
            rates[name].append(args.updates / run())
        log(f"pair {i + 1}/{args.pairs}: ours {rates['ours'][-1]:.1f}, unifloral {rates['unifloral'][-1]:.1f} "
            "critic updates/s")
    median = {name: statistics.median(r) for name, r in rates.items()}
    result = {"ours_updates_per_s": round(median["ours"], 2),
              "unifloral_updates_per_s": round(median["unifloral"], 2),
              "ratio": round(median["ours"] / median["unifloral"], 3), "pairs": args.pairs,
              "layer_norm": args.layer_norm, "transitions": args.transitions, "updates_per_chunk": args.updates,
              "xla_flags": xla_flags, "cores": cores, "jax": jax.__version__,
              "ours_rates": [round(r, 2) for r in rates["ours"]],
              "unifloral_rates": [round(r, 2) for r in rates["unifloral"]],
              "unifloral_commit": _commit(args.unifloral), "load1": round(os.getloadavg()[0], 2)}
    if args.json:
        print(json.dumps(result), flush=True)
    else:
        print(f"{'':<10} {'critic updates/s':>17}   (median of {args.pairs} chunks of {args.updates}, "
              f"LayerNorm {ln}, {cores} cores)")
        print(f"{'ours':<10} {result['ours_updates_per_s']:>17.1f}")
        print(f"{'unifloral':<10} {result['unifloral_updates_per_s']:>17.1f}")
        print(f"{'ratio':<10} {result['ratio']:>17.2f}   ours / unifloral")
    if out_path is not None:
        append_results(out_path, [result])
        log(f"# appended to {out_path}")
    return result


if __name__ == "__main__":
    from offrl_jax.system.cli import run_main

    run_main(main)
