"""The ReBRAC family (`rebrac`; Tarasov et al. 2023): TD3 with behaviour penalties in the actor and in the critic's
target, LayerNorm in the critic, a large batch and 3-layer networks.

    actor   mean(actor_beta ||pi(s) - a||^2 - Q(s, pi(s)) / sg(mean |Q|)),  Q = min over the critics
    critic  r + gamma (1 - d) (min_i Q'_i(s', a~') - critic_beta ||a~' - a'||^2),  a~' the target actor's smoothed
            action, a' the dataset's next action (`data.device.next_actions`; time-out rows are left out by default, as
            CORL's loader does, so a bootstrapped target never lacks one)

One critic update per minibatch; every `policy_delay`-th also updates the actor on the same minibatch, after the
critic, and then both targets (CORL's `rebrac.py` order).

Pre-training (first imitate, then improve), as TD3+BC's: `actor` = BC (MSE, the actor penalty alone), `critic` =
regression on the Monte-Carlo returns (optionally lambda-mixed with the ReBRAC TD target), `actor+critic` = both at
once on the same minibatch, targets Polyak-updated throughout.
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
    DataNeeds,
    Family,
    Model,
    Phase,
    bc_step,
    done_flags,
    first,
    gradient_step,
    joint_phases,
    new_model,
    polyak,
    pretrain_update,
)
from offrl_jax.algos.config import Config, arch_with_bias, require
from offrl_jax.nets import Arch, CriticEnsemble, DeterministicActor


@dataclasses.dataclass(frozen=True)
class ReBRACConfig(Config):
    actor_lr: float = 1e-3
    critic_lr: float = 1e-3
    hidden: tuple[int, ...] = (256, 256, 256)
    actor_layer_norm: bool = False  # ReBRAC: LayerNorm in the critic only
    init: str = "torch"
    timeouts: str = "drop"
    # ReBRAC's behaviour penalty in the actor loss (its published per-env values: ENV_DEFAULTS)
    actor_beta: float = 1.0
    # ReBRAC's behaviour penalty in the critic's target (its published per-env values: ENV_DEFAULTS)
    critic_beta: float = 1.0
    policy_noise: float = 0.2  # std of the target policy smoothing noise
    noise_clip: float = 0.5  # clip of the target policy smoothing noise
    policy_delay: int = 2  # critic updates per actor and target update (TD3)
    normalize_q: bool = True  # divide the actor's Q term by sg(mean |Q|)
    hidden_bias: float | None = 0.1  # constant hidden-layer bias (CORL's ReBRAC, after EDAC); None: the init's own
    out_init: bool = True  # final layers U(+-1e-3) actor, U(+-3e-3) critics; False: the init scheme's own
    explore_noise: float = 0.0  # CORL's ReBRAC fine-tunes without exploration noise (expl_noise 0)
    online_critic_beta: float = 0.0  # the critic penalty online: 0 (CORL's fine-tuning drops it), the only value yet
    # online, the actor penalty decays linearly from actor_beta towards this fraction of it over the online updates,
    # then stays there (CORL's min_decay_coef; 1 = no decay)
    online_actor_beta_floor: float = 0.5

    SWEEPABLE: ClassVar[tuple[str, ...]] = ("actor_beta", "critic_beta", "tau", "policy_noise", "noise_clip")

    def __post_init__(self):
        super().__post_init__()
        require(self, [
            ("actor_beta", self.actor_beta >= 0, "must be >= 0"),
            ("critic_beta", self.critic_beta >= 0, "must be >= 0"),
            ("policy_noise", self.policy_noise >= 0, "must be >= 0"),
            ("noise_clip", self.noise_clip >= 0, "must be >= 0"),
            ("policy_delay", self.policy_delay >= 1, "must be >= 1"),
            ("online_critic_beta", self.online_critic_beta == 0, "must be 0, CORL's fine-tuning (online rows do not "
             "record the next action the critic penalty reads)"),
            ("online_actor_beta_floor", 0 <= self.online_actor_beta_floor <= 1, "must be in [0, 1]"),
            ("pretrain_auto_window", not self.pretrain_auto or self.pretrain_auto_window % self.policy_delay == 0,
             f"must be a multiple of policy_delay ({self.policy_delay})"),
        ])

    def arch(self) -> Arch:
        return arch_with_bias(self)

    def phases(self, total_updates: int) -> list[Phase]:
        """Pre-training, then offline RL with the actor updated once every `policy_delay` critic updates."""
        return joint_phases(self, total_updates, self.policy_delay)

    def needs(self) -> DataNeeds:
        """The critic's penalty reads each row's next action in its episode."""
        return dataclasses.replace(super().needs(), next_actions=True)


@struct.dataclass
class ReBRACState:
    actor: Model
    critic: Model


class ReBRAC(Algorithm):
    def __init__(self, config: ReBRACConfig, obs_dim: int, act_dim: int, num_transitions: int = 0):
        self.cfg, self.obs_dim, self.act_dim = config, obs_dim, act_dim
        arch = config.arch()
        self.actor = DeterministicActor(act_dim, config.actor_hidden or config.hidden, config.actor_layer_norm, arch,
                                        1e-3 if config.out_init else None)
        self.critic = CriticEnsemble(config.num_critics, config.hidden, config.critic_layer_norm,
                                     out_scale=3e-3 if config.out_init else None, arch=arch)
        self.actor_tx, self.critic_tx = optax.adam(config.actor_lr), optax.adam(config.critic_lr)

    def init(self, key: jax.Array) -> ReBRACState:
        k_actor, k_critic = jax.random.split(key)
        obs, act = jnp.zeros((1, self.obs_dim)), jnp.zeros((1, self.act_dim))
        return ReBRACState(actor=new_model(self.actor.init(k_actor, obs), self.actor_tx, with_target=True),
                           critic=new_model(self.critic.init(k_critic, obs, act), self.critic_tx, with_target=True))

    def act(self, state: ReBRACState, obs: jax.Array) -> jax.Array:
        return self.actor.apply(state.actor.params, obs)

    def online_values(self, progress: jax.Array) -> dict[str, jax.Array]:
        """The penalties online, at `progress` (online updates done / all of them, traced): CORL's fine-tuning, the
        critic's at `online_critic_beta`, the actor's decaying linearly to `online_actor_beta_floor` of its own."""
        cfg = self.cfg
        decay = jnp.maximum(cfg.online_actor_beta_floor, 1.0 - progress)
        return {"critic_beta": cfg.online_critic_beta, "actor_beta": cfg.actor_beta * decay}

    def updates(self):
        return {OFFLINE_RL: self.rl_update,
                "pretrain": pretrain_update(self.cfg.pretrain, self.bc_update, self.mc_update)}

    def td_target(self, state: ReBRACState, batch: Batch, key: jax.Array) -> jax.Array:
        cfg = self.cfg
        next_obs = batch["next_observations"]
        next_pi = L.target_policy_smoothing(key, self.actor.apply(state.actor.target, next_obs), cfg.policy_noise,
                                            cfg.noise_clip)
        next_q = self.critic.apply(state.critic.target, next_obs, next_pi)
        next_value = L.rebrac_next_value(next_q, next_pi, batch["next_actions"], cfg.critic_beta)
        return L.td_target(batch["rewards"], done_flags(batch, cfg.timeouts), next_value, cfg.gamma)

    def critic_loss(self, params, state: ReBRACState, batch: Batch, key: jax.Array, pretraining: bool):
        q = self.critic.apply(params, batch["observations"], batch["actions"])  # (N, B)
        td_fn = lambda: self.td_target(state, batch, key)  # noqa: E731
        if pretraining:
            loss = L.pretrain_critic_loss(q, batch["returns"], td_fn, self.cfg.lam, self.cfg.lambda_mode)
        else:
            loss = L.critic_regression_loss(q, td_fn())
        return loss, {"critic_loss": loss, "q_mean": jnp.mean(q), "mc_error": jnp.mean((q[0] - batch["returns"]) ** 2)}

    def actor_loss(self, params, state: ReBRACState, batch: Batch):
        pi = self.actor.apply(params, batch["observations"])
        q = jnp.min(self.critic.apply(state.critic.params, batch["observations"], pi), axis=0)
        loss = L.rebrac_actor_loss(q, pi, batch["actions"], self.cfg.actor_beta, self.cfg.normalize_q)
        return loss, {"actor_loss": loss, "bc_mse": L.bc_loss(pi, batch["actions"])}

    def bc_update(self, state: ReBRACState, batch: Batch, key: jax.Array):
        actor, metrics = bc_step(state.actor, self.actor.apply, self.actor_tx, batch, self.cfg.tau)
        return state.replace(actor=actor), metrics

    def mc_update(self, state: ReBRACState, batch: Batch, key: jax.Array):
        critic, metrics = gradient_step(state.critic, self.critic_tx, self.critic_loss, state, batch, key, True)
        return state.replace(critic=polyak(critic, self.cfg.tau)), metrics

    def rl_update(self, state: ReBRACState, batches: Batch, key: jax.Array):
        """The first minibatch: a critic update, then the actor's and both targets'; the others: a critic update."""
        metrics = {}
        for i, k in enumerate(jax.random.split(key, self.cfg.policy_delay)):
            batch = first(batches, i)
            critic, m = gradient_step(state.critic, self.critic_tx, self.critic_loss, state, batch, k, False)
            state, metrics = state.replace(critic=critic), metrics | m
            if i == 0:
                actor, m = gradient_step(state.actor, self.actor_tx, self.actor_loss, state, batch)
                tau = self.cfg.tau
                state, metrics = state.replace(actor=polyak(actor, tau), critic=polyak(state.critic, tau)), metrics | m
        return state, metrics


FAMILY = Family(ReBRACConfig, ReBRAC)
ALGOS = {"rebrac": Algo("rebrac", without_behaviour={"actor_beta": 0.0, "critic_beta": 0.0})}
# ReBRAC's published values per env, keyed as `offrl_jax.algos.ENV_DEFAULTS`
ENV_DEFAULTS = {
    # the medium datasets' betas (CORL's configs/offline/rebrac/<env>/medium_v2.yaml)
    ("rebrac", "hopper"): {"actor_beta": 0.01, "critic_beta": 0.01},
    ("rebrac", "halfcheetah"): {"actor_beta": 0.001, "critic_beta": 0.01},
    ("rebrac", "walker2d"): {"actor_beta": 0.05, "critic_beta": 0.1},
    # door (CORL's configs/offline/rebrac/door/<level>_v1.yaml, the same in configs/finetune/rebrac/door/cloned_v1.yaml)
    ("rebrac", "door"): {"actor_beta": 0.01, "critic_beta": 0.1, "actor_lr": 3e-4, "critic_lr": 3e-4},
    ("rebrac", "door:human"): {"actor_beta": 0.1},
}
PRESETS: dict = {}
