"""door-cloned: D4RL's recipe for Adroit "cloned" datasets, on gymnasium-robotics' AdroitHandDoor-v1.

    from offrl_jax.data.generate.door_cloned import generate_door_cloned
    demos = offrl_jax.data.catalogue.load("door-human")
    path = generate_door_cloned(demos)                             # 1M rows -> cache_dir()/"datasets"/"door-cloned"
    path = generate_door_cloned(demos, transitions=4000, out_dir="/tmp/dc")

The demonstrations come in as an argument (the catalogue, `data/catalogue.py`, loads them), so this generator does
not call back into the catalogue.

D4RL (scripts/generation/hand_dapg_policies.py + hand_dapg_combined.py): an MLP policy behaviour-cloned on the 25
human demonstrations is rolled out with Gaussian action noise (mjrl's `get_action(obs)[0]`, actions clipped to
[-1, 1], time-outs only: the door env never terminates); the dataset is the first half of the rollouts, cut at the
first episode end at or after N/2, followed by the human demonstrations tiled (`np.tile`) to fill the remaining rows.
Here:

  * BC = this library's `bc` (TD3BC family, actor-only MSE pre-training; `make_config("bc", "door")`), trained with
    `Driver` on the demonstrations for `bc_updates` updates; its deterministic tanh actor on normalised
    observations is the mean, and rollouts add N(0, noise_std^2) noise per action dimension, then clip to [-1, 1].
  * Rollouts use `make_env("door")` (the paper's 300-step limit; D4RL used the v0 env's 200) with the *original*
    D4RL reward (`envs.adroit.OriginalAdroitReward`), so both halves share the demonstrations' reward function.
  * Rows: whole rollout episodes until >= transitions // 2 rows (the last one cut if it would pass `transitions`),
    then the demonstrations repeated in order until exactly `transitions` rows; a demonstration cut short by the end
    of the dataset ends in a time-out (a cut, not a terminal).  No terminals anywhere.

Written with `offrl_jax.data.generate.write.write_minari` (Minari format, dataset id `door-cloned-v0`), plus
`out_dir/offrl_jax.json` (provenance and statistics) and `out_dir/bc_policy.msgpack` (the BC actor's variables,
`flax.serialization.to_bytes`; apply `DeterministicActor(28, hidden)` to `(obs - obs_mean) / obs_std` from the json).
"""
from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from offrl_jax.data.dataset import ARRAY_FIELDS, Dataset, dataset_dir

NAME = "door-cloned"
DEFAULT_TRANSITIONS = 1_000_000
DEFAULT_BC_UPDATES = 30_000
DEFAULT_NOISE_STD = 0.1


def train_bc(demos: Dataset, updates: int = DEFAULT_BC_UPDATES, seed: int = 0, batch_size: int = 256,
             progress: bool = False) -> tuple[Callable[[np.ndarray], np.ndarray], dict[str, Any]]:
    """Behaviour cloning on `demos` with the library's `bc` algorithm.

    Returns `(act, info)`: `act(obs (E, obs_dim)) -> (E, act_dim)` the deterministic policy (raw observations in,
    normalised inside), and info with the final BC loss, timing, hidden sizes, obs statistics and the actor variables.
    """
    import jax
    import jax.numpy as jnp

    from offrl_jax.algos import make_algorithm, make_config
    from offrl_jax.data.device import device_data
    from offrl_jax.driver import Driver
    from offrl_jax.envs.evaluate import make_policy

    config = make_config("bc", "door")
    algo = make_algorithm(config, demos.obs_dim, demos.act_dim, len(demos))
    data = device_data(demos, config.gamma)
    driver = Driver(algo, data.arrays, (seed,), batch_size)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=updates, desc="door-cloned: BC", unit="upd", mininterval=1.0)
    tic, last = time.time(), None
    for chunk in driver.run(algo.phases(updates), chunk_updates=min(5_000, updates)):
        if bar is not None:
            bar.update(chunk.update - bar.n)
            bar.set_postfix(bc_loss=f"{float(chunk.metrics['bc_loss'][0]):.4f}", refresh=False)
        last = chunk
    if bar is not None:
        bar.close()
    states = last.states
    policy = make_policy(algo.act, data.obs_mean, data.obs_std)

    def act(obs: np.ndarray) -> np.ndarray:
        return np.asarray(policy(states, jnp.asarray(obs, jnp.float32)[None]))[0]

    actor_vars = jax.tree.map(lambda x: np.asarray(x[0]), states.actor.params)
    info = {"updates": int(last.update), "batch_size": batch_size, "seed": seed, "hidden": list(config.hidden),
            "layer_norm": bool(config.actor_layer_norm), "final_bc_loss": float(last.metrics["bc_loss"][0]),
            "train_s": round(time.time() - tic, 1), "obs_mean": data.obs_mean.tolist(),
            "obs_std": data.obs_std.tolist(), "actor_variables": actor_vars}
    return act, info


def rollout(act: Callable[[np.ndarray], np.ndarray], min_transitions: int, max_transitions: int | None = None,
            seed: int = 0, noise_std: float = DEFAULT_NOISE_STD, num_envs: int = 16,
            progress: bool = False) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Whole episodes of `clip(act(obs) + noise_std * N(0, 1), -1, 1)` in `make_env("door")` with the original D4RL
    reward, until at least `min_transitions` rows (the episode crossing `max_transitions` is cut there, ending in a
    time-out).  Env i is reset with seed `seed * 10_000 + i` once and then continues its own RNG.

    The envs are stepped by `collect.rollout_episodes`; episodes are taken in the order they finish, and the cut one is
    cut after it has finished.  Door episodes all run the full horizon in lockstep, so that is the episode a cut in
    mid-episode would also hit; with episodes of different lengths other envs could finish episodes before it.

    Returns (arrays of the Dataset fields, float32, episodes in the order they finish; stats).
    """
    from offrl_jax.data.generate.collect import rollout_episodes
    from offrl_jax.envs.adroit import with_original_reward
    from offrl_jax.envs.registry import get_env_spec, make_env

    horizon = get_env_spec("door").max_episode_steps
    max_transitions = max_transitions or min_transitions
    num_envs = max(1, min(num_envs, math.ceil(min_transitions / horizon)))
    rng = np.random.default_rng(seed)

    def noisy_act(obs: np.ndarray) -> np.ndarray:
        actions = act(obs)
        if noise_std > 0:
            actions = actions + noise_std * rng.standard_normal(actions.shape)
        return np.clip(actions, -1.0, 1.0).astype(np.float32)

    episodes, successes, total = [], [], 0
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=min_transitions, desc="door-cloned: rollouts", unit="tr", mininterval=1.0)
    gen = rollout_episodes("door", noisy_act, num_envs, seed, info_keys=("success",),
                           make=lambda: with_original_reward(make_env("door", disable_env_checker=True)))
    try:
        for _, ep in gen:
            n = len(ep["rewards"])
            if total + n >= max_transitions:  # reaching max_transitions is a cut: a time-out, never a terminal
                n = max_transitions - total
                ep = {k: v[:n] for k, v in ep.items()}
                ep["terminals"][-1] = 0.0
                ep["timeouts"][-1] = 1.0
            episodes.append(ep)
            successes.append(bool(ep["success"].any()))
            total += n
            if bar is not None:
                bar.update(n)
                bar.set_postfix(episodes=len(episodes), ret=f"{ep['rewards'].sum():.0f}", refresh=False)
            if total >= min_transitions or total >= max_transitions:
                break
    finally:
        gen.close()
        if bar is not None:
            bar.close()
    arrays = {k: np.concatenate([e[k] for e in episodes]) for k in ARRAY_FIELDS}
    returns = np.array([e["rewards"].sum() for e in episodes])
    stats = {"episodes": len(episodes), "transitions": int(total), "return_mean": float(returns.mean()),
             "return_std": float(returns.std()), "success_rate": float(np.mean(successes)),
             "noise_std": noise_std, "num_envs": num_envs, "seed": seed}
    return arrays, stats


def tile_demos(demos: Dataset, n: int) -> dict[str, np.ndarray]:
    """`n` rows of the demonstrations repeated in order (as D4RL's `np.tile`); a demonstration cut by the end gets a
    time-out on its last kept row."""
    reps = math.ceil(n / len(demos))
    arrays = {k: np.concatenate([getattr(demos, k)] * reps)[:n].astype(np.float32) for k in ARRAY_FIELDS}
    if n:
        arrays["timeouts"][-1] = max(arrays["timeouts"][-1], 1.0 - arrays["terminals"][-1])
    return arrays


def build_door_cloned(demos: Dataset, transitions: int = DEFAULT_TRANSITIONS, seed: int = 0,
                      bc_updates: int = DEFAULT_BC_UPDATES, noise_std: float = DEFAULT_NOISE_STD, num_envs: int = 16,
                      progress: bool = True) -> tuple[Dataset, dict[str, Any]]:
    """The in-memory door-cloned dataset from the human demonstrations `demos`, and its provenance (no writing); see
    the module docstring."""
    if transitions < 2:
        raise ValueError(f"transitions = {transitions}: need at least 2 (one rollout row and one demonstration row)")
    act, bc_info = train_bc(demos, bc_updates, seed, progress=progress)
    tic = time.time()
    roll, roll_stats = rollout(act, transitions // 2, transitions - 1, seed, noise_std, num_envs, progress)
    roll_stats["collect_s"] = round(time.time() - tic, 1)
    n_demo = transitions - len(roll["rewards"])
    demo = tile_demos(demos, n_demo)
    arrays = {k: np.concatenate([roll[k], demo[k]]) for k in ARRAY_FIELDS}
    ds = Dataset(**arrays, env="door", name=NAME, source="generated")
    source = {
        "recipe": "D4RL hand_dapg_combined: BC rollouts (first half, whole episodes) ++ human demos tiled",
        "bc": {k: v for k, v in bc_info.items() if k != "actor_variables"},
        "rollouts": roll_stats,
        "demos": {"path": demos.source, "episodes": int(demos.episode_ends.sum()),
                  "transitions": len(demos), "rows_used": int(n_demo),
                  "repeats": round(n_demo / len(demos), 2)},
        "reward": "original D4RL reward (offrl_jax.envs.adroit.OriginalAdroitReward), as the demonstrations' rewards",
    }
    source["_actor_variables"] = bc_info["actor_variables"]
    return ds, source


def generate_door_cloned(demos: Dataset, transitions: int | None = None, out_dir: str | Path | None = None,
                         seed: int = 0, *, overwrite: bool = False, progress: bool = True,
                         bc_updates: int = DEFAULT_BC_UPDATES, noise_std: float = DEFAULT_NOISE_STD,
                         num_envs: int = 16, shown_as: str | None = None) -> Path:
    """Generate door-cloned from the human demonstrations `demos` (`transitions` rows, half BC rollouts, half
    demonstrations) in Minari format; returns its
    directory (default `dataset_dir("door-cloned")`; an existing one raises unless overwrite)."""
    import flax.serialization

    from offrl_jax.data.generate.collect import summarize
    from offrl_jax.data.generate.write import write_minari
    from offrl_jax.envs.registry import get_env_spec

    cap, transitions = transitions, int(transitions or DEFAULT_TRANSITIONS)
    out = Path(out_dir) if out_dir is not None else dataset_dir(NAME)
    if out.exists() and not overwrite:
        raise FileExistsError(f"{out} exists; pass overwrite=True to replace it")
    t0 = time.time()
    ds, source = build_door_cloned(demos, transitions, seed, bc_updates, noise_std, num_envs, progress)
    actor_vars = source.pop("_actor_variables")
    spec = get_env_spec("door")
    half = source["rollouts"]["transitions"]
    info = {
        "name": NAME, "env": "door", "gym_id": spec.gym_id, "level": "cloned", "seed": seed,
        "transitions_cap": cap, "algorithm": "BC", "source": source,
        "ref_min_score": spec.ref_min_score, "ref_max_score": spec.ref_max_score,
        "stats": summarize(ds), "stats_rollouts": summarize(ds.select(slice(0, half))),
        "stats_demos": summarize(ds.select(slice(half, None))) if half < len(ds) else None,
        "d4rl_v1": {"transitions": 1_000_000, "episodes": 4358, "horizon": 200},
    }
    write_minari(ds, out, info, overwrite=overwrite)
    (out / "bc_policy.msgpack").write_bytes(flax.serialization.to_bytes(actor_vars))
    info["total_s"] = round(time.time() - t0, 1)
    (out / "offrl_jax.json").write_text(json.dumps(info, indent=1))
    if progress:
        st = info["stats"]
        print(f"[generate] {NAME}: {st['transitions']} transitions, {st['episodes']} episodes, return "
              f"{st['return_mean']:.0f} (norm {st['normalized_score']:.1f}; rollouts "
              f"{info['stats_rollouts']['return_mean']:.0f}) in {info['total_s']:.0f}s -> {shown_as or out}")
    return out


__all__ = ["generate_door_cloned", "build_door_cloned", "train_bc", "rollout", "tile_demos", "NAME"]
