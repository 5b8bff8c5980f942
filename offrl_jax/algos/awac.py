"""The AWAC family (`awac`; Nair et al. 2020): advantage-weighted actor-critic, with CORL's `finetune/awac.py` update.

    critic  twin critics on r + gamma (1 - d) min_i Q'_i(s', a'), a' a sample of the current policy clipped to
            [-1, 1] (SAC's target without its entropy term); the sum of the two critics' mean squared errors
    actor   a Gaussian (unsquashed mean, state-independent std) by advantage-weighted likelihood of the data's action:
            mean(min(exp(A / awac_lambda), max_weight) * -log pi(a | s)),  A = min_i Q_i(s, a) - min_i Q_i(s, a~),
            a~ a sample of the policy clipped to [-1, 1], both from the critics just updated

One update per minibatch: the critics, then the actor, then both targets (CORL's order).  The policy acts with its
mean (clipped to [-1, 1]) and explores online with a clipped sample (CORL's fine-tuning acts with `actor(state)`).

Online form: AWAC was made to fine-tune online with the data in its replay, and its update is the same offline and
online: the actor has no behaviour term to drop (the likelihood weighs the replay's own actions, whatever their
source), so its form for the `online-rl` arm is itself (`without_behaviour` {}).  CORL appends the online rows to
the dataset (`replay` "append") and takes one update per env step.

Pre-training (first imitate, then improve): `actor` = behaviour cloning (the same likelihood, every row weighing 1);
`critic` = both critics' regression on the Monte-Carlo returns (optionally lambda-mixed with the TD target above),
targets Polyak-updated; `actor+critic` = both on each minibatch.
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
from offrl_jax.nets import CriticEnsemble, GaussianActor, gaussian_log_prob


@dataclasses.dataclass(frozen=True)
class AWACConfig(Config):
    hidden: tuple[int, ...] = (256, 256, 256)  # CORL: three hidden layers of 256, actor and critics
    actor_layer_norm: bool = False  # AWAC: no LayerNorm
    critic_layer_norm: bool = False
    init: str = "torch"
    timeouts: str = "drop"  # CORL's loader (d4rl.qlearning_dataset) leaves out the rows a time limit cut
    # the temperature of the advantage weights exp(A / awac_lambda) (CORL's: 0.3333 on MuJoCo, 0.1 on Adroit, 1 with
    # no env)
    awac_lambda: float = 1.0
    max_weight: float = 100.0  # clip of exp(A / awac_lambda) (CORL's exp_adv_max)
    replay: str = "append"  # CORL's AWAC fine-tunes on the dataset with the online rows appended

    SWEEPABLE: ClassVar[tuple[str, ...]] = ("awac_lambda", "tau")

    def __post_init__(self):
        super().__post_init__()
        require(self, [("awac_lambda", self.awac_lambda > 0, "must be positive"),
                       ("max_weight", self.max_weight > 0, "must be positive"),
                       ("num_critics", self.num_critics == 2, "must be 2 (AWAC's twin critics)")])


@struct.dataclass
class AWACState:
    actor: Model
    critic: Model


class AWAC(Algorithm):
    def __init__(self, config: AWACConfig, obs_dim: int, act_dim: int, num_transitions: int = 0):
        self.cfg, self.obs_dim, self.act_dim = config, obs_dim, act_dim
        arch = config.arch()
        self.actor = GaussianActor(act_dim, config.actor_hidden or config.hidden, config.actor_layer_norm, arch,
                                   tanh_mean=False)
        self.critic = CriticEnsemble(config.num_critics, config.hidden, config.critic_layer_norm, arch=arch)
        self.actor_tx, self.critic_tx = optax.adam(config.actor_lr), optax.adam(config.critic_lr)

    def init(self, key: jax.Array) -> AWACState:
        k_actor, k_critic = jax.random.split(key)
        obs, act = jnp.zeros((1, self.obs_dim)), jnp.zeros((1, self.act_dim))
        return AWACState(actor=new_model(self.actor.init(k_actor, obs), self.actor_tx, with_target=False),
                         critic=new_model(self.critic.init(k_critic, obs, act), self.critic_tx, with_target=True))

    def act(self, state: AWACState, obs: jax.Array) -> jax.Array:
        return jnp.clip(self.actor.apply(state.actor.params, obs)[0], -1.0, 1.0)

    def explore(self, state: AWACState, obs: jax.Array, key: jax.Array) -> jax.Array:
        """Online the policy acts with a sample of its Gaussian, clipped to [-1, 1] (CORL's fine-tuning)."""
        return self.sample(state.actor.params, obs, key)

    def updates(self):
        return {OFFLINE_RL: single(self.rl_update),
                "pretrain": pretrain_update(self.cfg.pretrain, self.bc_update, self.mc_update)}

    # --------------------------------------------------------------------------------------------- pieces
    def sample(self, actor_params, obs: jax.Array, key: jax.Array) -> jax.Array:
        """A sample of the policy at `obs`, clipped to [-1, 1] (CORL's `Actor.forward`).  (B, D) -> (B, A)."""
        mean, log_std = self.actor.apply(actor_params, obs)
        return jnp.clip(mean + jnp.exp(log_std) * jax.random.normal(key, mean.shape), -1.0, 1.0)

    def td_target(self, state: AWACState, batch: Batch, key: jax.Array) -> jax.Array:
        next_obs = batch["next_observations"]
        next_q = self.critic.apply(state.critic.target, next_obs, self.sample(state.actor.params, next_obs, key))
        return L.td_target(batch["rewards"], done_flags(batch, self.cfg.timeouts), L.clipped_double_q(next_q),
                           self.cfg.gamma)

    def critic_loss(self, params, state: AWACState, batch: Batch, key: jax.Array, pretraining: bool):
        q = self.critic.apply(params, batch["observations"], batch["actions"])  # (2, B)
        td_fn = lambda: self.td_target(state, batch, key)  # noqa: E731
        if pretraining:
            loss = L.pretrain_critic_loss(q, batch["returns"], td_fn, self.cfg.lam, self.cfg.lambda_mode)
        else:  # CORL: q1_loss + q2_loss
            loss = L.critic_regression_loss(q, td_fn())
        return loss, {"critic_loss": loss, "q_mean": jnp.mean(q), "mc_error": jnp.mean((q[0] - batch["returns"]) ** 2)}

    def actor_step(self, state: AWACState, batch: Batch, advantage: jax.Array, beta, name: str):
        def loss_fn(params):
            nll = -gaussian_log_prob(*self.actor.apply(params, batch["observations"]), batch["actions"])
            loss = L.awr_actor_loss(nll, advantage, beta, self.cfg.max_weight)
            return loss, {name: loss}

        actor, metrics = gradient_step(state.actor, self.actor_tx, loss_fn)
        return state.replace(actor=actor), metrics

    # -------------------------------------------------------------------------------------------- updates
    def bc_update(self, state: AWACState, batch: Batch, key: jax.Array):
        return self.actor_step(state, batch, jnp.zeros_like(batch["rewards"]), 0.0, "bc_loss")

    def mc_update(self, state: AWACState, batch: Batch, key: jax.Array):
        critic, metrics = gradient_step(state.critic, self.critic_tx, self.critic_loss, state, batch, key, True)
        return state.replace(critic=polyak(critic, self.cfg.tau)), metrics

    def rl_update(self, state: AWACState, batch: Batch, key: jax.Array):
        k_target, k_pi = jax.random.split(key)
        critic, metrics = gradient_step(state.critic, self.critic_tx, self.critic_loss, state, batch, k_target, False)
        obs = batch["observations"]
        q_data = self.critic.apply(critic.params, obs, batch["actions"])
        q_pi = self.critic.apply(critic.params, obs, self.sample(state.actor.params, obs, k_pi))
        advantage = L.awac_advantage(q_data, q_pi)
        state, actor_metrics = self.actor_step(state.replace(critic=critic), batch, advantage,
                                               1.0 / self.cfg.awac_lambda, "actor_loss")
        tau = self.cfg.tau
        return state.replace(critic=polyak(state.critic, tau)), metrics | actor_metrics | {
            "advantage": jnp.mean(advantage)}


FAMILY = Family(AWACConfig, AWAC)
# its own online form: the update has no behaviour term to drop (see the module's docstring)
ALGOS = {"awac": Algo("awac", without_behaviour={})}
# AWAC's lambda per env, keyed as `offrl_jax.algos.ENV_DEFAULTS`, the same at every level: CORL's
# configs/offline/awac/<env>/*.yaml for MuJoCo (it has no MuJoCo fine-tuning configs), configs/finetune/awac/<env>/
# cloned_v1.yaml for Adroit (its offline ones agree)
ENV_DEFAULTS = {**{("awac", env): {"awac_lambda": 0.3333} for env in ("hopper", "halfcheetah", "walker2d")},
                **{("awac", env): {"awac_lambda": 0.1} for env in ("pen", "door", "hammer", "relocate")}}
PRESETS: dict = {}
