"""ajax-rl's TD3+BC (ajax-rl 0.4.0, PyPI `ajax-rl`), timed as its own jitted training scan runs it.

    PYTHON benchmarks/adapters/ajax_rl_td3bc.py [--transitions N] [--updates K] [--repeats R] [--seeds S]

PYTHON: an interpreter (Python >= 3.12) with `ajax-rl` installed.  One JSON line per repeat on stdout.

What is built (everything from the installed package, nothing copied):
  * ajax.agents.TD3.TD3.TD3 with the ImitationLoss extension
    (ajax.extensions.expert.ImitationLoss(target="replay", alpha=2.5)), which its own docstring
    (extensions/expert.py:264-277) declares to be TD3+BC when trained with train_offline and
    normalize_observations=True.
  * ajax.buffers.dataset.TransitionDataset holds the synthetic rows.
  * A minimal gymnax Environment stub (obs 11, action Box(-1, 1, (3,))) only gives ajax the shapes:
    offline training never steps it, and without a logging config the evaluation is not traced.

How it is timed (the way ajax's own training runs):
  ActorCritic.train (agents/base.py:410-525) vmaps the jitted train function that
  TrainLoop.offline builds (agents/loop.py:723-762, perf_utils.py:90-128) over the seeds; each scan
  iteration is one `update_agent` (agents/TD3/train_TD3.py:345-405): one critic step, and an actor
  step + Polyak updates every policy_delay-th iteration. So one scan iteration = one critic update.
  1. setup (not timed as updates): agent.train_offline(dataset, n_updates=1) builds the
     fresh per-seed states and fills their replays with the dataset (fill_replay: a lax.scan of N adds).
  2. the K-update train function is built once with the agent's make_train (as ActorCritic.train
     does) and called on the resume path (resume_from_state=True, as ActorCritic.train does for an
     initial_state), vmapped over the seeds: only the K-iteration scan runs, no init, no replay fill.
  3. jit(vmap(resume)) is compiled ahead of time (lower().compile(): compile_s = trace + lower + compile,
     no update run); ajax's persistent compile cache (ajax/_compile_cache.py) is switched off
     (AJAX_NO_COMPILE_CACHE=1) unless --compile-cache.
     One untimed call, then each repeat times one call, jax.block_until_ready on the returned state.
  Excluded: evaluation and logging (logging_config=None: ajax.log.evaluate_and_log returns before
  tracing the evaluation, log.py:278-279; no W&B/TensorBoard worker is started), the replay fill.
  Included (ajax's loop does them every update): the flashbax replay sample, in-agent observation
  normalisation, the extension fold (one key split per update), the n_updates/timestep counters.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from importlib.metadata import version

if "--compile-cache" not in sys.argv:
    # ajax/__init__.py imports ajax/_compile_cache.py, which turns on a persistent XLA cache in
    # ~/.cache/ajax (min compile time 0): a warm cache would hide the compile time. Off unless asked.
    os.environ.setdefault("AJAX_NO_COMPILE_CACHE", "1")

import jax
import jax.numpy as jnp
import numpy as np
from ajax.agents.base import shared_counters, with_shared_counters
from ajax.agents.TD3.TD3 import TD3
from ajax.buffers.dataset import TransitionDataset
from ajax.extensions.expert import ImitationLoss
from flax import struct
from gymnax.environments import environment, spaces

OBS_DIM, ACT_DIM = 11, 3


@struct.dataclass
class StubParams(environment.EnvParams):
    max_steps_in_episode: int = 1000


@struct.dataclass
class StubState(environment.EnvState):
    time: int = 0


class HopperShapedStub(environment.Environment):
    """Shapes only (obs 11, actions in [-1, 1]^3); offline training never steps it."""

    @property
    def default_params(self) -> StubParams:
        return StubParams()

    def step_env(self, key, state, action, params):
        obs = jnp.zeros((OBS_DIM,), jnp.float32)
        new = StubState(time=state.time + 1)
        done = new.time >= params.max_steps_in_episode
        return obs, new, jnp.float32(0.0), done, {"discount": 1.0 - done}

    def reset_env(self, key, params):
        return jnp.zeros((OBS_DIM,), jnp.float32), StubState(time=0)

    def get_obs(self, state, params=None, key=None):
        return jnp.zeros((OBS_DIM,), jnp.float32)

    def is_terminal(self, state, params):
        return state.time >= params.max_steps_in_episode

    @property
    def name(self) -> str:
        return "HopperShapedStub-v0"

    @property
    def num_actions(self) -> int:
        return ACT_DIM

    def action_space(self, params=None):
        return spaces.Box(-1.0, 1.0, (ACT_DIM,), jnp.float32)

    def observation_space(self, params=None):
        return spaces.Box(-jnp.inf, jnp.inf, (OBS_DIM,), jnp.float32)

    def state_space(self, params=None):
        return spaces.Dict({"time": spaces.Discrete(1000)})


def synthetic_dataset(n: int, seed: int = 0) -> TransitionDataset:
    rng = np.random.default_rng(seed)
    obs = rng.normal(size=(n + 1, OBS_DIM)).astype(np.float32)
    terminated = rng.random(n) < 0.01
    truncated = np.zeros(n, bool)
    if not terminated[-1]:
        truncated[-1] = True  # ajax's dataset must end an episode on its last row
    return TransitionDataset(
        obs=obs[:-1],
        action=rng.uniform(-1, 1, (n, ACT_DIM)).astype(np.float32),
        reward=rng.normal(size=n).astype(np.float32),
        terminated=terminated,
        truncated=truncated,
        next_obs=obs[1:],
        env="hopper-synthetic",
    )


def architecture(hidden: list[int], layer_norm: bool) -> tuple[str, ...]:
    # parse_layer (networks/utils.py:234-258): "256" Dense, "layernorm" flax nn.LayerNorm, "relu".
    out: list[str] = []
    for h in hidden:
        out += [str(h), "layernorm", "relu"] if layer_norm else [str(h), "relu"]
    return tuple(out)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--transitions", type=int, default=100_000, help="synthetic dataset rows")
    p.add_argument("--updates", type=int, default=2000, help="critic updates (scan iterations) per timed call")
    p.add_argument("--repeats", type=int, default=3, help="timed calls, after one untimed call")
    p.add_argument("--seeds", type=int, default=1, help="seeds, vmapped as ajax-rl runs them")
    p.add_argument("--batch", type=int, default=256, help="minibatch rows")
    p.add_argument("--hidden", type=int, nargs="+", default=[256, 256], help="hidden widths, actor and critics")
    p.add_argument("--layer-norm", choices=("both", "critic", "actor", "none"), default="both",
                   help="LayerNorm after every hidden Dense, before ReLU, in these networks (ajax TD3: none)")
    p.add_argument("--policy-delay", type=int, default=2, help="critic updates per actor update")
    p.add_argument("--alpha", type=float, default=2.5, help="TD3+BC's alpha")
    p.add_argument("--compile-cache", action="store_true", help="keep ajax's persistent compile cache on (its default)")
    p.add_argument("--no-normalize-obs", action="store_true", help="drop TD3+BC's in-agent observation normalisation")
    args = p.parse_args()

    log = lambda m: print(m, file=sys.stderr, flush=True)  # noqa: E731
    t0 = time.perf_counter()
    data = synthetic_dataset(args.transitions)
    ln_actor = args.layer_norm in ("both", "actor")
    ln_critic = args.layer_norm in ("both", "critic")
    agent = TD3(
        HopperShapedStub(),
        n_envs=1,
        actor_architecture=architecture(args.hidden, ln_actor),
        critic_architecture=architecture(args.hidden, ln_critic),
        batch_size=args.batch,
        buffer_size=args.transitions,
        policy_delay=args.policy_delay,
        num_critics=2,
        normalize_observations=not args.no_normalize_obs,
        extensions=(ImitationLoss(expert_policy=None, target="replay", alpha=args.alpha),),
    )
    seeds = list(range(args.seeds))

    # 1. fresh states with the dataset in their replays (ajax's public offline entry point).
    state, _ = agent.train_offline(data, n_updates=1, seed=seeds)
    jax.block_until_ready(state)
    setup_s = time.perf_counter() - t0
    log(f"setup (dataset, agent, fresh states + replay fill, 1 update): {setup_s:.1f}s")

    # 2. the K-update train function, built as ActorCritic.train builds it (agents/base.py:473-486).
    train_jit = agent.get_make_train()(
        env_args=agent.env_args,
        actor_optimizer_args=agent.actor_optimizer_args,
        critic_optimizer_args=agent.critic_optimizer_args,
        network_args=agent.network_args,
        agent_config=agent.agent_config,
        total_timesteps=args.updates,
        num_episode_test=10,
        run_ids=[],
        logging_config=None,
        offline_data=data,
    )
    counters = shared_counters(state, agent.per_seed_update_counts)

    def resume(key, index, s, counters):  # as ActorCritic.train's resume (agents/base.py:502-517)
        s = with_shared_counters(s, counters)
        return train_jit(key, index, initial_state=s, resume_from_state=True)

    index = jnp.arange(len(seeds))
    keys = jax.vmap(jax.random.PRNGKey)(jnp.array(seeds))
    # jit(vmap(resume)) is the program ActorCritic.train dispatches as vmap(jitted train); jitting the outer
    # vmap lets it be compiled ahead of time (lower().compile()), so the warm-up does not have to run K updates.
    run = jax.jit(jax.vmap(resume, in_axes=(0, 0, 0, None)), donate_argnums=(2,))
    t = time.perf_counter()
    compiled = run.lower(keys, index, state, counters).compile()
    compile_s = time.perf_counter() - t
    log(f"trace + lower + compile of the {args.updates}-update program x {args.seeds} seeds: {compile_s:.2f}s")

    def steps(state):  # (critic optimiser steps, actor optimiser steps) of seed 0, outside the timed region
        return int(state.critic_state.step[0]), int(state.actor_state.step[0])

    def call(state):
        c = shared_counters(state, agent.per_seed_update_counts)
        t, cpu = time.perf_counter(), time.process_time()
        state, _ = compiled(keys, index, state, c)
        jax.block_until_ready(state)
        return state, time.perf_counter() - t, time.process_time() - cpu

    state, warmup_s, _ = call(state)  # one untimed call first, as the other adapters warm up
    log(f"warm-up call: {warmup_s:.2f}s")
    for r in range(args.repeats):
        before = steps(state)
        state, dt, cpu_s = call(state)
        after = steps(state)
        print(json.dumps({
            "library": "ajax-rl",
            "version": version("ajax-rl"),
            "jax": jax.__version__,
            "algo": f"TD3+BC (TD3 + ImitationLoss(target='replay', alpha={args.alpha:g}))",
            "seeds": args.seeds,
            "transitions": args.transitions,
            "updates": args.updates,
            "repeat": r,
            "wall_s": round(dt, 4),
            "critic_updates_per_s": round(args.updates * args.seeds / dt, 2),
            "critic_updates_per_s_per_seed": round(args.updates / dt, 2),
            # process CPU seconds (all threads) in the timed call: on a loaded machine updates per CPU-second
            # says more than wall-clock; with multi-threaded Eigen idle worker threads may add to it.
            "cpu_s": round(cpu_s, 3),
            "critic_updates_per_cpu_s": round(args.updates * args.seeds / cpu_s, 2),
            "critic_steps_in_call": after[0] - before[0],
            "actor_steps_in_call": after[1] - before[1],
            "compile_s": round(compile_s, 2),
            "setup_s": round(setup_s, 2),
            "layer_norm": args.layer_norm,
            "hidden": args.hidden,
            "batch": args.batch,
            "policy_delay": args.policy_delay,
            "normalize_obs": not args.no_normalize_obs,
            "compile_cache": args.compile_cache,
            "xla_flags": os.environ.get("XLA_FLAGS", ""),
            "cpus": len(os.sched_getaffinity(0)),
        }), flush=True)


if __name__ == "__main__":
    main()
