"""Monte-Carlo returns of online episodes, with the offline data's rules (`offrl_jax.data.returns.returns_to_go`):
an episode that ends in a terminal has no tail; one cut by the time limit gets its last reward repeated forever,
r_T / (1 - gamma), when `timeout_tail` (the default, as for the offline returns).

`episode_returns` is one ended episode's; `window_returns` is what the buffer writes when an insert ends episodes:
the returns of the rows of a window (the newest rows of a member's ring, oldest first) that belong to an episode that
has ended, the other rows unchanged.
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from offrl_jax.data.returns import returns_to_go


def episode_returns(rewards: np.ndarray, terminal: bool, gamma: float, timeout_tail: bool = True) -> jax.Array:
    """The discounted return-to-go of every step of one ended episode.  rewards: (n,) -> (n,) float32.

    `terminal`: the episode ended in a true terminal (else the time limit cut it)."""
    n = len(rewards)
    if not n:
        raise ValueError("an episode has at least one step")
    end = np.zeros(n, np.float32)
    end[-1] = 1.0
    terminals, timeouts = (end, np.zeros(n, np.float32)) if terminal else (np.zeros(n, np.float32), end)
    return returns_to_go(np.asarray(rewards, np.float32), terminals, timeouts, gamma, timeout_tail)


def window_returns(returns: jax.Array, rewards: jax.Array, terminals: jax.Array, timeouts: jax.Array,
                   first: jax.Array, last: jax.Array, gamma: float, timeout_tail: bool = True) -> jax.Array:
    """`returns` with rows first..last (inclusive) replaced by their returns-to-go.  (W,) each, first/last () -> (W,).

    The rows are a window of consecutive transitions, oldest first.  Row `last` must end an episode (or last < first:
    nothing ends, nothing changes); rows before `first` may be anything (older episodes, unfilled rows), since a
    return depends only on the rows after it, up to its episode's end."""
    rtg = returns_to_go(rewards, terminals, timeouts, gamma, timeout_tail)
    rows = jnp.arange(returns.shape[0])
    return jnp.where((rows >= first) & (rows <= last), rtg, returns)
