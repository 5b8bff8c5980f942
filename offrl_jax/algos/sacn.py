"""The SAC-N family (`sacn`): a tanh-Gaussian actor, an ensemble of N critics and a learned temperature.  Its
algorithms (`ALGOS`):

    edac     EDAC: SAC-N + eta * ensemble-diversity loss on the critics (eta > 0)
    sacn     SAC-N: SAC with the min over N critics (eta = 0)
    edac_bc  EDAC+BC: EDAC with the actor loss balanced against MSE(sampled action, dataset action) (the paper's
             hybrid, Appendix G)

CQL and Cal-QL extend this family in their own file (`algos/cql.py`).

Pre-training (Alg. 2): soft BC with the temperature tuned (`actor`), then soft returns-to-go computed once with that
actor and alpha, then critic regression on them with the diversity loss as regulariser (`critic`), then offline RL
with alpha carried over.  `actor+critic` runs both phases in that order (the paper's procedure for soft algorithms).

Over 300 lines for a stated reason: the file is the family's whole algorithm, its three named algorithms with their
per-env values and presets included, so that reading it is reading EDAC, SAC-N and EDAC+BC.
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
    Phase,
    chain,
    done_flags,
    gradient_step,
    new_model,
    polyak,
    single,
    split_budget,
)
from offrl_jax.algos.config import AUTHORS_CODE, Config, arch_with_bias, require
from offrl_jax.data.returns import soft_returns_to_go, soft_returns_to_go_from_states
from offrl_jax.losses import BALANCES
from offrl_jax.nets import (
    FANS,
    TANH_LOG_DETS,
    Arch,
    CriticEnsemble,
    TanhGaussianActor,
    sample_tanh_gaussian,
    tanh_gaussian_log_prob,
)

SOFT_ENTROPY_AT = ("next_observations", "observations")  # SACNConfig.soft_entropy_at


@dataclasses.dataclass(frozen=True)
class SACNConfig(Config):
    num_critics: int = 10  # critic ensemble size
    hidden: tuple[int, ...] = (256, 256, 256)
    pretrain_updates: int = 20_000  # split between soft BC and critic regression by actor_pretrain_fraction
    eta: float = 1.0  # EDAC's ensemble-diversity weight (0 = SAC-N)
    alpha_lr: float = 3e-4  # Adam learning rate of the entropy temperature
    hidden_bias: float | None = None  # constant hidden-layer bias; CORL's EDAC: 0.1
    critic_fan: str = "in"  # the critics' "torch" init bound 1/sqrt(fan): in, or out (CORL's VectorizedLinear)
    out_init: bool = True  # final layers U(+-1e-3) actor, U(+-3e-3) critics (EDAC); False: the init scheme's own
    log_std_bounds: tuple[float, float] = (-5.0, 2.0)  # EDAC; CORL's CQL: (-20, 2)
    log_std_offset: float = 0.0  # added to the raw log-std before clipping; CORL's CQL: -1
    tanh_log_det: str = "exact"  # log(1 - tanh(u)^2): exact (softplus form) or eps (log(1 - a^2 + 1e-6), CORL)
    log_alpha_bound: float = 0.0  # > 0: offline RL uses exp(clip(log alpha, +-bound)) (authors: 10)
    balance: str = "abs"  # EDAC+BC's normalisation: x / sg|x| (abs) or the authors' x / sg(x) (signed)
    init_alpha: float = 1.0  # initial entropy temperature
    backup_entropy: bool = True  # subtract alpha log pi(a'|s') in the TD target
    bc_weight: float = 0.0  # EDAC+BC: actor loss = SAC/sg|SAC| + bc_weight * MSE/sg|MSE| (0 = off)
    actor_pretrain_fraction: float = 0.5  # share of pretrain_updates spent on soft BC (the rest: critic regression)
    # updates added to the last pre-training phase after pretrain_updates, taken from offline RL while it has them;
    # the authors' loop pre-trains while epoch <= pretrain_epochs, one 1k-update epoch more than it names: 1000
    pretrain_extra: int = 0
    # where the soft returns' entropies are sampled (`data.returns`): next_observations (each row's successor; the
    # last row of an episode gets its successor's) or observations (each row's own state, the authors' code: the
    # last row gets none and a time-out's tail repeats H(s_T))
    soft_entropy_at: str = "next_observations"
    entropy_batch: int = 16_384  # rows per batch when computing the per-state entropies for the soft returns

    SWEEPABLE: ClassVar[tuple[str, ...]] = ("eta", "tau")  # vmappable in one program (see common.with_hparams)

    def __post_init__(self):
        super().__post_init__()
        if self.alpha_lr <= 0 or self.init_alpha <= 0:
            raise ValueError("SACNConfig.alpha_lr and init_alpha must be positive")
        require(self, [
            ("entropy_batch", self.entropy_batch >= 1, "must be >= 1"),
            ("eta", self.eta >= 0, "must be >= 0"),
            ("num_critics", not (self.eta > 0 and self.num_critics < 2), "must be >= 2 for EDAC (eta > 0)"),
            ("actor_pretrain_fraction", 0.0 <= self.actor_pretrain_fraction <= 1.0, "must be in [0, 1]"),
            ("pretrain_extra", self.pretrain_extra >= 0, "must be >= 0"),
            ("log_std_bounds", self.log_std_bounds[0] < self.log_std_bounds[1], "must be (low, high) with low < high"),
            ("tanh_log_det", self.tanh_log_det in TANH_LOG_DETS, f"must be one of {', '.join(TANH_LOG_DETS)}"),
            ("log_alpha_bound", self.log_alpha_bound >= 0, "must be >= 0"),
            ("critic_fan", self.critic_fan in FANS, f"must be {' or '.join(FANS)}"),
            ("soft_entropy_at", self.soft_entropy_at in SOFT_ENTROPY_AT, f"must be {' or '.join(SOFT_ENTROPY_AT)}"),
            ("bc_weight", self.bc_weight >= 0, "must be >= 0 (0 = off)"),
            ("balance", self.balance in BALANCES, f"must be one of {', '.join(BALANCES)}"),
        ])

    def arch(self) -> Arch:
        return arch_with_bias(self)

    def phases(self, total_updates: int) -> list[Phase]:
        """Pre-training in two phases, soft BC ("actor_pretrain", `actor_pretrain_fraction` of `pretrain_updates`)
        then the critic on soft returns ("critic_pretrain", the rest and `pretrain_extra`), then offline RL."""
        pre, rl = split_budget(total_updates, 0 if self.pretrain == "none" else self.pretrain_updates)
        actor_steps = {"actor": pre, "critic": 0, "actor+critic": int(pre * self.actor_pretrain_fraction)}.get(
            self.pretrain, 0)
        extra = min(self.pretrain_extra, rl) if pre else 0  # one more epoch of the last pre-training phase
        pre, rl = pre + extra, rl - extra
        actor_steps += extra if self.pretrain == "actor" else 0
        planned = [Phase("actor_pretrain", steps=actor_steps, auto_stop=self.auto_stop(("soft_bc_loss",))),
                   Phase("critic_pretrain", steps=pre - actor_steps, auto_stop=self.auto_stop(("mc_error",)))]
        return [p for p in planned if p.steps] + [Phase(OFFLINE_RL, steps=rl)]


@struct.dataclass
class SACNState:
    actor: Model
    critic: Model
    log_alpha: Model
    soft_returns: jax.Array  # (T,) soft returns-to-go of this seed's own soft-BC policy (zeros until computed)


class SACN(Algorithm):
    def __init__(self, config: SACNConfig, obs_dim: int, act_dim: int, num_transitions: int):
        self.cfg, self.obs_dim, self.act_dim, self.num_transitions = config, obs_dim, act_dim, num_transitions
        arch = config.arch()
        self.actor = TanhGaussianActor(act_dim, config.actor_hidden or config.hidden, config.actor_layer_norm, arch,
                                       tuple(config.log_std_bounds), config.log_std_offset,
                                       1e-3 if config.out_init else None)
        critic_kw = dict(num=config.num_critics, hidden=config.hidden, layer_norm=config.critic_layer_norm,
                         out_scale=3e-3 if config.out_init else None,
                         arch=dataclasses.replace(arch, fan=config.critic_fan))
        self.critic = CriticEnsemble(**critic_kw)
        self.critic_per_member = CriticEnsemble(**critic_kw, per_member_actions=True)  # same parameters
        self.actor_tx, self.critic_tx = optax.adam(config.actor_lr), optax.adam(config.critic_lr)
        self.alpha_tx = optax.adam(config.alpha_lr)
        self.target_entropy = -float(act_dim)

    # ------------------------------------------------------------------------------------------------ set-up
    def init(self, key: jax.Array) -> SACNState:
        k_actor, k_critic = jax.random.split(key)
        obs, act = jnp.zeros((1, self.obs_dim)), jnp.zeros((1, self.act_dim))
        log_alpha = jnp.asarray(jnp.log(self.cfg.init_alpha), jnp.float32)
        return SACNState(
            actor=new_model(self.actor.init(k_actor, obs), self.actor_tx, with_target=False),
            critic=new_model(self.critic.init(k_critic, obs, act), self.critic_tx, with_target=True),
            log_alpha=new_model(log_alpha, self.alpha_tx, with_target=False),
            soft_returns=jnp.zeros((self.num_transitions,), jnp.float32),
        )

    def act(self, state: SACNState, obs: jax.Array) -> jax.Array:
        mean, _ = self.actor.apply(state.actor.params, obs)
        return jnp.tanh(mean)

    def explore(self, state: SACNState, obs: jax.Array, key: jax.Array) -> jax.Array:
        """Online the policy acts with a sample of its tanh-Gaussian (SAC's exploration)."""
        return self.sample_policy(state.actor.params, obs, key)[0]

    def updates(self):
        return {"actor_pretrain": single(chain(self.temperature_update, self.soft_bc_update)),
                "critic_pretrain": single(self.soft_mc_update), OFFLINE_RL: single(self.rl_update)}

    def start_hooks(self):
        return {"critic_pretrain": self.compute_soft_returns}

    # ---------------------------------------------------------------------------------------- soft returns
    def compute_soft_returns(self, state: SACNState, data: Batch, key: jax.Array) -> SACNState:
        """Entropy -log pi(a~|s) of one sampled action at every next observation, or every observation
        (`soft_entropy_at`; in batches), folded into soft returns-to-go with the temperature as it stands."""
        obs = data[self.cfg.soft_entropy_at]
        n, size = obs.shape[0], self.cfg.entropy_batch
        pad = (-n) % size
        chunks = jnp.pad(obs, ((0, pad), (0, 0))).reshape(-1, size, obs.shape[1])
        entropy = lambda args: -self.sample_policy(state.actor.params, *args)[1]  # noqa: E731  (obs, key) -> (B,)
        entropies = jax.lax.map(entropy, (chunks, jax.random.split(key, chunks.shape[0]))).reshape(-1)[:n]
        fold = soft_returns_to_go if self.cfg.soft_entropy_at == "next_observations" else soft_returns_to_go_from_states
        returns = fold(data["rewards"], entropies, data["terminals"], data["timeouts"], self.cfg.gamma,
                       self.alpha(state, clip=False))
        return state.replace(soft_returns=returns)

    # --------------------------------------------------------------------------------------------- pieces
    def alpha(self, state: SACNState, clip: bool) -> jax.Array:
        """The temperature; `clip` (offline RL, as the authors' code): exp of log alpha clipped to
        +-log_alpha_bound when that is set, the parameter itself left where its steps take it."""
        bound, log_alpha = self.cfg.log_alpha_bound, state.log_alpha.params
        return jnp.exp(jnp.clip(log_alpha, -bound, bound) if clip and bound > 0 else log_alpha)

    def sample_policy(self, actor_params, obs: jax.Array, key: jax.Array):
        return sample_tanh_gaussian(key, *self.actor.apply(actor_params, obs), self.cfg.tanh_log_det)

    def td_target(self, state: SACNState, batch: Batch, key: jax.Array, clip: bool = True) -> jax.Array:
        next_action, next_log_prob = self.sample_policy(state.actor.params, batch["next_observations"], key)
        next_q = self.critic.apply(state.critic.target, batch["next_observations"], next_action)
        alpha = self.alpha(state, clip) if self.cfg.backup_entropy else 0.0
        return L.td_target(batch["rewards"], done_flags(batch, self.cfg.timeouts),
                           L.soft_value(next_q, next_log_prob, alpha), self.cfg.gamma)

    def q_and_diversity(self, params, batch: Batch) -> tuple[jax.Array, jax.Array]:
        """Q (N, B) at the dataset actions and the diversity loss, from one forward pass.

        d/da sum_b Q_i(s_b, a_b) gives every sample's action gradient at once (no per-sample Jacobians).
        """
        actions = jnp.broadcast_to(batch["actions"], (self.cfg.num_critics, *batch["actions"].shape))
        q, vjp = jax.vjp(lambda a: self.critic_per_member.apply(params, batch["observations"], a), actions)
        if isinstance(self.cfg.eta, (int, float)) and self.cfg.eta == 0:  # SAC-N; a swept (traced) eta computes it
            return q, jnp.zeros(())
        (grads,) = vjp(jnp.ones_like(q))
        return q, L.edac_diversity_loss(grads)

    # ---------------------------------------------------------------------------------------------- losses
    def pretrain_returns(self, state: SACNState, batch: Batch) -> jax.Array:
        """(B,) the critic's pre-training target: the soft returns-to-go of the soft-BC policy (Alg. 2)."""
        return state.soft_returns[batch["idx"]]

    def critic_loss(self, params, state: SACNState, batch: Batch, key: jax.Array, pretraining: bool):
        loss, metrics, _ = self.critic_terms(params, state, batch, key, pretraining)
        return loss, metrics

    def critic_terms(self, params, state: SACNState, batch: Batch, key: jax.Array, pretraining: bool):
        """(loss, metrics, Q (N, B) at the data's actions): the TD (or pre-training) loss + eta * diversity, with
        the second half of `key` left for a penalty a subclass adds (CQL's)."""
        cfg = self.cfg
        k_target, _ = jax.random.split(key)
        q, diversity = self.q_and_diversity(params, batch)
        td_fn = lambda: self.td_target(state, batch, k_target, clip=not pretraining)  # noqa: E731
        if pretraining:  # the authors' EDAC pre-training averages over critics; its TD loss (below) sums over them
            mc = self.pretrain_returns(state, batch)
            loss = L.pretrain_critic_loss(q, mc, td_fn, cfg.lam, cfg.lambda_mode, per_critic="mean", form=cfg.balance)
            metrics = {"mc_error": jnp.mean((q - mc[None]) ** 2)}
        else:
            loss = L.critic_regression_loss(q, td_fn())
            metrics = {}
        metrics |= {"critic_loss": loss, "q_mean": jnp.mean(q), "q_std": jnp.mean(jnp.std(q, axis=0)),
                    "diversity": diversity}
        return loss + cfg.eta * diversity, metrics, q

    def actor_loss(self, params, state: SACNState, batch: Batch, key: jax.Array):
        action, log_prob = self.sample_policy(params, batch["observations"], key)
        q = self.critic.apply(state.critic.params, batch["observations"], action)
        loss = L.sac_actor_loss(q, log_prob, self.alpha(state, clip=True))
        bc = L.bc_loss(action, batch["actions"])  # logged always: how far the policy has moved from the data
        metrics = {"actor_loss": loss, "entropy": -jnp.mean(log_prob), "bc_mse": bc}
        if self.cfg.bc_weight > 0:
            loss = L.balance_losses(loss, bc, self.cfg.bc_weight, self.cfg.balance)
        return loss, metrics

    def soft_bc_loss(self, params, state: SACNState, batch: Batch, key: jax.Array):
        mean, log_std = self.actor.apply(params, batch["observations"])
        _, log_prob_sampled = sample_tanh_gaussian(key, mean, log_std, self.cfg.tanh_log_det)
        log_prob_data = tanh_gaussian_log_prob(mean, log_std, batch["actions"], log_det=self.cfg.tanh_log_det)
        loss = L.soft_bc_loss(log_prob_sampled, log_prob_data, self.alpha(state, clip=False))
        return loss, {"soft_bc_loss": loss, "entropy": -jnp.mean(log_prob_sampled)}

    # ------------------------------------------------------------------------------------ update functions
    def temperature_update(self, state: SACNState, batch: Batch, key: jax.Array, clip: bool = False):
        """One step on the temperature; `clip`: offline RL, where the temperature used is `alpha(clip=True)`."""
        _, log_prob = self.sample_policy(state.actor.params, batch["observations"], key)

        def loss_fn(log_alpha):
            loss = L.temperature_loss(log_alpha, log_prob, self.target_entropy)
            return loss, {"alpha_loss": loss}

        log_alpha, metrics = gradient_step(state.log_alpha, self.alpha_tx, loss_fn)
        state = state.replace(log_alpha=log_alpha)
        return state, metrics | {"alpha": self.alpha(state, clip)}

    def soft_bc_update(self, state: SACNState, batch: Batch, key: jax.Array):
        actor, metrics = gradient_step(state.actor, self.actor_tx, self.soft_bc_loss, state, batch, key)
        return state.replace(actor=actor), metrics

    def actor_update(self, state: SACNState, batch: Batch, key: jax.Array):
        actor, metrics = gradient_step(state.actor, self.actor_tx, self.actor_loss, state, batch, key)
        return state.replace(actor=actor), metrics

    def soft_mc_update(self, state: SACNState, batch: Batch, key: jax.Array):
        critic, metrics = gradient_step(state.critic, self.critic_tx, self.critic_loss, state, batch, key, True)
        return state.replace(critic=polyak(critic, self.cfg.tau)), metrics

    def td_update(self, state: SACNState, batch: Batch, key: jax.Array):
        critic, metrics = gradient_step(state.critic, self.critic_tx, self.critic_loss, state, batch, key, False)
        return state.replace(critic=polyak(critic, self.cfg.tau)), metrics

    def rl_steps(self):
        """The offline-RL update's three steps, in CORL's order: temperature, actor, critic (+ target)."""
        temperature = lambda state, batch, key: self.temperature_update(state, batch, key, clip=True)  # noqa: E731
        return temperature, self.actor_update, self.td_update

    def rl_update(self, state: SACNState, batch: Batch, key: jax.Array):
        """The three steps on one minibatch, each seeing the one before (CORL's edac.py)."""
        return chain(*self.rl_steps())(state, batch, key)


FAMILY = Family(SACNConfig, SACN)
ALGOS = {
    "edac": Algo("sacn", without_behaviour={}),
    # EDAC's ensemble sizes
    "sacn": Algo("sacn", {"eta": 0.0}, sections=("edac",), skip=("eta",), without_behaviour={}),
    "edac_bc": Algo("sacn", {"bc_weight": 1.0}, sections=("edac",), without_behaviour={"bc_weight": 0.0}),
}
# The paper's per-env values (Section 5, Appendix G Table 3), keyed by (family or algorithm, env) as
# `offrl_jax.algos.ENV_DEFAULTS`: Adroit's pre-training is the paper's 200k updates; EDAC's ensemble sizes and eta
# per env, pen-cloned's eta under ("edac", "pen:cloned").
ENV_DEFAULTS = {
    ("sacn", "halfcheetah"): {"lam": 0.1},
    ("sacn", "walker2d"): {"lam": 0.1},
    ("sacn", "door"): {"pretrain_updates": 200_000},
    ("sacn", "hammer"): {"pretrain_updates": 200_000},
    ("sacn", "relocate"): {"pretrain_updates": 200_000},
    ("sacn", "pen"): {"pretrain_updates": 200_000},
    ("edac", "hopper"): {"num_critics": 50, "eta": 1.0},
    ("edac", "halfcheetah"): {"num_critics": 10, "eta": 1.0},
    ("edac", "walker2d"): {"num_critics": 10, "eta": 1.0},
    ("edac", "door"): {"num_critics": 50, "eta": 200.0},
    ("edac", "hammer"): {"num_critics": 50, "eta": 200.0},
    ("edac", "relocate"): {"num_critics": 50, "eta": 200.0},
    ("edac", "pen"): {"num_critics": 20, "eta": 1000.0},
    ("edac", "pen:cloned"): {"eta": 10.0},
}
# "authors": the authors' code switch by switch (`AUTHORS_CODE`, docs/fidelity.md)
PRESETS = {
    "authors": {
        "sacn": AUTHORS_CODE | {"hidden_bias": 0.1, "tanh_log_det": "eps", "log_alpha_bound": 10.0,
                                "pretrain_extra": 1000, "soft_entropy_at": "observations", "critic_fan": "out"},
    },
}
