"""Rolling out behaviour policies into a `Dataset`, evaluating them, and loading the shipped checkpoints.

A behaviour policy is the actor of our online SAC (`offrl_jax.data.generate.sac`): a tanh-Gaussian MLP 256-256 without
LayerNorm, stored as `flax.serialization.to_bytes` of its variables ({"params": ...}, msgpack).  Acting:
stochastic = tanh(mean + std * eps) (what D4RL's medium / expert datasets record), deterministic = tanh(mean)
(what the evaluations during training report).

Rollouts step `num_envs` independent envs in lockstep so that one jitted policy call serves a batch of observations.
Every env keeps its own episode buffer; finished episodes are appended to the dataset in the order they finish.
"""
from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import flax.serialization
import jax
import jax.numpy as jnp
import numpy as np

from offrl_jax.data.dataset import Dataset
from offrl_jax.data.generate.reference import D4RL_V2
from offrl_jax.envs.registry import get_env_spec, make_env, normalized_score
from offrl_jax.nets import TanhGaussianActor, sample_tanh_gaussian

ACTOR_HIDDEN = (256, 256)
POLICY_DIR = Path(__file__).resolve().parent.parent / "policies"
POLICY_INDEX = POLICY_DIR / "policies.json"
# D4RL's medium behaviour normalised scores: the shipped medium checkpoint is the one whose eval is closest to these.
MEDIUM_TARGET_SCORE = {name.split("-")[0]: ref["normalized_score"] for name, ref in D4RL_V2.items()
                       if name.endswith("-medium")}


def actor_module(act_dim: int, hidden: tuple[int, ...] = ACTOR_HIDDEN) -> TanhGaussianActor:
    """The behaviour-policy network: tanh-Gaussian actor, ReLU MLP `hidden`, no LayerNorm."""
    return TanhGaussianActor(act_dim=act_dim, hidden=tuple(hidden), layer_norm=False)


def make_policy(act_dim: int, hidden: tuple[int, ...] = ACTOR_HIDDEN, stochastic: bool = True) -> Callable:
    """Jitted `(params, obs (B, obs_dim), key, step) -> actions (B, act_dim)` in [-1, 1].

    The noise of a stochastic policy uses `fold_in(key, step)`: pass a fresh integer `step` per call.
    """
    actor = actor_module(act_dim, hidden)

    @jax.jit
    def act(params, obs, key, step):
        key = jax.random.fold_in(key, step)
        mean, log_std = actor.apply(params, obs)
        if stochastic:
            return sample_tanh_gaussian(key, mean, log_std)[0]
        return jnp.tanh(mean)

    return act


# ------------------------------------------------------------------------------------------------ shipped policies


def shipped_policies() -> dict[str, dict[str, Any]]:
    """Metadata of the checkpoints shipped in `offrl_jax/data/policies/`, keyed by name ("hopper-medium", ...)."""
    if not POLICY_INDEX.exists():
        return {}
    return json.loads(POLICY_INDEX.read_text())


def load_policy(name_or_path: str | Path) -> tuple[dict, dict[str, Any]]:
    """(params, metadata) of a shipped policy ("hopper-medium") or of any actor checkpoint file (.msgpack).

    params is the flax variables dict {"params": ...} for `actor_module(meta["act_dim"], meta["hidden"])`.
    For a bare file the metadata holds only what the file itself tells (act_dim, hidden, path).
    """
    index = shipped_policies()
    if str(name_or_path) in index:
        meta = dict(index[str(name_or_path)])
        path = POLICY_DIR / meta["file"]
    else:
        path = Path(name_or_path)
        if not path.exists():
            raise FileNotFoundError(f"no shipped policy or checkpoint file '{name_or_path}'; shipped: {sorted(index)}")
        meta = {}
    params = flax.serialization.msgpack_restore(path.read_bytes())
    params = jax.tree_util.tree_map(jnp.asarray, params)
    dense = params["params"]["MLP_0"]
    layers = sorted(dense, key=lambda k: int(k.split("_")[1]))
    meta.setdefault("hidden", [int(dense[k]["kernel"].shape[1]) for k in layers[:-1]])
    meta.setdefault("obs_dim", int(dense[layers[0]]["kernel"].shape[0]))
    meta.setdefault("act_dim", int(dense[layers[-1]]["kernel"].shape[1]) // 2)
    meta.setdefault("path", str(path))
    return params, meta


# ------------------------------------------------------------------------------------------------------ rollouts


def _make_envs(env_name: str, num_envs: int, max_episode_steps: int | None, make: Callable | None = None):
    envs = [make() if make is not None else make_env(env_name, max_episode_steps) for _ in range(num_envs)]
    for env in envs:
        low, high = env.action_space.low, env.action_space.high
        if not (np.allclose(low, -1.0) and np.allclose(high, 1.0)):
            raise ValueError(f"{env_name}: expected actions in [-1, 1], got [{low}, {high}]")
    return envs


def rollout_episodes(
    env_name: str,
    act: Callable[[np.ndarray], np.ndarray],
    num_envs: int = 16,
    seed: int = 0,
    max_episode_steps: int | None = None,
    make: Callable[[], Any] | None = None,
    info_keys: tuple[str, ...] = (),
) -> Iterator[tuple[int, dict[str, np.ndarray]]]:
    """Endless generator of finished episodes `(env_index, episode)`, episode a dict of `Dataset` fields (float32).

    `act(obs (num_envs, obs_dim)) -> actions (num_envs, act_dim)`.  Env i is reset with seed `seed * 10_000 + i` once,
    then continues its own RNG.  A step that is both terminated and truncated counts as a terminal.  The recorded
    next observation is the env's real s_{t+1}, also at a time-out (the reset observation is never recorded).

    `make() -> env` builds each env instead of `make_env(env_name, max_episode_steps)` (env_name then only gives
    the default horizon).  Every key in `info_keys` adds a (n,) float32 field to the episode: `info.get(key, 0)` of
    each step (e.g. "success" for the Adroit envs).
    """
    envs = _make_envs(env_name, num_envs, max_episode_steps, make)
    horizon = max_episode_steps or get_env_spec(env_name).max_episode_steps
    obs_dim = envs[0].observation_space.shape[0]
    act_dim = envs[0].action_space.shape[0]
    buf = {
        "observations": np.zeros((num_envs, horizon, obs_dim), np.float32),
        "actions": np.zeros((num_envs, horizon, act_dim), np.float32),
        "rewards": np.zeros((num_envs, horizon), np.float32),
        "next_observations": np.zeros((num_envs, horizon, obs_dim), np.float32),
        **{key: np.zeros((num_envs, horizon), np.float32) for key in info_keys},
    }
    lengths = np.zeros(num_envs, np.int64)
    obs = np.stack([env.reset(seed=seed * 10_000 + i)[0] for i, env in enumerate(envs)]).astype(np.float32)
    try:
        while True:
            actions = np.asarray(act(obs), dtype=np.float32)
            for i, env in enumerate(envs):
                t = lengths[i]
                next_obs, reward, terminated, truncated, info = env.step(actions[i])
                buf["observations"][i, t] = obs[i]
                buf["actions"][i, t] = actions[i]
                buf["rewards"][i, t] = reward
                buf["next_observations"][i, t] = next_obs
                for key in info_keys:
                    buf[key][i, t] = info.get(key, 0)
                lengths[i] = t + 1
                if terminated or truncated or t + 1 >= horizon:
                    n = t + 1
                    episode = {k: v[i, :n].copy() for k, v in buf.items()}
                    episode["terminals"] = np.zeros(n, np.float32)
                    episode["timeouts"] = np.zeros(n, np.float32)
                    if terminated:
                        episode["terminals"][-1] = 1.0
                    else:
                        episode["timeouts"][-1] = 1.0
                    yield i, episode
                    lengths[i] = 0
                    next_obs, _ = env.reset()
                obs[i] = next_obs
    finally:
        for env in envs:
            env.close()


def _batched_actor(act_dim: int, policy_params, seed: int, stochastic: bool, hidden) -> Callable:
    if isinstance(policy_params, str):
        if policy_params != "random":
            raise ValueError(f"policy must be params or 'random', got '{policy_params}'")
        rng = np.random.default_rng(seed)
        return lambda obs: rng.uniform(-1.0, 1.0, (obs.shape[0], act_dim)).astype(np.float32)
    policy = make_policy(act_dim, hidden, stochastic)
    key = jax.random.PRNGKey(seed)
    calls = iter(range(2**31 - 1))

    def act(obs):
        return np.asarray(policy(policy_params, jnp.asarray(obs), key, next(calls)))

    return act


def collect(
    env_name: str,
    policy_params: Any,
    n_transitions: int,
    seed: int = 0,
    stochastic: bool = True,
    num_envs: int = 16,
    max_episode_steps: int | None = None,
    hidden: tuple[int, ...] = ACTOR_HIDDEN,
    progress: bool = False,
    name: str | None = None,
) -> Dataset:
    """Exactly `n_transitions` rows of rollouts of `policy_params` (actor variables) or "random" (uniform actions).

    Episodes end with a terminal or, at the time limit (`max_episode_steps`, default the env's 1000), a time-out.
    Whole episodes are appended in the order they finish; the episode that crosses `n_transitions` is cut there and
    its last kept row is marked as a time-out (a cut, not a terminal), as D4RL's last episode.
    """
    spec = get_env_spec(env_name)
    num_envs = max(1, min(num_envs, math.ceil(n_transitions / 50)))
    act = _batched_actor(spec.act_dim, policy_params, seed, stochastic, hidden)
    episodes, total = [], 0
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=n_transitions, desc=f"collect {name or env_name}", unit="tr", smoothing=0.05, mininterval=1.0)
    for _, episode in rollout_episodes(env_name, act, num_envs, seed, max_episode_steps):
        n = len(episode["rewards"])
        if total + n >= n_transitions:
            keep = n_transitions - total
            if keep < n:
                episode = {k: v[:keep] for k, v in episode.items()}
                episode["terminals"][-1] = 0.0
                episode["timeouts"][-1] = 1.0
            n = keep
        episodes.append(episode)
        total += n
        if bar is not None:
            bar.set_postfix(episodes=len(episodes), ret=f"{episode['rewards'].sum():.0f}", refresh=False)
            bar.update(n)
        if total >= n_transitions:
            break
    if bar is not None:
        bar.close()
    arrays = {k: np.concatenate([e[k] for e in episodes]) for k in episodes[0]}
    return Dataset(**arrays, env=spec.name, name=name or f"{spec.name}-collected", source="generated")


def evaluate(
    env_name: str,
    policy_params: Any,
    episodes: int = 5,
    seed: int = 0,
    deterministic: bool = True,
    hidden: tuple[int, ...] = ACTOR_HIDDEN,
    num_envs: int | None = None,
    max_episode_steps: int | None = None,
) -> np.ndarray:
    """(episodes,) undiscounted returns of full episodes of the policy (deterministic = tanh(mean) by default)."""
    spec = get_env_spec(env_name)
    act = _batched_actor(spec.act_dim, policy_params, seed, not deterministic, hidden)
    # rounds of `num_envs` envs; an env's later episodes are ignored within a round (no bias to short episodes)
    n = min(num_envs or episodes, episodes)
    returns: list[float] = []
    round_seed = seed + 7_777
    while len(returns) < episodes:
        want = min(n, episodes - len(returns))
        done: dict[int, float] = {}
        for i, episode in rollout_episodes(env_name, act, want, round_seed, max_episode_steps):
            done.setdefault(i, float(episode["rewards"].sum()))
            if len(done) == want:
                break
        returns.extend(done[i] for i in range(want))
        round_seed += 1
    return np.asarray(returns)


def summarize(dataset: Dataset) -> dict[str, float]:
    """Transitions, episodes, mean / std behaviour return and the mean normalised score (over episodes)."""
    returns = dataset.episode_returns()
    return {
        "transitions": len(dataset),
        "episodes": int(returns.shape[0]),
        "terminals": int(dataset.terminals.sum()),
        "timeouts": int(dataset.timeouts.sum()),
        "return_mean": float(returns.mean()),
        "return_std": float(returns.std()),
        "normalized_score": float(normalized_score(dataset.env or dataset.name, returns.mean())),
    }
