"""Env registry: short names -> gymnasium ids, time limits, D4RL reference scores, default hyper-parameters.

normalized score = 100 * (R - random) / (expert - random), with D4RL's reference returns for the same env names so
results compare with published tables.  Adroit uses the paper's longer time limits and re-computed random scores
(Appendix H, Table 4); the max (human) scores are D4RL's.
"""
from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class EnvSpec:
    name: str
    gym_id: str
    max_episode_steps: int
    ref_min_score: float
    ref_max_score: float
    obs_dim: int
    act_dim: int
    adroit: bool = False


ENVS: dict[str, EnvSpec] = {
    spec.name: spec
    for spec in [
        EnvSpec("hopper", "Hopper-v5", 1000, -20.272305, 3234.3, 11, 3),
        EnvSpec("halfcheetah", "HalfCheetah-v5", 1000, -280.178953, 12135.0, 17, 6),
        EnvSpec("walker2d", "Walker2d-v5", 1000, 1.629008, 4592.3, 17, 6),
        EnvSpec("pen", "AdroitHandPen-v1", 100, -162.09, 3076.83, 45, 24, adroit=True),
        EnvSpec("door", "AdroitHandDoor-v1", 300, -84.52, 2880.5693, 39, 28, adroit=True),
        EnvSpec("hammer", "AdroitHandHammer-v1", 624, -856.83, 12794.13, 46, 26, adroit=True),
        EnvSpec("relocate", "AdroitHandRelocate-v1", 527, -37.95, 4233.88, 39, 30, adroit=True),
    ]
}


def get_env_spec(name: str) -> EnvSpec:
    """Look up an env by short name ("hopper") or by a dataset name that starts with it ("hopper-medium")."""
    key = name.split("-")[0].lower()
    if key not in ENVS:
        raise ValueError(f"unknown env '{name}'; valid: {', '.join(ENVS)}")
    return ENVS[key]


def normalized_score(env: str, returns: np.ndarray | float) -> np.ndarray | float:
    spec = get_env_spec(env)
    return 100.0 * (np.asarray(returns) - spec.ref_min_score) / (spec.ref_max_score - spec.ref_min_score)


def warn_once_per_message() -> None:
    """Print each distinct MuJoCo warning once per process (MuJoCo 3.3+ warns on every compile of halfcheetah's
    deprecated `settotalmass`, once per env an evaluation or a collection makes)."""
    import sys

    import mujoco

    if getattr(mujoco.get_mju_user_warning(), "offrl_jax", False):
        return
    seen: set[str] = set()

    def handler(message) -> None:
        text = message.decode(errors="replace") if isinstance(message, bytes) else str(message)
        if text not in seen:
            seen.add(text)
            print(f"WARNING: {text} (MuJoCo; shown once)", file=sys.stderr)

    handler.offrl_jax = True
    mujoco.set_mju_user_warning(handler)


def make_env(name: str, max_episode_steps: int | None = None, **kwargs):
    """A gymnasium env with this project's time limit (the paper's longer limits for Adroit), or
    `max_episode_steps`; Adroit envs with D4RL's reward either way."""
    import gymnasium as gym

    warn_once_per_message()

    spec = get_env_spec(name)
    if spec.adroit:
        import gymnasium_robotics

        gym.register_envs(gymnasium_robotics)
    from offrl_jax.envs.adroit import (
        with_original_reward,  # D4RL's dense reward (gymnasium-robotics >= 1.2.1 flips a sign)
    )

    limit = spec.max_episode_steps if max_episode_steps is None else max_episode_steps
    return with_original_reward(gym.make(spec.gym_id, max_episode_steps=limit, **kwargs))
