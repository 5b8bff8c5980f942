"""Every-visit discounted returns-to-go, per episode, vectorised (no Python loop over transitions).

An episode ends at a terminal, a time-out, or the dataset end.  With `timeout_tail` (default, as in the authors'
code) the last reward of an episode that ends in a time-out or at the dataset end is replaced by r_T / (1 - gamma):
the last reward repeated forever, since the task did not end there.  A true terminal gets no tail.

The recurrence G_t = b_t + c_t G_{t+1} (c_t = 0 at episode ends, gamma otherwise) is a composition of affine maps,
which `lax.associative_scan` evaluates in O(log T) depth: 1M transitions in a few milliseconds, jit- and vmap-able
(so every seed can compute soft returns with its own policy inside one compiled program).
"""
from __future__ import annotations

import jax
import jax.numpy as jnp


def _episode_flags(terminals: jax.Array, timeouts: jax.Array, timeout_tail: bool) -> tuple[jax.Array, jax.Array]:
    """(ends, tail): the row ends its episode; the row gets the r / (1 - gamma) tail.  (T,) -> (T,) bool each."""
    terminal = terminals > 0
    ends = terminal | (timeouts > 0)
    ends = ends.at[-1].set(True)
    tail = ends & ~terminal & timeout_tail
    return ends, tail


def _discounted_sum(values: jax.Array, ends: jax.Array, gamma: float) -> jax.Array:
    """G_t = values_t + gamma * G_{t+1}, restarting after every row where ends is True.  (T,), (T,) -> (T,)."""
    decay = jnp.where(ends, 0.0, gamma).astype(values.dtype)

    def compose(later, earlier):  # reverse scan: `later` accumulates rows t+1.., `earlier` is row t
        c_later, b_later = later
        c_now, b_now = earlier
        return c_now * c_later, b_now + c_now * b_later

    _, returns = jax.lax.associative_scan(compose, (decay, values), reverse=True)
    return returns


@jax.jit(static_argnames=("timeout_tail",))
def returns_to_go(
    rewards: jax.Array, terminals: jax.Array, timeouts: jax.Array, gamma: float, timeout_tail: bool = True
) -> jax.Array:
    """Discounted return-to-go of every transition.  rewards, terminals, timeouts: (T,) -> (T,) float32."""
    rewards = jnp.asarray(rewards, jnp.float32)
    ends, tail = _episode_flags(jnp.asarray(terminals), jnp.asarray(timeouts), timeout_tail)
    values = jnp.where(tail, rewards / (1.0 - gamma), rewards)
    return _discounted_sum(values, ends, gamma)


@jax.jit(static_argnames=("timeout_tail",))
def soft_returns_to_go(
    rewards: jax.Array,
    next_entropies: jax.Array,
    terminals: jax.Array,
    timeouts: jax.Array,
    gamma: float,
    alpha: jax.Array | float,
    timeout_tail: bool = True,
) -> jax.Array:
    """Soft return-to-go (eq. 8): R_t + alpha sum_{n>=1} gamma^n H(pi(.|s_{t+n})).  (T,) each -> (T,).

    `next_entropies[t]` is the entropy estimate at the transition's next observation s_{t+1} (-log pi(a~|s_{t+1}),
    a~ ~ pi).  Folding it into the reward, r'_t = r_t + gamma alpha H(s_{t+1}), makes this the plain return of r'.
    A terminal's successor is absorbing (no entropy bonus); a time-out's tail r'_T / (1 - gamma) repeats the entropy
    bonus as well as the reward.

    Versus the authors' form (`soft_returns_to_go_from_states`): inside an episode the two are identical.  At its
    last row T they give the soft part 0 and row T-1 the bonus gamma H(s_T) / (1 - gamma); here row T gets gamma
    alpha H(s_{T+1}) (/ (1 - gamma) at a time-out), the entropy of the state the episode actually continues from,
    so the last row is not the only one without an entropy term.
    """
    rewards = jnp.asarray(rewards, jnp.float32)
    terminal = jnp.asarray(terminals) > 0
    soft_rewards = rewards + jnp.where(terminal, 0.0, gamma * alpha * next_entropies)
    ends, tail = _episode_flags(terminal, jnp.asarray(timeouts), timeout_tail)
    values = jnp.where(tail, soft_rewards / (1.0 - gamma), soft_rewards)
    return _discounted_sum(values, ends, gamma)


@jax.jit(static_argnames=("timeout_tail",))
def soft_returns_to_go_from_states(
    rewards: jax.Array,
    entropies: jax.Array,
    terminals: jax.Array,
    timeouts: jax.Array,
    gamma: float,
    alpha: jax.Array | float,
    timeout_tail: bool = True,
) -> jax.Array:
    """The authors' soft return-to-go: R_t + alpha sum_{k=t+1}^{T} gamma^(k-t) H'_k.  (T,) each -> (T,).

    `entropies[t]` is the entropy estimate at the row's own observation s_t; T is the episode's last row, and H'_T
    is H_T / (1 - gamma) where the reward gets its tail (a time-out or the dataset end).  So the last row of an
    episode has no entropy term, and the row before it carries gamma H(s_T) / (1 - gamma) (`soft_returns_to_go`
    gives the last row gamma alpha H(s_{T+1}) instead).  Written as the plain return of
    r'_t = r_t + gamma alpha H'_{t+1} (0 on the episode's last row).
    """
    rewards = jnp.asarray(rewards, jnp.float32)
    entropies = jnp.asarray(entropies, jnp.float32)
    ends, tail = _episode_flags(jnp.asarray(terminals), jnp.asarray(timeouts), timeout_tail)
    tailed = lambda x: jnp.where(tail, x / (1.0 - gamma), x)  # noqa: E731
    next_entropies = jnp.append(tailed(entropies)[1:], 0.0)  # H'_{t+1}, within the episode (ends: unused)
    values = tailed(rewards) + jnp.where(ends, 0.0, gamma * alpha * next_entropies)
    return _discounted_sum(values, ends, gamma)
