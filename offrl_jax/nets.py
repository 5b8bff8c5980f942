"""Networks (flax.linen): MLP with optional LayerNorm, actors, critics, vectorised critic ensembles.

Conventions
- Observations are already normalised (see `offrl_jax.data.dataset.normalize_obs`); actions live in [-1, 1].
- `layer_norm=True` puts a LayerNorm after every hidden linear layer, before the activation, never after the last
  layer (the paper's setting, Section 5.1 / Appendix B).  `layer_norm_affine=False` drops its learned scale and
  bias, as the authors' code does (`nn.LayerNorm(256, elementwise_affine=False)`), and costs less on a CPU.
- A critic ensemble of N members is one module whose parameters carry a leading axis N (`nn.vmap`), so TD3's twin
  critics (N = 2) and EDAC's N = 10..50 critics are the same code and evaluate as batched matmuls.
"""
from __future__ import annotations

from collections.abc import Sequence

import flax.linen as nn
import jax
import jax.numpy as jnp

LOG_STD_MIN, LOG_STD_MAX = -5.0, 2.0


class MLP(nn.Module):
    """[Dense -> (LayerNorm) -> ReLU] * len(hidden) -> Dense(out_dim).  x: (..., in) -> (..., out_dim)."""

    hidden: Sequence[int]
    out_dim: int
    layer_norm: bool = True
    out_scale: float | None = None  # if set: final layer uniformly initialised in [-out_scale, out_scale] (EDAC/SAC-N)
    layer_norm_affine: bool = True  # learned LayerNorm scale and bias (False: the authors' elementwise_affine=False)

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        for width in self.hidden:
            x = nn.Dense(width)(x)
            if self.layer_norm:
                x = nn.LayerNorm(use_scale=self.layer_norm_affine, use_bias=self.layer_norm_affine)(x)
            x = nn.relu(x)
        if self.out_scale is None:
            return nn.Dense(self.out_dim)(x)
        init = nn.initializers.uniform(2 * self.out_scale)
        shifted = lambda key, shape, dtype=jnp.float32: init(key, shape, dtype) - self.out_scale  # noqa: E731
        return nn.Dense(self.out_dim, kernel_init=shifted, bias_init=shifted)(x)


class DeterministicActor(nn.Module):
    """TD3-style actor: obs (..., obs_dim) -> action (..., act_dim) in [-1, 1] via tanh."""

    act_dim: int
    hidden: Sequence[int] = (256, 256)
    layer_norm: bool = True
    layer_norm_affine: bool = True

    @nn.compact
    def __call__(self, obs: jax.Array) -> jax.Array:
        return jnp.tanh(MLP(self.hidden, self.act_dim, self.layer_norm, layer_norm_affine=self.layer_norm_affine)(obs))


class TanhGaussianActor(nn.Module):
    """SAC-style actor: obs (..., obs_dim) -> (mean, log_std), each (..., act_dim); log_std clipped to [-5, 2].

    The policy is a = tanh(u), u ~ N(mean, exp(log_std)); use `sample_tanh_gaussian` / `tanh_gaussian_log_prob`.
    """

    act_dim: int
    hidden: Sequence[int] = (256, 256, 256)
    layer_norm: bool = True
    layer_norm_affine: bool = True

    @nn.compact
    def __call__(self, obs: jax.Array) -> tuple[jax.Array, jax.Array]:
        out = MLP(self.hidden, 2 * self.act_dim, self.layer_norm, 1e-3, self.layer_norm_affine)(obs)
        mean, log_std = jnp.split(out, 2, axis=-1)
        return mean, jnp.clip(log_std, LOG_STD_MIN, LOG_STD_MAX)


def tanh_gaussian_log_prob(mean: jax.Array, log_std: jax.Array, action: jax.Array, eps: float = 1e-6) -> jax.Array:
    """log pi(action | s) for a = tanh(u), u ~ N(mean, std).  mean, log_std, action: (..., A) -> (...,).

    Dataset actions are clipped to +-(1 - eps) before atanh so that |a| = 1 stays finite.
    """
    action = jnp.clip(action, -1.0 + eps, 1.0 - eps)
    u = jnp.arctanh(action)
    return _log_prob_pre_tanh(mean, log_std, u)


def _log_prob_pre_tanh(mean: jax.Array, log_std: jax.Array, u: jax.Array) -> jax.Array:
    gauss = -0.5 * (((u - mean) / jnp.exp(log_std)) ** 2) - log_std - 0.5 * jnp.log(2 * jnp.pi)
    # log|d tanh(u)/du| = log(1 - tanh(u)^2) = 2 (log 2 - u - softplus(-2u)), numerically stable.
    log_det = 2.0 * (jnp.log(2.0) - u - jax.nn.softplus(-2.0 * u))
    return jnp.sum(gauss - log_det, axis=-1)


def sample_tanh_gaussian(key: jax.Array, mean: jax.Array, log_std: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Reparameterised sample a = tanh(mean + std * eps) and its log-prob.  (..., A) -> ((..., A), (...,))."""
    u = mean + jnp.exp(log_std) * jax.random.normal(key, mean.shape)
    return jnp.tanh(u), _log_prob_pre_tanh(mean, log_std, u)


class Critic(nn.Module):
    """Q(s, a): obs (..., obs_dim), act (..., act_dim) -> (...,)."""

    hidden: Sequence[int] = (256, 256)
    layer_norm: bool = True
    out_scale: float | None = None
    layer_norm_affine: bool = True

    @nn.compact
    def __call__(self, obs: jax.Array, act: jax.Array) -> jax.Array:
        x = jnp.concatenate([obs, act], axis=-1)
        return MLP(self.hidden, 1, self.layer_norm, self.out_scale, self.layer_norm_affine)(x)[..., 0]


class CriticEnsemble(nn.Module):
    """N critics with stacked parameters.  obs (..., obs_dim), act (..., act_dim) -> (N, ...).

    `act` may also carry the leading ensemble axis, act (N, ..., act_dim), when each member gets its own actions
    (`per_member_actions=True`), e.g. for the per-critic action gradients of EDAC's diversity loss.
    """

    num: int = 2
    hidden: Sequence[int] = (256, 256)
    layer_norm: bool = True
    out_scale: float | None = None
    per_member_actions: bool = False
    layer_norm_affine: bool = True

    @nn.compact
    def __call__(self, obs: jax.Array, act: jax.Array) -> jax.Array:
        ensemble = nn.vmap(
            Critic,
            variable_axes={"params": 0},
            split_rngs={"params": True},
            in_axes=(None, 0 if self.per_member_actions else None),
            out_axes=0,
            axis_size=self.num,
        )
        return ensemble(self.hidden, self.layer_norm, self.out_scale, self.layer_norm_affine)(obs, act)
