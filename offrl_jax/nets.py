"""Networks (flax.linen): MLP with optional LayerNorm, actors, critics, vectorised critic ensembles.

Conventions
- Observations are already normalised (see `offrl_jax.data.dataset.normalize_obs`); actions live in [-1, 1].
- `layer_norm=True` puts a LayerNorm after every hidden linear layer, before the activation, never after the last
  layer (the paper's setting, Section 5.1 / Appendix B).  `layer_norm_affine=False` drops its learned scale and
  bias, as the authors' code does (`nn.LayerNorm(256, elementwise_affine=False)`), and costs less on a CPU.
- A critic ensemble of N members is one module whose parameters carry a leading axis N (`nn.vmap`), so TD3's twin
  critics (N = 2) and EDAC's N = 10..50 critics are the same code and evaluate as batched matmuls.
- `Arch` holds what the authors' code sets differently from flax's defaults: LayerNorm epsilon (torch 1e-5, flax
  1e-6), the initialisation scheme (`INITS`) and a constant for the hidden biases (CORL's EDAC: 0.1).
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import flax.linen as nn
import jax
import jax.numpy as jnp

LOG_STD_MIN, LOG_STD_MAX = -5.0, 2.0
# "flax": lecun-normal kernels, zero biases.  "torch": PyTorch's nn.Linear default, kaiming-uniform(a=sqrt(5)) =
# U(+-1/sqrt(fan_in)) for kernel and bias.  "orthogonal": orthogonal kernels (gain sqrt(2) hidden, 1e-2 output),
# zero biases (CORL's CQL today with orthogonal_init=True).  "orthogonal_all": gain sqrt(2) for the output layer too
# (the authors' cql.py, and CORL's before it changed the output layer's).
INITS = ("flax", "torch", "orthogonal", "orthogonal_all")
TANH_LOG_DETS = ("exact", "eps")
FANS = ("in", "out")  # Arch.fan


@dataclasses.dataclass(frozen=True)
class Arch:
    """How the layers are built beyond their widths; hashable, so it can be a flax module attribute."""

    layer_norm_affine: bool = True  # learned LayerNorm scale/bias (False: the authors' elementwise_affine=False)
    layer_norm_eps: float = 1e-6  # flax's default; torch's (the authors') is 1e-5
    init: str = "flax"  # one of INITS
    hidden_bias: float | None = None  # constant hidden-layer bias (CORL's EDAC: 0.1); None: the scheme's own
    # the width "torch"'s bound reads: a layer's input (nn.Linear) or its output (CORL's VectorizedLinear hands
    # kaiming_uniform an (in, out) weight, so its EDAC critics get U(+-1/sqrt(out)))
    fan: str = "in"

    def kernel_init(self, fan_in: int, last: bool):
        if self.init == "torch":
            return _uniform(1.0 / math.sqrt(fan_in))
        if self.init in ("orthogonal", "orthogonal_all"):
            return nn.initializers.orthogonal(1e-2 if last and self.init == "orthogonal" else math.sqrt(2.0))
        return nn.initializers.lecun_normal()

    def bias_init(self, fan_in: int, last: bool):
        if self.hidden_bias is not None and not last:
            return nn.initializers.constant(self.hidden_bias)
        if self.init == "torch":
            return _uniform(1.0 / math.sqrt(fan_in))
        return nn.initializers.zeros


def _uniform(bound: float):
    """U(-bound, bound), any shape."""
    def init(key, shape, dtype=jnp.float32):
        return jax.random.uniform(key, shape, dtype, -bound, bound)
    return init


class MLP(nn.Module):
    """[Dense -> (LayerNorm) -> ReLU] * len(hidden) -> Dense(out_dim).  x: (..., in) -> (..., out_dim)."""

    hidden: Sequence[int]
    out_dim: int
    layer_norm: bool = True
    out_scale: float | None = None  # if set: final layer uniformly initialised in [-out_scale, out_scale] (EDAC/SAC-N)
    arch: Arch = Arch()

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        a = self.arch
        for width in self.hidden:
            fan_in = x.shape[-1] if a.fan == "in" else width
            x = nn.Dense(width, kernel_init=a.kernel_init(fan_in, False), bias_init=a.bias_init(fan_in, False))(x)
            if self.layer_norm:
                x = nn.LayerNorm(epsilon=a.layer_norm_eps, use_scale=a.layer_norm_affine,
                                 use_bias=a.layer_norm_affine)(x)
            x = nn.relu(x)
        fan_in = x.shape[-1] if a.fan == "in" else self.out_dim
        if self.out_scale is None:
            init = dict(kernel_init=a.kernel_init(fan_in, True), bias_init=a.bias_init(fan_in, True))
            return nn.Dense(self.out_dim, **init)(x)
        shifted = _uniform(self.out_scale)
        return nn.Dense(self.out_dim, kernel_init=shifted, bias_init=shifted)(x)


class DeterministicActor(nn.Module):
    """TD3-style actor: obs (..., obs_dim) -> action (..., act_dim) in [-1, 1] via tanh."""

    act_dim: int
    hidden: Sequence[int] = (256, 256)
    layer_norm: bool = True
    arch: Arch = Arch()
    out_scale: float | None = None  # final layer U(+-out_scale) (ReBRAC: 1e-3); None: the arch's own init

    @nn.compact
    def __call__(self, obs: jax.Array) -> jax.Array:
        return jnp.tanh(MLP(self.hidden, self.act_dim, self.layer_norm, self.out_scale, self.arch)(obs))


class TanhGaussianActor(nn.Module):
    """SAC-style actor: obs (..., obs_dim) -> (mean, log_std), each (..., act_dim); log_std = clip(raw + offset,
    *log_std_bounds) (EDAC: [-5, 2], offset 0; CORL's CQL: [-20, 2], offset -1).

    The policy is a = tanh(u), u ~ N(mean, exp(log_std)); use `sample_tanh_gaussian` / `tanh_gaussian_log_prob`.
    """

    act_dim: int
    hidden: Sequence[int] = (256, 256, 256)
    layer_norm: bool = True
    arch: Arch = Arch()
    log_std_bounds: tuple[float, float] = (LOG_STD_MIN, LOG_STD_MAX)
    log_std_offset: float = 0.0
    out_scale: float | None = 1e-3  # final layer U(+-out_scale) (EDAC); None: the arch's own init

    @nn.compact
    def __call__(self, obs: jax.Array) -> tuple[jax.Array, jax.Array]:
        out = MLP(self.hidden, 2 * self.act_dim, self.layer_norm, self.out_scale, self.arch)(obs)
        mean, log_std = jnp.split(out, 2, axis=-1)
        return mean, jnp.clip(log_std + self.log_std_offset, *self.log_std_bounds)


def tanh_gaussian_log_prob(mean: jax.Array, log_std: jax.Array, action: jax.Array, eps: float = 1e-6,
                           log_det: str = "exact") -> jax.Array:
    """log pi(action | s) for a = tanh(u), u ~ N(mean, std).  mean, log_std, action: (..., A) -> (...,).

    Dataset actions are clipped to +-(1 - eps) before atanh so that |a| = 1 stays finite.  `log_det`: see
    `_log_prob_pre_tanh`.
    """
    action = jnp.clip(action, -1.0 + eps, 1.0 - eps)
    u = jnp.arctanh(action)
    return _log_prob_pre_tanh(mean, log_std, u, log_det)


def _log_prob_pre_tanh(mean: jax.Array, log_std: jax.Array, u: jax.Array, log_det: str = "exact") -> jax.Array:
    """log N(u; mean, std) - log|d tanh(u)/du|, summed over the action dims.  log_det "exact": log(1 - tanh(u)^2) =
    2 (log 2 - u - softplus(-2u)), stable for any u; "eps": log(1 - tanh(u)^2 + 1e-6), CORL's and the authors' form
    (it caps the correction near |a| = 1)."""
    gauss = -0.5 * (((u - mean) / jnp.exp(log_std)) ** 2) - log_std - 0.5 * jnp.log(2 * jnp.pi)
    if log_det == "eps":
        log_det_value = jnp.log(1.0 - jnp.tanh(u) ** 2 + 1e-6)
    else:
        log_det_value = 2.0 * (jnp.log(2.0) - u - jax.nn.softplus(-2.0 * u))
    return jnp.sum(gauss - log_det_value, axis=-1)


def sample_tanh_gaussian(key: jax.Array, mean: jax.Array, log_std: jax.Array,
                         log_det: str = "exact") -> tuple[jax.Array, jax.Array]:
    """Reparameterised sample a = tanh(mean + std * eps) and its log-prob.  (..., A) -> ((..., A), (...,))."""
    u = mean + jnp.exp(log_std) * jax.random.normal(key, mean.shape)
    return jnp.tanh(u), _log_prob_pre_tanh(mean, log_std, u, log_det)


class GaussianActor(nn.Module):
    """IQL's and AWAC's Gaussian policy: obs (..., obs_dim) -> (mean, log_std), mean = tanh(MLP(obs)) (..., act_dim)
    (IQL; `tanh_mean` False: MLP(obs) itself, AWAC's), log_std a learned state-independent (act_dim,) vector clipped
    to `log_std_bounds`; it acts with the mean."""

    act_dim: int
    hidden: Sequence[int] = (256, 256)
    layer_norm: bool = False
    arch: Arch = Arch()
    log_std_bounds: tuple[float, float] = (-20.0, 2.0)
    tanh_mean: bool = True

    @nn.compact
    def __call__(self, obs: jax.Array) -> tuple[jax.Array, jax.Array]:
        mean = MLP(self.hidden, self.act_dim, self.layer_norm, arch=self.arch)(obs)
        mean = jnp.tanh(mean) if self.tanh_mean else mean
        log_std = self.param("log_std", nn.initializers.zeros, (self.act_dim,))
        return mean, jnp.clip(log_std, *self.log_std_bounds)


def gaussian_log_prob(mean: jax.Array, log_std: jax.Array, action: jax.Array) -> jax.Array:
    """log N(action; mean, exp(log_std)) summed over the action dims.  (..., A), (A,) or (..., A) -> (...,)."""
    return jnp.sum(-0.5 * ((action - mean) / jnp.exp(log_std)) ** 2 - log_std - 0.5 * jnp.log(2 * jnp.pi), axis=-1)


class Value(nn.Module):
    """V(s): obs (..., obs_dim) -> (...,)."""

    hidden: Sequence[int] = (256, 256)
    layer_norm: bool = False
    arch: Arch = Arch()

    @nn.compact
    def __call__(self, obs: jax.Array) -> jax.Array:
        return MLP(self.hidden, 1, self.layer_norm, arch=self.arch)(obs)[..., 0]


class Critic(nn.Module):
    """Q(s, a): obs (..., obs_dim), act (..., act_dim) -> (...,)."""

    hidden: Sequence[int] = (256, 256)
    layer_norm: bool = True
    out_scale: float | None = None
    arch: Arch = Arch()

    @nn.compact
    def __call__(self, obs: jax.Array, act: jax.Array) -> jax.Array:
        x = jnp.concatenate([obs, act], axis=-1)
        return MLP(self.hidden, 1, self.layer_norm, self.out_scale, self.arch)(x)[..., 0]


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
    arch: Arch = Arch()

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
        return ensemble(self.hidden, self.layer_norm, self.out_scale, self.arch)(obs, act)

    def member(self, variables: dict, i: int) -> tuple[Critic, dict]:
        """Member i as a plain `Critic` and its variables: `critic.apply(v, obs, act)` (...,) equals
        `self.apply(variables, obs, act)[i]`.  Cheaper than a 1-member ensemble on XLA CPU, whose reductions over
        rows with a leading axis of size 1 ran 7x slower than the same reductions without it (benchmarks/README.md,
        "Against unifloral")."""
        critic = Critic(self.hidden, self.layer_norm, self.out_scale, self.arch, parent=None)
        return critic, {"params": jax.tree.map(lambda x: x[i], variables["params"]["VmapCritic_0"])}
