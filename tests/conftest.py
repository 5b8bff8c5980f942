import numpy as np
import pytest

from offrl_jax.data.dataset import Dataset


def synthetic_dataset(transitions: int = 2000, env: str = "hopper", obs_dim: int = 11, act_dim: int = 3,
                      episode_len: int = 100, seed: int = 0) -> Dataset:
    """A small random dataset (learnable reward 1 + 0.1 s_0) with time-outs every `episode_len` rows, a few
    terminals."""
    rng = np.random.default_rng(seed)
    obs = rng.normal(size=(transitions + 1, obs_dim)).astype(np.float32)
    timeouts = np.zeros(transitions, np.float32)
    timeouts[episode_len - 1::episode_len] = 1
    terminals = np.zeros(transitions, np.float32)
    terminals[episode_len // 2::episode_len * 3] = 1
    return Dataset(obs[:-1], rng.uniform(-1, 1, (transitions, act_dim)).astype(np.float32),
                   (1.0 + 0.1 * obs[:-1, 0]).astype(np.float32), obs[1:], terminals, timeouts, env=env,
                   name=f"{env}-synthetic", source="synthetic")


@pytest.fixture
def tiny_dataset() -> Dataset:
    return synthetic_dataset()
