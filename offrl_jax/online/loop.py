"""The online phase of a run: after its offline phases, S members (seeds, and sweep values) fine-tune in their own
environments, on the driver's member axis, in one program.

Every block of K env steps: every member's env steps K times, with actions for all members from one jitted call
per step (`offrl_jax.online.envs.collect`, the family's exploration: a stochastic actor samples, a deterministic
one adds Gaussian noise); the block goes into each member's online buffer (`offrl_jax.online.buffer`), which writes
the Monte-Carlo returns of the episodes it ends; then K * utd updates run as one jitted scan, each minibatch drawn
inside it from the dataset and the member's buffer as the family's `replay` says (`offrl_jax.online.sampling`).
The first `warmup` env steps only collect.  Nothing is recompiled per block.

The update is the family's offline-RL update, with the online values a family declares
(`Algorithm.online_values(progress)`: a penalty that decays over the online phase, say) recomputed at every update
from the online progress.  Randomness stays a pure function of (seed, index): update u of the run uses
fold_in(key, u) as offline, the exploration noise of env step t fold_in(key(seed, EXPLORE), t), and every episode's
reset its seed and start step (`online.envs.reset_seed`).
"""
from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Callable, Iterator
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import serialization

from offrl_jax.algos.common import Phase, with_hparams
from offrl_jax.data.device import DeviceData
from offrl_jax.driver import Chunk, Driver, merge_metrics
from offrl_jax.envs.registry import normalized_score
from offrl_jax.online.buffer import OnlineBuffer, device_rows, insert, new_buffer
from offrl_jax.online.config import OnlineConfig
from offrl_jax.online.envs import MemberEnvs, collect, exploration_keys, exploration_policy
from offrl_jax.online.sampling import Replay, sample
from offrl_jax.system.distributed import to_host


def online_phase(algo: Any, offline_updates: int, online: OnlineConfig
                 ) -> tuple[Phase, Callable[[dict | None, jax.Array], Phase]]:
    """(the online phase, phase_at): the family's offline-RL phase renamed "online" and `online.updates()` long,
    and the phase at update u (with a sweep's hyper-parameters), carrying the family's online values at that
    update's progress through the online phase."""
    last = algo.phases(offline_updates)[-1]
    online.check(type(algo).__name__, last)
    updates = online.updates()
    phase = dataclasses.replace(last, name="online", steps=updates, on_start=None, auto_stop=None)

    def phase_at(hparams: dict | None, update: jax.Array) -> Phase:
        now = algo if not hparams else with_hparams(algo, **hparams)
        if values := now.online_values((update - offline_updates) / updates):
            now = with_hparams(now, **values)
        return dataclasses.replace(now.phases(offline_updates)[-1], name="online", steps=updates)

    return phase, phase_at


def train_metrics(episodes: list, members: int, env: str) -> dict[str, np.ndarray]:
    """Per member, the training episodes that ended in an evaluation interval: their mean return, D4RL-normalised
    (`train_score`; NaN where none ended), and how many (`train_episodes`)."""
    returns = [[e.return_ for e in episodes if e.member == m] for m in range(members)]
    mean = np.array([np.mean(r) if r else np.nan for r in returns])
    return {"train_score": np.asarray(normalized_score(env, mean), float),
            "train_episodes": np.array([len(r) for r in returns], float)}


def run_online(driver: Driver, algo: Any, online: OnlineConfig, env: str, form: DeviceData, states: Any,
               offline_updates: int, seconds: float, reward_scale: float = 1.0,
               on_slice: Callable[[int], None] | None = None,
               make_env: Callable[[], Any] | None = None, saved: dict | None = None) -> Iterator[Chunk]:
    """Fine-tune `states` (the hand-over, leading axis the driver's members) online in `env`, yielding a `Chunk`
    (phase "online", `env_steps` set, metrics the updates' means and `train_metrics`) every `online.eval_every` env
    steps.  `offline_updates` is the updates the offline phases made (the online phase's updates count on from
    there); `reward_scale` scales online rewards as the dataset's were (`Dataset.reward_scale` when they are
    normalised); `on_slice(updates)` hears of every block's updates (a stop it raises ends the run there).

    Each chunk's `carry()` is the phase's state there (`online_state`); `saved`, one of those with `states` the
    checkpoint's, goes on from its env step as if the run had not stopped."""
    layout, members, cfg = driver.layout, driver.members, algo.cfg
    phase, phase_at = online_phase(algo, offline_updates, online)
    replay = Replay(cfg.replay, cfg.online_mix, ended_only=cfg.needs().returns)
    calls = online.block * online.utd // phase.updates_per_call
    draw = lambda key, data, buffer, shape: sample(key, replay, data, buffer, shape)  # noqa: E731
    fn = driver.chunk_fn(phase, calls, draw=draw, phase_at=phase_at)
    extra = () if driver.hparams is None else (driver.hparams,)
    envs = MemberEnvs(env, members, make_env)
    try:
        obs_dim, act_dim = form.arrays["observations"].shape[1], form.arrays["actions"].shape[1]
        if envs.observations.shape[1] != obs_dim or envs.act_dim != act_dim:
            raise ValueError(f"{env}'s observations and actions ({envs.observations.shape[1]}, {envs.act_dim}) do "
                             f"not match the dataset's ({obs_dim}, {act_dim})")
        buffer = new_buffer(len(members), online.rows(envs.horizon), obs_dim, act_dim, cfg.gamma, envs.horizon)
        update = offline_updates
        if saved is not None:
            buffer = serialization.from_state_dict(buffer, saved["buffer"])
            envs.restore(saved["envs"])
            update = int(json.loads(saved["key"])["update"])
        buffer = layout.place(buffer)
        explore = exploration_policy(algo.act, form.obs_mean, form.obs_std, cfg.explore_noise, algo.explore)
        keys = exploration_keys(members)
        states = layout.place(states)
        parts, episodes, blocks, steps_done = [], [], [], 0
        tic = time.perf_counter()
        while envs.step_count < online.steps:
            acting = driver.real(states)
            block, ended = collect(envs, lambda obs, t, s=acting: explore(s, keys, obs, t), online.block)
            episodes += ended
            blocks.append(block)
            rows = device_rows(block, form.obs_mean, form.obs_std, reward_scale)
            buffer = insert(buffer, layout.place(rows), donate=True)
            if envs.step_count > online.warmup:
                states, metrics = fn(states, driver.data, driver.run_keys, jnp.int32(update), buffer, *extra)
                parts.append(driver.real(to_host(metrics)))
                update += calls * phase.updates_per_call
                if on_slice is not None:
                    on_slice(calls * phase.updates_per_call)
            steps_done += online.block
            if envs.step_count % online.eval_every and envs.step_count < online.steps:
                continue
            elapsed = time.perf_counter() - tic
            seconds += elapsed
            metrics = merge_metrics(parts) if parts else {"finite": np.ones(len(members), bool)}  # warm-up only
            carry = lambda b=buffer, u=update: online_state(driver, b, envs, u, offline_updates, online)  # noqa: E731
            transitions = {f: np.concatenate([b[f] for b in blocks], axis=1) for f in blocks[0]}
            yield Chunk("online", update, driver.real(states), metrics | train_metrics(episodes, len(members), env),
                        seconds, steps_done / elapsed, env_steps=envs.step_count, carry=carry,
                        transitions=transitions)
            parts, episodes, blocks, steps_done, tic = [], [], [], 0, time.perf_counter()
    finally:
        envs.close()


def online_state(driver: Driver, buffer: OnlineBuffer, envs: MemberEnvs, update: int, offline_updates: int,
                 online: OnlineConfig) -> dict | None:
    """What going on from here needs besides the agent states (at an evaluation, where no training episode is
    pending in the measures): the update and env step, every env's state and the members' online buffers, as host
    arrays, with the offline updates and the online settings it belongs to (`online_state_key`).  None when the envs
    cannot be saved (not MuJoCo's): a resume then starts the phase again."""
    saved = envs.state()
    if saved is None:
        return None
    return {"key": online_state_key(update, envs.step_count, offline_updates, online), "envs": saved,
            "buffer": serialization.to_state_dict(to_host(driver.real(buffer)))}


def online_state_key(update: int, env_steps: int, offline_updates: int, online: OnlineConfig) -> str:
    """What an online state belongs to: the update and env step it was saved at, the offline phases' updates and the
    online settings; a resume goes on from the state only where all of these are its own."""
    return json.dumps({"update": int(update), "env_steps": int(env_steps), "offline_updates": int(offline_updates),
                       "online": dataclasses.asdict(online)}, sort_keys=True)
