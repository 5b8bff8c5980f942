"""What every algorithm shares: a trainable `Model` (params + target + optimiser state), the `Phase` record the
driver runs, and small helpers to take a gradient step and to chain update functions.

An algorithm (`Algorithm`) is a frozen config plus pure functions:
    init(key) -> AgentState                                  (a pytree of arrays: vmappable over seeds, checkpointable)
    updates() -> {phase name: update function}               (one per phase its config plans)
    act(state, obs) -> action                                (deterministic policy for evaluation)
The config plans the phases (`Config.phases(total_updates)`: pre-training phases, then offline RL), once, before any
network exists; `Algorithm.phases` gives each planned phase its update function.  Each
`Phase.update(state, batch, key) -> (state, metrics)` is one scan body; batch leaves are (k, B, ...) with
k = `Phase.updates_per_call` minibatches (k = 2 for TD3's delayed actor update).  `single` / `first` hand a loss the
(B, ...) minibatch.

A minibatch (`Batch`: rows of a dataset's device form, `offrl_jax.data.device`, drawn uniformly, plus `idx`), for B
rows:
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
from collections.abc import Callable, Mapping
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import struct

from offrl_jax import losses as L

Params = Any
Batch = dict[str, jax.Array]
Metrics = dict[str, jax.Array]
UpdateFn = Callable[[Any, Batch, jax.Array], tuple[Any, Metrics]]


@dataclasses.dataclass(frozen=True)
class Family:
    """A family of algorithms: its config dataclass (extending `offrl_jax.algos.config.Config`) and the algorithm
    class built from it, `algorithm(config, obs_dim, act_dim, num_transitions)` with `init`, `phases` and `act`."""
    config: type
    algorithm: type


@dataclasses.dataclass(frozen=True)
class Algo:
    """An algorithm: a family plus the config values that make it that algorithm (td3bc_cql's cql_weight)."""
    family: str  # a key of `offrl_jax.algos.FAMILIES`
    values: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    # the per-env sections (`ENV_DEFAULTS`) it reads after its family's and before its own, and the values of those
    # it skips
    sections: tuple[str, ...] = ()
    skip: tuple[str, ...] = ()
    # the values that make its form without behaviour terms (the fine-tuning study's online-rl arm: online RL with
    # the data in its replay); None: it has none (IQL's actor is a weighted regression on the data)
    without_behaviour: Mapping[str, Any] | None = None


OFFLINE_RL = "offline_rl"  # the offline-RL phase, the last of every plan but behaviour cloning's


@dataclasses.dataclass(frozen=True)
class DataNeeds:
    """What a family's updates read from the dataset beyond its device form (`offrl_jax.data.device.DATA_FIELDS`),
    as its config declares it (`Config.needs`); the data layer builds what is declared (`data.device.for_updates`)."""
    next_actions: bool = False  # each row's next action in its episode (ReBRAC's critic penalty)
    # whether rows where the time limit cut the episode may be drawn (False: never, as CORL's loader drops them)
    cut_rows: bool = True
    # offline RL reads the Monte-Carlo returns (a max(MC, TD) target): online, only rows of ended episodes, whose
    # returns are known, are drawn
    returns: bool = False


class Algorithm:
    """What a family's algorithm class offers, built from its config (`cfg`, the family's config dataclass).  The
    methods with a body here are optional: their defaults are a family with no such part."""

    cfg: Any

    def updates(self) -> dict[str, UpdateFn]:
        """{phase name: its update function} for every phase the config may plan (`Config.phases`)."""
        raise NotImplementedError

    def start_hooks(self) -> dict[str, Callable[[Any, Batch, jax.Array], Any]]:
        """{phase name: (state, data, key) -> state, called once before that phase starts}; none by default."""
        return {}

    def phases(self, total_updates: int) -> list[Phase]:
        """The config's plan of a run of `total_updates` updates, each phase with its update and start hook."""
        updates, hooks = self.updates(), self.start_hooks()
        return [dataclasses.replace(p, update=updates[p.name], on_start=hooks.get(p.name))
                for p in self.cfg.phases(total_updates)]

    # ------------------------------------------------------------------------------------------------ online
    def explore(self, state: Any, obs: jax.Array, key: jax.Array) -> jax.Array | None:
        """The online action at normalised `obs`: a stochastic actor's sample; None (the default): the policy's
        action (`act`) plus Gaussian noise of std `cfg.explore_noise` (TD3's exploration)."""
        return None

    def online_values(self, progress: jax.Array) -> dict[str, Any]:
        """Sweepable hyper-parameters that take other values online, at `progress` (online updates done / all of
        them, traced); none by default."""
        return {}


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
    # None in a plan (`Config.phases`: what a budget check and a dry run read); the algorithm gives each planned
    # phase its update (`Algorithm.phases`)
    update: UpdateFn | None = None
    steps: int = 0  # gradient updates in this phase (a multiple of updates_per_call)
    updates_per_call: int = 1
    # Called once (jitted, vmapped over seeds) before the phase starts: (state, data, key) -> state.
    on_start: Callable[[Any, Batch, jax.Array], Any] | None = None
    # Pre-training that ends itself (`AutoStop`); `steps` is then its cap.
    auto_stop: AutoStop | None = None

    @property
    def pretraining(self) -> bool:
        """Whether this is a pre-training phase (any offline phase but offline RL)."""
        return self.name != OFFLINE_RL


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


def bc_step(actor: Model, apply: Callable, tx: optax.GradientTransformation, batch: Batch,
            tau: float | None) -> tuple[Model, Metrics]:
    """One behaviour-cloning step of a deterministic actor (`apply(params, obs)`, MSE to the data's actions), its
    target moved by `tau` (None: left where it is)."""
    def loss_fn(params):
        loss = L.bc_loss(apply(params, batch["observations"]), batch["actions"])
        return loss, {"bc_loss": loss}

    actor, metrics = gradient_step(actor, tx, loss_fn)
    return (actor if tau is None else polyak(actor, tau)), metrics


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


PRETRAIN_MONITOR = {"actor": ("bc_loss",), "critic": ("mc_error",), "actor+critic": ("bc_loss", "mc_error")}


def joint_phases(cfg: Any, total: int, policy_delay: int = 1) -> list[Phase]:
    """The planned phases of a family that pre-trains its actor by BC and its critic on MC returns in one phase:
    "pretrain" (`cfg.pretrain` "actor", "critic" or "actor+critic", `cfg.pretrain_updates` long, ending itself with
    `cfg.pretrain_auto`; none for "none"), then "offline_rl" (a multiple of `policy_delay` long, that many updates
    per call)."""
    pre, rl = split_budget(total, 0 if cfg.pretrain == "none" else cfg.pretrain_updates)
    planned = [Phase("pretrain", steps=pre, auto_stop=cfg.auto_stop(PRETRAIN_MONITOR[cfg.pretrain]))] if pre else []
    return planned + [Phase(OFFLINE_RL, steps=rl - rl % policy_delay, updates_per_call=policy_delay)]


def pretrain_update(mode: str, bc_update: UpdateFn, mc_update: UpdateFn) -> UpdateFn:
    """The single-minibatch update of a joint "pretrain" stage for pre-training mode `mode`."""
    return single({"actor": bc_update, "critic": mc_update, "actor+critic": chain(bc_update, mc_update)}.get(
        mode, bc_update))


def split_budget(total: int, pretrain: int) -> tuple[int, int]:
    """(pre-training updates, RL updates): pre-training counts inside the total budget."""
    if pretrain > total:
        raise ValueError(f"pre-training updates ({pretrain}) exceed the total budget ({total}): give fewer "
                         "(--pretrain-updates) or more updates (--updates)")
    return pretrain, total - pretrain


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
