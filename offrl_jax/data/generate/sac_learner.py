"""The learner of the online SAC that trains the behaviour policies (`offrl_jax.data.generate.sac` runs it).

Written like the offline algorithms (`offrl_jax.algos`): a `struct.dataclass` state of `Model`s (params, optimiser
state, target), one `gradient_step` per trained quantity, `polyak` for the target, and the losses of
`offrl_jax.losses` that SAC-N / EDAC (`offrl_jax.algos.sacn`) use too.

Actor 256-256 tanh-Gaussian (`collect.actor_module`, the shipped policies' network), twin critics 256-256
(`CriticEnsemble(num=2)`), no LayerNorm, auto temperature with target entropy -act_dim, Adam 3e-4, batch 256,
gamma 0.99, tau 0.005.  One update per env step, in this order, on one replay minibatch:
    critic       sum_i mean (Q_i(s, a) - y)^2,  y = r + gamma (1 - terminal) (min_i Q'_i(s', a') - alpha log pi(a'|s')),
                 a' ~ pi(s'): only true terminals stop the target, time-outs bootstrap
    actor        mean(alpha log pi(a~|s) - min_i Q_i(s, a~)), a~ ~ pi(s), with the critic just updated
    temperature  -mean(log_alpha (log pi(a~|s) + H_target)), on the actor step's own samples
    target       Q' <- tau Q + (1 - tau) Q'
alpha is the temperature before this update in all three losses.
"""
from __future__ import annotations

import dataclasses
import functools

import flax.serialization
import jax
import jax.numpy as jnp
import optax
from flax import struct

from offrl_jax import losses as L
from offrl_jax.algos.common import Batch, Metrics, Model, gradient_step, new_model, polyak
from offrl_jax.data.generate.collect import ACTOR_HIDDEN, actor_module
from offrl_jax.nets import CriticEnsemble, sample_tanh_gaussian


@dataclasses.dataclass(frozen=True)
class SACConfig:
    hidden: tuple[int, ...] = ACTOR_HIDDEN
    lr: float = 3e-4
    batch_size: int = 256
    gamma: float = 0.99
    tau: float = 0.005
    warmup_steps: int = 5_000
    init_log_alpha: float = 0.0


@struct.dataclass
class SACState:
    actor: Model  # params: the actor's flax variables, as `checkpoints/actor_<step>.msgpack` holds them
    critic: Model  # twin critics, with their target
    log_alpha: Model  # the log temperature, a () array
    key: jax.Array  # drawn from for every update and every action


class SAC:
    """Networks, optimiser, losses and the jitted `update` / `update_and_act` of SAC for one (obs_dim, act_dim)."""

    def __init__(self, obs_dim: int, act_dim: int, cfg: SACConfig = SACConfig()):
        self.obs_dim, self.act_dim, self.cfg = obs_dim, act_dim, cfg
        self.actor = actor_module(act_dim, cfg.hidden)
        self.critic = CriticEnsemble(num=2, hidden=cfg.hidden, layer_norm=False)
        self.tx = optax.adam(cfg.lr)  # stateless: one transformation serves actor, critic and temperature
        self.target_entropy = -float(act_dim)
        self.update = jax.jit(self._update)
        self.update_and_act = jax.jit(self._update_and_act)

    def init(self, seed: int) -> SACState:
        return jax.jit(self._init)(jax.random.PRNGKey(seed))

    def _init(self, key: jax.Array) -> SACState:
        key, k_actor, k_critic = jax.random.split(key, 3)
        obs, act = jnp.zeros((1, self.obs_dim)), jnp.zeros((1, self.act_dim))
        return SACState(
            actor=new_model(self.actor.init(k_actor, obs), self.tx, with_target=False),
            critic=new_model(self.critic.init(k_critic, obs, act), self.tx, with_target=True),
            log_alpha=new_model(jnp.asarray(self.cfg.init_log_alpha, jnp.float32), self.tx, with_target=False),
            key=key,
        )

    # ---------------------------------------------------------------------------------------------- losses
    def sample_policy(self, actor_params, obs: jax.Array, key: jax.Array) -> tuple[jax.Array, jax.Array]:
        return sample_tanh_gaussian(key, *self.actor.apply(actor_params, obs))

    def td_target(self, state: SACState, batch: Batch, key: jax.Array) -> jax.Array:
        next_action, next_log_prob = self.sample_policy(state.actor.params, batch["next_observations"], key)
        next_q = self.critic.apply(state.critic.target, batch["next_observations"], next_action)
        next_value = L.soft_value(next_q, next_log_prob, jnp.exp(state.log_alpha.params))
        return L.td_target(batch["rewards"], batch["terminals"], next_value, self.cfg.gamma)

    def critic_loss(self, params, target: jax.Array, batch: Batch) -> tuple[jax.Array, Metrics]:
        q = self.critic.apply(params, batch["observations"], batch["actions"])
        loss = L.critic_regression_loss(q, target)
        return loss, {"critic_loss": loss, "q_mean": jnp.mean(q)}

    def actor_loss(self, params, state: SACState, batch: Batch, key: jax.Array) -> tuple[jax.Array, Metrics]:
        """The SAC actor loss; its metrics carry the samples' `log_prob` (B,) for the temperature step."""
        action, log_prob = self.sample_policy(params, batch["observations"], key)
        q = self.critic.apply(state.critic.params, batch["observations"], action)
        loss = L.sac_actor_loss(q, log_prob, jnp.exp(state.log_alpha.params))
        return loss, {"actor_loss": loss, "entropy": -jnp.mean(log_prob), "log_prob": log_prob}

    def temperature_loss(self, log_alpha: jax.Array, log_prob: jax.Array) -> tuple[jax.Array, Metrics]:
        loss = L.temperature_loss(log_alpha, log_prob, self.target_entropy)
        return loss, {"alpha": jnp.exp(log_alpha), "alpha_loss": loss}

    # ---------------------------------------------------------------------------------------------- updates
    def _update(self, state: SACState, batch: Batch) -> tuple[SACState, Metrics]:
        """Critic, actor, temperature, then the critic's target (see the module doc)."""
        key, k_target, k_actor = jax.random.split(state.key, 3)
        target = self.td_target(state, batch, k_target)
        critic, m_critic = gradient_step(state.critic, self.tx, self.critic_loss, target, batch)
        state = state.replace(critic=critic)
        actor, m_actor = gradient_step(state.actor, self.tx, self.actor_loss, state, batch, k_actor)
        log_prob = m_actor.pop("log_prob")
        log_alpha, m_alpha = gradient_step(state.log_alpha, self.tx, self.temperature_loss, log_prob)
        state = state.replace(actor=actor, critic=polyak(critic, self.cfg.tau), log_alpha=log_alpha, key=key)
        return state, m_critic | m_actor | m_alpha

    def _update_and_act(self, state: SACState, batch: Batch, obs: jax.Array) -> tuple[SACState, Metrics, jax.Array]:
        """One update, then a stochastic action of the updated actor for `obs` (obs_dim,) -> (act_dim,)."""
        state, metrics = self._update(state, batch)
        key, k_act = jax.random.split(state.key)
        action, _ = self.sample_policy(state.actor.params, obs, k_act)
        return state.replace(key=key), metrics, action


@functools.lru_cache(maxsize=8)
def make_sac(obs_dim: int, act_dim: int, cfg: SACConfig = SACConfig()) -> SAC:
    """A shared `SAC` per (dims, config), so its jitted functions compile once per process."""
    return SAC(obs_dim, act_dim, cfg)


def check_state_bytes(data: bytes) -> None:
    """ValueError (one line) unless `data` is a `SACState` as `state_to_bytes` writes it (e.g. a state of the
    earlier layout with separate actor_opt / critic_opt / target_critic fields)."""
    try:
        keys = set(flax.serialization.msgpack_restore(data))
    except Exception as e:  # msgpack raises several types for damaged bytes
        raise ValueError(f"state.msgpack is not readable ({type(e).__name__}: {e})") from None
    expected = {f.name for f in dataclasses.fields(SACState)}
    if keys == expected:
        return
    if {"actor_opt", "critic_opt", "target_critic"} <= keys:
        raise ValueError("state.msgpack holds a SAC state of the earlier layout (separate actor_opt, critic_opt and "
                         "target_critic fields), which this version cannot resume: start a new run")
    raise ValueError(f"state.msgpack holds the fields {', '.join(sorted(keys))}, not this version's "
                     f"{', '.join(sorted(expected))}: it cannot be resumed; start a new run")


def state_to_bytes(state: SACState) -> bytes:
    return flax.serialization.to_bytes(state)


def state_from_bytes(template: SACState, data: bytes) -> SACState:
    """The state in `data`, shaped like `template` (from `SAC.init`); ValueError (one line) when it does not fit."""
    check_state_bytes(data)
    try:
        state = flax.serialization.from_bytes(template, data)
    except (ValueError, KeyError, TypeError) as e:
        raise ValueError(f"state.msgpack does not fit this run's networks ({type(e).__name__}: {e})") from None
    if [jnp.shape(x) for x in jax.tree.leaves(state)] != [jnp.shape(x) for x in jax.tree.leaves(template)]:
        raise ValueError("state.msgpack does not fit this run's networks (array shapes differ)")
    return state
