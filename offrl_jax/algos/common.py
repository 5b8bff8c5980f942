"""What every algorithm shares: a trainable `Model` (params + target + optimiser state), the `Phase` record the
driver runs, and small helpers to take a gradient step and to chain update functions.

An algorithm is a frozen config plus pure functions:
    init(key) -> AgentState                                  (a pytree of arrays: vmappable over seeds, checkpointable)
    phases(total_updates) -> list[Phase]                     (pre-training phases, then offline RL)
    act(state, obs) -> action                                (deterministic policy for evaluation)
Each `Phase.update(state, batch, key) -> (state, metrics)` is one scan body; batch leaves are (k, B, ...) with
k = `Phase.updates_per_call` minibatches (k = 2 for TD3's delayed actor update).  `single` / `first` hand a loss the
(B, ...) minibatch.

A minibatch (`Batch`: `driver.DATA_FIELDS` drawn uniformly from `driver.device_data`, plus `idx`), for B rows:
    observations       (B, obs_dim)  normalised with the dataset mean / std
    actions            (B, act_dim)  in [-1, 1]
    rewards            (B,)
    next_observations  (B, obs_dim)  normalised
    terminals          (B,)          1.0 at a true terminal only, so TD targets bootstrap through time-outs
    timeouts           (B,)          1.0 where the time limit cut an episode
    returns            (B,)          Monte-Carlo discounted return-to-go (`offrl_jax.data.returns.returns_to_go`)
    idx                (B,)          the rows' dataset indices: EDAC reads its soft returns `state.soft_returns[idx]`,
                                     which depend on the pre-trained actor and so live in the state, not the data
"""
from __future__ import annotations

import copy
import dataclasses
import math
import numbers
import types
import typing
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import struct

from offrl_jax.losses import BALANCES
from offrl_jax.nets import INITS, Arch

# What a TD target does at a time-out (the time limit cut the episode, the task did not end):
#   "bootstrap"  r + gamma Q(s', a') as anywhere else (the state is not terminal)
#   "stop"       r, as at a terminal (the authors' code: dones = terminals + timeouts)
#   "drop"       the row is never sampled (CORL's loader drops it: its next observation is not recorded)
TIMEOUTS = ("bootstrap", "stop", "drop")

Params = Any
Batch = dict[str, jax.Array]
Metrics = dict[str, jax.Array]
UpdateFn = Callable[[Any, Batch, jax.Array], tuple[Any, Metrics]]


@struct.dataclass
class Model:
    params: Params
    opt_state: optax.OptState
    target: Params | None = None


def new_model(params: Params, tx: optax.GradientTransformation, with_target: bool) -> Model:
    return Model(params=params, opt_state=tx.init(params), target=params if with_target else None)


def gradient_step(model: Model, tx: optax.GradientTransformation, loss_fn: Callable, *args) -> tuple[Model, Metrics]:
    """One optimiser step on `loss_fn(params, *args) -> (loss, metrics)`; returns the new model and the metrics."""
    grads, metrics = jax.grad(loss_fn, has_aux=True)(model.params, *args)
    updates, opt_state = tx.update(grads, model.opt_state, model.params)
    return model.replace(params=optax.apply_updates(model.params, updates), opt_state=opt_state), metrics


def polyak(model: Model, tau: float) -> Model:
    """target <- tau * params + (1 - tau) * target."""
    return model.replace(target=optax.incremental_update(model.params, model.target, tau))


@dataclasses.dataclass(frozen=True)
class Phase:
    name: str  # "actor_pretrain", "critic_pretrain", "pretrain", "offline_rl"
    update: UpdateFn
    steps: int  # gradient updates in this phase (a multiple of updates_per_call)
    updates_per_call: int = 1
    # Called once (jitted, vmapped over seeds) before the phase starts: (state, data, key) -> state.
    on_start: Callable[[Any, Batch, jax.Array], Any] | None = None
    # Pre-training that ends itself (`AutoStop`); `steps` is then its cap.
    auto_stop: AutoStop | None = None


@dataclasses.dataclass(frozen=True)
class AutoStop:
    """End a phase when its supervised losses stop improving (the paper: "pre-train until convergence ...
    determined by monitoring the convex supervised loss functions").

    Every `window` updates the driver takes each monitored metric's mean over that window, per member, and compares
    it with the previous window's: the phase ends when, for every member and every metric, the relative
    improvement (previous - current) / |previous| is below `tol`.  All members hand over together; the updates
    left of the phase's cap go to the last phase (offline RL), so the total budget is unchanged.
    """

    monitor: tuple[str, ...]  # metric names, e.g. ("bc_loss", "mc_error")
    window: int = 1_000
    tol: float = 0.01

    def converged(self, previous: dict[str, Any] | None, current: dict[str, Any]) -> bool:
        if previous is None:
            return False
        for name in self.monitor:
            prev, cur = np.asarray(previous[name], np.float64), np.asarray(current[name], np.float64)
            if not np.all((prev - cur) < self.tol * np.abs(prev)):
                return False
        return True


def with_hparams(algo: Any, **values: Any) -> Any:
    """A shallow copy of `algo` whose config holds `values` (traced, in a vmapped sweep) instead of its own.

    Only the config's `SWEEPABLE` fields may be swept: they enter the losses as plain arithmetic (never a Python `if`
    or a shape), so a traced value computes exactly what the concrete value would.
    """
    cfg = copy.copy(algo.cfg)
    for name, value in values.items():
        if name not in type(cfg).SWEEPABLE:
            raise ValueError(f"'{name}' cannot be swept in one program; sweepable: {', '.join(type(cfg).SWEEPABLE)}")
        object.__setattr__(cfg, name, value)  # frozen dataclass: bypass __setattr__ (and validation of a tracer)
    new = copy.copy(algo)
    new.cfg = cfg
    return new


def first(batch: Batch, i: int = 0) -> Batch:
    """The i-th of the k stacked minibatches."""
    return jax.tree.map(lambda x: x[i], batch)


def chain(*updates: UpdateFn) -> UpdateFn:
    """Run several single-batch update functions on the same minibatch, one after another; merge their metrics."""

    def update(state, batch: Batch, key: jax.Array):
        metrics: Metrics = {}
        for fn, k in zip(updates, jax.random.split(key, len(updates))):
            state, m = fn(state, batch, k)
            metrics.update(m)
        return state, metrics

    return update


def single(update: UpdateFn) -> UpdateFn:
    """Adapt a single-minibatch update to the driver's stacked (1, B, ...) batch."""
    return lambda state, batch, key: update(state, first(batch), key)


def split_budget(total: int, pretrain: int) -> tuple[int, int]:
    """(pre-training updates, RL updates): pre-training counts inside the total budget."""
    if pretrain > total:
        raise ValueError(f"pre-training updates ({pretrain}) exceed the total budget ({total})")
    return pretrain, total - pretrain


def _typed(annotation: Any, value: Any) -> tuple[bool, Any, str]:
    """(value fits `annotation`, the value as the field stores it, what the field must be).  JSON's forms are
    accepted and converted: a list for a tuple, an integer for a float; so are numpy's scalars."""
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if origin in (typing.Union, types.UnionType):  # X | None
        if value is None and type(None) in args:
            return True, None, ""
        inner = [a for a in args if a is not type(None)]
        if len(inner) != 1:
            return True, value, ""
        ok, value, need = _typed(inner[0], value)
        return ok, value, need + (" or None" if type(None) in args else "")
    if annotation is bool:
        return isinstance(value, (bool, np.bool_)), bool(value) if isinstance(value, np.bool_) else value, \
            "must be True or False"
    if annotation is int:
        ok = isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_))
        return ok, int(value) if ok else value, "must be an integer"
    if annotation is float:
        ok = isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))
        try:
            return ok, float(value) if ok else value, "must be a number"
        except OverflowError:  # an integer too large for a float
            return False, value, "must be a finite number"
    if annotation is str:
        return isinstance(value, str), value, "must be a string"
    if origin is typing.Literal:
        need = f"must be {args[0]!r} or {args[1]!r}" if len(args) == 2 else f"must be one of {', '.join(args)}"
        return isinstance(value, str) and value in args, value, need
    if origin is tuple:
        element = args[0]
        need = (f"must be a tuple of {'integers' if element is int else 'numbers'}" if args[1:] == (...,) else
                f"must be a tuple of {len(args)} {'integers' if element is int else 'finite numbers'}")
        if not isinstance(value, (tuple, list)) or (args[1:] != (...,) and len(value) != len(args)):
            return False, value, need
        items = [_typed(element, x) for x in value]
        ok = all(fits for fits, _, _ in items) and all(
            math.isfinite(x) for _, x, _ in items if element is float and isinstance(x, float))
        return ok, tuple(x for _, x, _ in items) if ok else value, need
    return True, value, ""  # an annotation this check does not know: the config's own checks decide


def check_types(cfg) -> None:
    """Check every field of a config dataclass against its annotation, before the value checks, and store JSON's
    forms as the annotation says (see `_typed`), so a config read back from config.json equals the one written."""
    hints = typing.get_type_hints(type(cfg))
    for field in dataclasses.fields(cfg):
        value = getattr(cfg, field.name)
        ok, typed, need = _typed(hints[field.name], value)
        if not ok:
            raise ValueError(f"{type(cfg).__name__}.{field.name} = {value!r} {need}")
        if typed is not value:
            object.__setattr__(cfg, field.name, typed)  # frozen dataclass


def validate_common(cfg) -> None:
    """Reject invalid hyper-parameters with one line naming the field (shared by every config): the types first
    (`check_types`), then the values."""
    check_types(cfg)
    for field in dataclasses.fields(cfg):
        value = getattr(cfg, field.name)
        if isinstance(value, float) and not math.isfinite(value):
            raise ValueError(f"{type(cfg).__name__}.{field.name} = {value!r} must be a finite number")
    checks = [
        ("gamma", 0.0 < cfg.gamma < 1.0, "must be in (0, 1) (a time-out's return tail is r / (1 - gamma))"),
        ("tau", 0.0 < cfg.tau <= 1.0, "must be in (0, 1]"),
        ("lam", 0.0 <= cfg.lam <= 1.0, "must be in [0, 1]"),
        ("actor_lr", cfg.actor_lr > 0, "must be positive"),
        ("critic_lr", cfg.critic_lr > 0, "must be positive"),
        ("pretrain_updates", cfg.pretrain_updates >= 0, "must be >= 0"),
        ("pretrain_auto_window", cfg.pretrain_auto_window > 0, "must be positive"),
        ("pretrain_auto_tol", cfg.pretrain_auto_tol >= 0, "must be >= 0"),
        ("hidden", len(cfg.hidden) > 0 and all(h > 0 for h in cfg.hidden), "must be positive layer widths"),
        ("pretrain", cfg.pretrain in ("none", "actor", "critic", "actor+critic"),
         "must be one of none, actor, critic, actor+critic"),
        ("lambda_mode", cfg.lambda_mode in ("loss", "target"), "must be 'loss' or 'target'"),
        ("num_critics", cfg.num_critics >= 1, "must be >= 1"),
        ("cql_actions", cfg.cql_actions >= 1, "must be >= 1"),
        ("actor_hidden", cfg.actor_hidden is None or (len(cfg.actor_hidden) > 0 and all(h > 0 for h in
                                                                                        cfg.actor_hidden)),
         "must be positive layer widths"),
        ("layer_norm_eps", cfg.layer_norm_eps > 0, "must be positive"),
        ("init", cfg.init in INITS, f"must be one of {', '.join(INITS)}"),
        ("timeouts", cfg.timeouts in TIMEOUTS, f"must be one of {', '.join(TIMEOUTS)}"),
        ("balance", cfg.balance in BALANCES, f"must be one of {', '.join(BALANCES)}"),
    ]
    for name, ok, message in checks:
        if not ok:
            raise ValueError(f"{type(cfg).__name__}.{name} = {getattr(cfg, name)!r} {message}")


def auto_stop_of(cfg, monitor: tuple[str, ...]) -> AutoStop | None:
    """The stopping rule of a pre-training phase that watches `monitor`, or None when pre-training is fixed-length."""
    return AutoStop(monitor, cfg.pretrain_auto_window, cfg.pretrain_auto_tol) if cfg.pretrain_auto else None


def arch_of(cfg) -> Arch:
    """The layer-building choices shared by every config (LayerNorm form, initialisation)."""
    return Arch(layer_norm_affine=cfg.layer_norm_affine, layer_norm_eps=cfg.layer_norm_eps, init=cfg.init,
                hidden_bias=getattr(cfg, "hidden_bias", None))


def done_flags(batch: Batch, timeouts: str) -> jax.Array:
    """(B,) 1.0 where a TD target stops bootstrapping: terminals, plus time-outs when `timeouts` is "stop"."""
    if timeouts == "stop":
        return jnp.maximum(batch["terminals"], batch["timeouts"])
    return batch["terminals"]


def uniform_actions(key: jax.Array, batch: int, num: int, act_dim: int) -> jax.Array:
    """(B, M, A) actions uniform in [-1, 1]."""
    return jax.random.uniform(key, (batch, num, act_dim), minval=-1.0, maxval=1.0)


def repeat_obs(obs: jax.Array, num: int) -> jax.Array:
    """(B, D) -> (B, M, D)."""
    return jnp.broadcast_to(obs[:, None], (obs.shape[0], num, obs.shape[1]))
