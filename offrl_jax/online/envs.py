"""The online phase's environments: one gymnasium env per member on the host, stepped together with actions for every
member from one jitted policy call per step, and `collect`, which gathers K steps of every member as one block.

Member m's env starts every episode with a reset seeded by (its seed, the env step at which the episode starts)
(`reset_seed`), so what it collects is a pure function of its seed and the actions it is given: member (j, i) of a
sweep steps what a single run with seed i steps, and a run that resumes an episode from a saved env state needs no
random-number state.  A step that is both terminated and truncated is a terminal (as in the offline datasets); the
recorded next observation is the env's real s_{t+1}, also at a time-out, never the reset observation.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from offrl_jax.driver import PHASE_START, seed_keys
from offrl_jax.envs.registry import make_env

EXPLORE = PHASE_START + 1  # the key stream of exploration noise, after the driver's
RESET_ENTROPY = 0x0F1E  # tells the envs' reset seeds apart from evaluation's start states


def reset_seed(seed: int, step: int) -> int:
    """The reset seed of an episode that a member with run seed `seed` starts at env step `step`."""
    return int(np.random.SeedSequence([RESET_ENTROPY, seed, step]).generate_state(1)[0])


class NonFiniteObservation(ValueError):
    """An env returned a NaN or infinite observation or reward."""


@dataclasses.dataclass(frozen=True)
class Episode:
    """An episode that ended while collecting: its member, the env steps it took, its undiscounted return, whether
    it ended in a terminal (else the time limit cut it), and the env step (counted from the phase's start) it ended
    at."""
    member: int
    length: int
    return_: float
    terminal: bool
    end_step: int


class MemberEnvs:
    """S envs of `env_name` (or `make()`), env m for the member with run seed `seeds[m]`; reset on creation.

    `observations` (S, obs_dim) are what the next step acts on; `step_count` is the env steps every env has taken.
    """

    def __init__(self, env_name: str, seeds: Sequence[int], make: Callable[[], Any] | None = None):
        self.seeds = tuple(int(s) for s in seeds)
        self.envs = [make() if make is not None else make_env(env_name, disable_env_checker=True) for _ in self.seeds]
        space = self.envs[0].action_space
        if not (np.allclose(space.low, -1.0) and np.allclose(space.high, 1.0)):
            raise ValueError(f"{env_name}: expected actions in [-1, 1], got [{space.low}, {space.high}]")
        self.horizon = getattr(self.envs[0].spec, "max_episode_steps", None)
        if not self.horizon:
            raise ValueError(f"{env_name}: the online phase needs an env with a time limit")
        self.act_dim = space.shape[0]
        self.step_count = 0
        self.episode_return = np.zeros(len(self.envs))
        self.episode_length = np.zeros(len(self.envs), np.int64)
        self.observations = np.stack([self._reset(m) for m in range(len(self.envs))])

    def _reset(self, member: int) -> np.ndarray:
        obs, _ = self.envs[member].reset(seed=reset_seed(self.seeds[member], self.step_count))
        self._check(member, obs, 0.0, "reset")
        return np.asarray(obs, np.float32)

    def _check(self, member: int, obs: np.ndarray, reward: float, what: str) -> None:
        if not (np.all(np.isfinite(obs)) and np.isfinite(reward)):
            raise NonFiniteObservation(f"member {member} (seed {self.seeds[member]}): the env returned a non-finite "
                                       f"observation or reward at its {what} at env step {self.step_count}")

    def step(self, actions: np.ndarray) -> tuple[dict[str, np.ndarray], list[Episode]]:
        """Step every env with its action ((S, act_dim)): (the transitions, `BLOCK_FIELDS` each (S, ...), float32;
        the episodes they ended).  Envs whose episode ended are reset, their next `observations` the reset's.

        A member whose action is not finite (its networks diverged; the runner has left it out) is not stepped: its
        env stays where it is, and its row has NaN next observation and reward, as its scores are NaN, and a time-out
        (nothing of it is under way: its online buffer waits for no episode end)."""
        actions = np.asarray(actions, np.float32)
        if actions.shape != (len(self.envs), self.act_dim):
            raise ValueError(f"expected actions of shape {(len(self.envs), self.act_dim)}, got {actions.shape}")
        out = {"observations": self.observations.copy(), "actions": actions,
               "next_observations": np.zeros_like(self.observations), "rewards": np.zeros(len(self.envs), np.float32),
               "terminals": np.zeros(len(self.envs), np.float32), "timeouts": np.zeros(len(self.envs), np.float32)}
        diverged = ~np.all(np.isfinite(actions), axis=1)
        out["next_observations"][diverged], out["rewards"][diverged], out["timeouts"][diverged] = np.nan, np.nan, 1.0
        ended = []
        for m, env in enumerate(self.envs):
            if diverged[m]:
                continue
            obs, reward, terminated, truncated, _ = env.step(actions[m])
            self._check(m, obs, reward, "step")
            out["next_observations"][m], out["rewards"][m] = obs, reward
            out["terminals"][m], out["timeouts"][m] = float(terminated), float(truncated and not terminated)
            self.episode_return[m] += reward
            self.episode_length[m] += 1
            if terminated or truncated:
                ended.append(Episode(m, int(self.episode_length[m]), float(self.episode_return[m]), bool(terminated),
                                     self.step_count + 1))
                self.episode_return[m], self.episode_length[m] = 0.0, 0
        self.step_count += 1
        self.observations = np.where(diverged[:, None], self.observations, out["next_observations"])
        for episode in ended:
            self.observations[episode.member] = self._reset(episode.member)
        return out, ended

    def state(self) -> dict[str, np.ndarray] | None:
        """Everything stepping on needs, as arrays (saved with an online checkpoint; `restore`): the env step, the
        episodes under way (return, length, the observation acted on next) and each env's exact simulator state
        (MuJoCo's integration state, the model fields a reset may place anew, `RESET_FIELDS`, and the time limit's
        step count).  None for an env that is not MuJoCo's."""
        physics, elapsed, placed = [], [], {name: [] for name in RESET_FIELDS}
        for env in self.envs:
            model, data = (getattr(env.unwrapped, name, None) for name in ("model", "data"))
            limit = _time_limit(env)
            if not isinstance(data, mujoco.MjData) or limit is None:
                return None
            saved = np.empty(mujoco.mj_stateSize(model, SIM_STATE))
            mujoco.mj_getState(model, data, saved, SIM_STATE)
            physics.append(saved)
            elapsed.append(limit._elapsed_steps)
            for name in RESET_FIELDS:
                placed[name].append(getattr(model, name).copy())
        return {"step_count": np.int64(self.step_count), "episode_return": self.episode_return.copy(),
                "episode_length": self.episode_length.copy(), "observations": self.observations.copy(),
                "physics": np.stack(physics), "elapsed": np.array(elapsed, np.int64),
                **{name: np.stack(values) for name, values in placed.items()}}

    def restore(self, state: dict[str, np.ndarray]) -> None:
        """Continue from `state()` of envs of the same env name and seeds: every later step is what the saved envs
        would have stepped."""
        for m, (env, physics, elapsed) in enumerate(zip(self.envs, state["physics"], state["elapsed"], strict=True)):
            model, data = env.unwrapped.model, env.unwrapped.data
            for name in RESET_FIELDS:
                if name in state:  # (an online state saved before these were, restored without them)
                    getattr(model, name)[:] = np.asarray(state[name][m])
            mujoco.mj_setState(model, data, np.asarray(physics), SIM_STATE)
            mujoco.mj_forward(model, data)  # positions, contacts and forces derived from it, as after a step
            _time_limit(env)._elapsed_steps = int(elapsed)
        self.step_count = int(state["step_count"])
        self.episode_return = np.array(state["episode_return"], np.float64)
        self.episode_length = np.array(state["episode_length"], np.int64)
        self.observations = np.array(state["observations"], np.float32)

    def close(self) -> None:
        for env in self.envs:
            env.close()


SIM_STATE = mujoco.mjtState.mjSTATE_INTEGRATION  # all MuJoCo's data needs to step on exactly as before
# model fields an env's reset may set (Adroit places the door, hammer nail and relocate object and target as body and
# site positions, the pen's goal as a body orientation): saved with the simulator state
RESET_FIELDS = ("body_pos", "body_quat", "site_pos", "site_quat")


def _time_limit(env: Any) -> Any:
    """The TimeLimit wrapper of a gymnasium env (its `_elapsed_steps` ends episodes), or None."""
    while env is not None and not hasattr(env, "_elapsed_steps"):
        env = getattr(env, "env", None)
    return env


def collect(envs: MemberEnvs, policy: Callable[[np.ndarray, int], Any], steps: int
            ) -> tuple[dict[str, np.ndarray], list[Episode]]:
    """`steps` (K) env steps of every member: (a block, `BLOCK_FIELDS` each (S, K, ...) float32, raw observations
    and rewards (`offrl_jax.online.buffer.device_rows` puts them in device form); the episodes that ended, in order).

    `policy(observations (S, obs_dim), env step) -> (S, act_dim)` acts for every member at once: one call, one
    transfer of S observations and S actions per step."""
    if steps < 1:
        raise ValueError(f"a block has at least one step, not {steps}")
    rows, episodes = [], []
    for _ in range(steps):
        transition, ended = envs.step(np.asarray(policy(envs.observations, envs.step_count)))
        rows.append(transition)
        episodes.extend(ended)
    return {f: np.stack([r[f] for r in rows], axis=1) for f in rows[0]}, episodes


def exploration_policy(act: Callable[[Any, jax.Array], jax.Array], obs_mean: np.ndarray, obs_std: np.ndarray,
                       noise: float, sample: Callable[[Any, jax.Array, jax.Array], jax.Array | None] | None = None
                       ) -> Callable:
    """jit(vmap over members) of the online action on normalised observations: (states (S..), keys (S, 2),
    observations (S, D), env step) -> (S, A).  `sample(state, obs, key)`, where the family has one and it gives an
    action (a stochastic actor's sample), else `act` plus Gaussian noise of std `noise`, clipped to [-1, 1] (TD3's
    exploration, for deterministic actors).  Member m at step t uses fold_in(keys[m], t): `exploration_keys(seeds)`."""
    mean, std = jnp.asarray(obs_mean), jnp.asarray(obs_std)

    def one(state, key, obs, step):
        key, x = jax.random.fold_in(key, step), (obs - mean) / std
        sampled = None if sample is None else sample(state, x, key)
        if sampled is not None:
            return sampled
        action = act(state, x)
        return jnp.clip(action + noise * jax.random.normal(key, action.shape), -1.0, 1.0)

    return jax.jit(jax.vmap(one, in_axes=(0, 0, 0, None)))


def exploration_keys(seeds: Sequence[int]) -> jax.Array:
    """(S, 2) the members' exploration keys: fold_in(PRNGKey(seed), EXPLORE)."""
    return seed_keys(tuple(seeds), EXPLORE)
