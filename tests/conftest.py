"""Shared fixtures.  The suite compiles the same small XLA programs many times, in this process and in the commands
it starts, so it shares one persistent compilation cache (JAX's own, keyed by program, options and versions):
compilation is most of a tiny run's time.  $JAX_COMPILATION_CACHE_DIR, if set, is used instead."""
import os
import tempfile

os.environ.setdefault("JAX_COMPILATION_CACHE_DIR",
                      os.path.join(tempfile.gettempdir(), f"offrl-jax-test-compile-cache-{os.getuid()}"))
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0")
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES", "-1")

import jax  # noqa: E402  (after the environment it reads)
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from offrl_jax.data.dataset import Dataset  # noqa: E402

jax.config.update("jax_compilation_cache_dir", os.environ["JAX_COMPILATION_CACHE_DIR"])
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0)
jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)


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
