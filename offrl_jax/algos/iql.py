"""The IQL family (`iql`; Kostrikov et al. 2022): implicit Q-learning, with CORL's `iql.py` update.

    V       expectile regression on the target critics' min Q(s, a):  expectile_loss(min Q'(s, a) - V(s), expectile)
    Q       regression on r + gamma (1 - d) V(s'), V(s') from before this step's V update; targets Polyak-updated
    actor   advantage-weighted regression: mean(min(exp(beta (min Q'(s, a) - V(s))), 100) * nll(a | s)), nll the
            Gaussian policy's negative log-likelihood (a state-independent std) or, with `deterministic`, the
            squared error of a tanh actor; the actor's learning rate decays on a cosine over `actor_lr_decay` steps

All three on the same minibatch, in that order (V, Q, actor).

Pre-training (first imitate, then improve): `actor` = behaviour cloning (AWR with beta = 0: every row weighs 1);
`critic` = Q regression on the Monte-Carlo returns (optionally lambda-mixed with the TD target r + gamma V(s')) and V
regression on the same returns with expectile 0.5 (the squared error, whose minimiser is their mean: the behaviour
policy's value V^beta(s), where the returns of its Q^beta(s, a) average to); `actor+critic` = both on each minibatch.
"""
from __future__ import annotations

import dataclasses
from typing import ClassVar

import jax
import jax.numpy as jnp
import optax
from flax import struct

from offrl_jax import losses as L
from offrl_jax.algos.common import (
    OFFLINE_RL,
    Algo,
    Algorithm,
    Batch,
    Family,
    Model,
    done_flags,
    gradient_step,
    new_model,
    polyak,
    pretrain_update,
    single,
)
from offrl_jax.algos.config import Config, require
from offrl_jax.nets import CriticEnsemble, DeterministicActor, GaussianActor, Value, gaussian_log_prob


@dataclasses.dataclass(frozen=True)
class IQLConfig(Config):
    actor_layer_norm: bool = False  # IQL: no LayerNorm
    critic_layer_norm: bool = False
    init: str = "torch"
    expectile: float = 0.7  # the V regression's expectile (IQL's tau)
    beta: float = 3.0  # the AWR inverse temperature (0: behaviour cloning)
    max_weight: float = 100.0  # clip of exp(beta A)
    value_lr: float = 3e-4  # Adam learning rate of V
    deterministic: bool = False  # a tanh actor with squared-error AWR (CORL's hopper) instead of the Gaussian policy
    # the actor's learning rate follows a cosine from actor_lr to 0 over this many actor updates (CORL: its 1M-update
    # budget; 0 = constant)
    actor_lr_decay: int = 1_000_000
    replay: str = "append"  # CORL's IQL fine-tunes on the dataset with the online rows appended
    explore_noise: float = 0.03  # CORL's IQL noise for a deterministic actor (the Gaussian policy samples instead)

    SWEEPABLE: ClassVar[tuple[str, ...]] = ("expectile", "beta", "tau")

    def __post_init__(self):
        super().__post_init__()
        require(self, [
            ("expectile", 0.0 < self.expectile < 1.0, "must be in (0, 1)"),
            ("beta", self.beta >= 0, "must be >= 0"),
            ("max_weight", self.max_weight > 0, "must be positive"),
            ("value_lr", self.value_lr > 0, "must be positive"),
            ("actor_lr_decay", self.actor_lr_decay >= 0, "must be >= 0"),
        ])


@struct.dataclass
class IQLState:
    actor: Model
    critic: Model
    value: Model


class IQL(Algorithm):
    def __init__(self, config: IQLConfig, obs_dim: int, act_dim: int, num_transitions: int = 0):
        self.cfg, self.obs_dim, self.act_dim = config, obs_dim, act_dim
        arch, hidden = config.arch(), config.actor_hidden or config.hidden
        self.actor = (DeterministicActor(act_dim, hidden, config.actor_layer_norm, arch) if config.deterministic
                      else GaussianActor(act_dim, hidden, config.actor_layer_norm, arch))
        self.critic = CriticEnsemble(config.num_critics, config.hidden, config.critic_layer_norm, arch=arch)
        self.value = Value(config.hidden, config.critic_layer_norm, arch)
        lr = (optax.cosine_decay_schedule(config.actor_lr, config.actor_lr_decay) if config.actor_lr_decay
              else config.actor_lr)
        self.actor_tx, self.critic_tx = optax.adam(lr), optax.adam(config.critic_lr)
        self.value_tx = optax.adam(config.value_lr)

    def init(self, key: jax.Array) -> IQLState:
        k_actor, k_critic, k_value = jax.random.split(key, 3)
        obs, act = jnp.zeros((1, self.obs_dim)), jnp.zeros((1, self.act_dim))
        return IQLState(actor=new_model(self.actor.init(k_actor, obs), self.actor_tx, with_target=False),
                        critic=new_model(self.critic.init(k_critic, obs, act), self.critic_tx, with_target=True),
                        value=new_model(self.value.init(k_value, obs), self.value_tx, with_target=False))

    def act(self, state: IQLState, obs: jax.Array) -> jax.Array:
        out = self.actor.apply(state.actor.params, obs)
        return out if self.cfg.deterministic else out[0]

    def explore(self, state: IQLState, obs: jax.Array, key: jax.Array) -> jax.Array | None:
        """Online, the Gaussian policy acts with a sample, clipped to [-1, 1] (CORL's IQL); a deterministic actor
        has none (None: its action plus `explore_noise`)."""
        if self.cfg.deterministic:
            return None
        mean, log_std = self.actor.apply(state.actor.params, obs)
        return jnp.clip(mean + jnp.exp(log_std) * jax.random.normal(key, mean.shape), -1.0, 1.0)

    def updates(self):
        return {OFFLINE_RL: single(self.rl_update),
                "pretrain": pretrain_update(self.cfg.pretrain, self.bc_update, self.mc_update)}

    def neg_log_lik(self, params, batch: Batch) -> jax.Array:
        """(B,) the actor's per-row loss of the dataset action: squared error, or the Gaussian's -log-likelihood."""
        out = self.actor.apply(params, batch["observations"])
        if self.cfg.deterministic:
            return L.action_penalty(out, batch["actions"])
        return -gaussian_log_prob(*out, batch["actions"])

    def actor_step(self, state: IQLState, batch: Batch, advantage: jax.Array, beta: float, name: str):
        def loss_fn(params):
            loss = L.awr_actor_loss(self.neg_log_lik(params, batch), advantage, beta, self.cfg.max_weight)
            return loss, {name: loss}

        actor, metrics = gradient_step(state.actor, self.actor_tx, loss_fn)
        return state.replace(actor=actor), metrics

    def bc_update(self, state: IQLState, batch: Batch, key: jax.Array):
        return self.actor_step(state, batch, jnp.zeros_like(batch["rewards"]), 0.0, "bc_loss")

    def td_target(self, state: IQLState, batch: Batch) -> jax.Array:
        next_v = self.value.apply(state.value.params, batch["next_observations"])
        return L.td_target(batch["rewards"], done_flags(batch, self.cfg.timeouts), next_v, self.cfg.gamma)

    def q_loss(self, params, batch: Batch, target_fn, pretraining: bool):
        q = self.critic.apply(params, batch["observations"], batch["actions"])  # (N, B)
        if pretraining:
            loss = L.pretrain_critic_loss(q, batch["returns"], target_fn, self.cfg.lam, self.cfg.lambda_mode,
                                          per_critic="mean")
        else:  # CORL: the mean over the twin critics of each one's mean squared error
            loss = L.critic_regression_loss(q, target_fn()) / q.shape[0]
        return loss, {"critic_loss": loss, "q_mean": jnp.mean(q), "mc_error": jnp.mean((q[0] - batch["returns"]) ** 2)}

    def mc_update(self, state: IQLState, batch: Batch, key: jax.Array):
        target = self.td_target(state, batch)
        critic, metrics = gradient_step(state.critic, self.critic_tx, self.q_loss, batch, lambda: target, True)

        def value_loss(params):
            loss = L.expectile_loss(batch["returns"] - self.value.apply(params, batch["observations"]), 0.5)
            return loss, {"value_loss": loss}

        value, value_metrics = gradient_step(state.value, self.value_tx, value_loss)
        return state.replace(critic=polyak(critic, self.cfg.tau), value=value), metrics | value_metrics

    def rl_update(self, state: IQLState, batch: Batch, key: jax.Array):
        cfg = self.cfg
        target = self.td_target(state, batch)  # V(s') before this step's V update (CORL)
        target_q = jnp.min(self.critic.apply(state.critic.target, batch["observations"], batch["actions"]), axis=0)

        def value_loss(params):
            v = self.value.apply(params, batch["observations"])
            loss = L.expectile_loss(target_q - v, cfg.expectile)
            return loss, {"value_loss": loss, "advantage": jnp.mean(target_q - v)}

        advantage = target_q - self.value.apply(state.value.params, batch["observations"])
        value, metrics = gradient_step(state.value, self.value_tx, value_loss)
        critic, critic_metrics = gradient_step(state.critic, self.critic_tx, self.q_loss, batch, lambda: target, False)
        state = state.replace(value=value, critic=polyak(critic, cfg.tau))
        state, actor_metrics = self.actor_step(state, batch, advantage, cfg.beta, "actor_loss")
        return state, metrics | critic_metrics | actor_metrics


FAMILY = Family(IQLConfig, IQL)
ALGOS = {"iql": Algo("iql")}
# IQL's values per env, keyed as `offrl_jax.algos.ENV_DEFAULTS` (CORL's configs/offline/iql/<env>/medium_v2.yaml:
# expectile 0.7, beta 3 everywhere); hopper's also scales the rewards by 1000 / (max - min episode return)
ENV_DEFAULTS = {
    ("iql", "hopper"): {"deterministic": True, "tau": 0.001, "normalize_reward": True},
    ("iql", "door"): {"expectile": 0.8},  # configs/{offline,finetune}/iql/door/*_v1.yaml (no actor dropout here)
}
PRESETS: dict = {}
