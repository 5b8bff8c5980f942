"""The CQL family (`cql`): SAC-N's tanh-Gaussian actor, critics and temperature (`algos/sacn.py`) with CORL's
importance-sampled CQL penalty on the critics.  Its algorithms (`ALGOS`):

    cql    CQL (CORL's cql.py): SAC with N = 2 + cql_alpha * the penalty, no entropy in the backup, the temperature,
           actor and critic losses all from the state before the update
    calql  Cal-QL (Nakamoto et al. 2023; CORL's cal_ql.py, the authors' JaxCQL): CQL with the policy-action values
           under the push-down bounded below by the Monte-Carlo return-to-go of the row's state,
           max(Q(s, a~pi(.|s)), G(s)) and max(Q(s, a~pi(.|s')), G(s)) (both sets of policy actions, evaluated at s, as
           both codes do; the random actions and the data's Q are not bounded)

Which return bounds a row: the data's discounted return-to-go (`batch["returns"]`, this library's one definition:
an episode cut by the time limit gets the r_T / (1 - gamma) tail, where both Cal-QL codes stop the sum there).
Online (`calibration_online`): "episode", the authors' code, bounds an online row by the return of its finished
episode, which the online buffer writes, and draws only rows of finished episodes; "off", CORL's, stores no return
online and turns calibration off for every row of the online phase.

Pre-training (first imitate, then improve) is SAC-N's: soft BC with the temperature tuned, then critic regression,
then offline RL.  With `backup_entropy` off (CQL's and Cal-QL's backup) the critic regresses on the data's plain
Monte-Carlo returns, the values its backup estimates; with it on, on SAC-N's soft returns.  The CQL penalty applies in
critic pre-training as in offline RL (as TD3+BC+CQL's does).
"""
from __future__ import annotations

import dataclasses
from typing import Literal

import jax
import jax.numpy as jnp

from offrl_jax import losses as L
from offrl_jax.algos.common import Algo, Batch, DataNeeds, Family, repeat_obs, uniform_actions
from offrl_jax.algos.config import AUTHORS_CODE, check_cql_fields, require
from offrl_jax.algos.sacn import SACN, SACNConfig, SACNState


@dataclasses.dataclass(frozen=True)
class CQLConfig(SACNConfig):
    cql_alpha: float = 0.0  # CQL: critic loss = TD + cql_alpha * CQL penalty (0 = off)
    cql_actions: int = 10  # CQL: random and policy actions sampled per state
    cql_temperature: float = 1.0  # CQL: logsumexp temperature
    # CQL (CORL's cql.py and cal_ql.py): temperature, actor and critic losses all from the state before the update;
    # False = EDAC's order (CORL's edac.py): temperature, then actor, then critic, each seeing the step before
    simultaneous_update: bool = False
    # Cal-QL: bound the policy-action values under the CQL push-down below by the state's Monte-Carlo return
    calibration: bool = False
    # Cal-QL online: "episode" bounds an online row by its finished episode's return and draws only rows of
    # finished episodes (the authors' JaxCQL code); "off" turns calibration off for the whole online phase (CORL's
    # cal_ql.py, which stores no online returns)
    calibration_online: Literal["episode", "off"] = "episode"

    def __post_init__(self):
        super().__post_init__()
        check_cql_fields(self)
        require(self, [("cql_alpha", self.cql_alpha >= 0, "must be >= 0 (0 = off)")])

    def needs(self) -> DataNeeds:
        """Cal-QL reads the Monte-Carlo returns; online, with `calibration_online` "episode", only rows of finished
        episodes (whose returns are known) are drawn."""
        return dataclasses.replace(super().needs(), returns=self.calibration and self.calibration_online == "episode")


class CQL(SACN):
    cfg: CQLConfig

    def start_hooks(self):
        """SAC-N's soft returns are computed only for a backup with entropy (else the data's returns are used)."""
        return super().start_hooks() if self.cfg.backup_entropy else {}

    def pretrain_returns(self, state: SACNState, batch: Batch) -> jax.Array:
        return super().pretrain_returns(state, batch) if self.cfg.backup_entropy else batch["returns"]

    def calibrated(self, batch: Batch) -> bool:
        """Whether this minibatch's policy-action values are bounded: Cal-QL offline, and online unless
        `calibration_online` is "off" (an online-phase minibatch carries the `online` field)."""
        return self.cfg.calibration and (self.cfg.calibration_online == "episode" or "online" not in batch)

    def cql_penalty(self, params, state: SACNState, batch: Batch, q_data: jax.Array, key: jax.Array):
        """(CQL penalty (), metrics): CORL's importance-sampled logsumexp over M random actions at s and M policy
        actions sampled at s and at s' (all evaluated at s), minus Q at the data's action; Cal-QL bounds the policy
        actions' values by the row's return first."""
        m, obs, next_obs = self.cfg.cql_actions, batch["observations"], batch["next_observations"]
        k_rand, k_pi, k_next = jax.random.split(key, 3)
        obs_m = repeat_obs(obs, m)
        a_pi, logp_pi = self.sample_policy(state.actor.params, obs_m, k_pi)
        a_next, logp_next = self.sample_policy(state.actor.params, repeat_obs(next_obs, m), k_next)
        q_rand = self.critic.apply(params, obs_m, uniform_actions(k_rand, obs.shape[0], m, self.act_dim))
        q_pi, q_next = self.critic.apply(params, obs_m, a_pi), self.critic.apply(params, obs_m, a_next)
        metrics = {}
        if self.cfg.calibration:  # the share of policy-action values below the bound (CORL's bound_rate)
            below = jnp.concatenate([q_pi, q_next], axis=-1) < batch["returns"][None, :, None]
            metrics["calibration_rate"] = jnp.mean(below)
        if self.calibrated(batch):
            q_pi, q_next = L.calibrated_q(q_pi, batch["returns"]), L.calibrated_q(q_next, batch["returns"])
        penalty = L.cql_importance_penalty(q_rand, q_pi, logp_pi, q_next, logp_next, q_data, self.act_dim,
                                           self.cfg.cql_temperature)
        return penalty, metrics | {"cql_penalty": penalty}

    def critic_loss(self, params, state: SACNState, batch: Batch, key: jax.Array, pretraining: bool):
        loss, metrics, q = self.critic_terms(params, state, batch, key, pretraining)
        if self.cfg.cql_alpha > 0:
            _, k_cql = jax.random.split(key)  # the half of the key critic_terms leaves
            penalty, cql_metrics = self.cql_penalty(params, state, batch, q, k_cql)
            loss, metrics = loss + self.cfg.cql_alpha * penalty, metrics | cql_metrics
        return loss, metrics

    def rl_update(self, state: SACNState, batch: Batch, key: jax.Array):
        """With `simultaneous_update` (CORL's CQL and Cal-QL) every loss is computed from the incoming state and the
        three steps are applied together; else SAC-N's order."""
        if not self.cfg.simultaneous_update:
            return super().rl_update(state, batch, key)
        steps = self.rl_steps()
        (t, m_t), (a, m_a), (c, m_c) = (fn(state, batch, k) for fn, k in zip(steps, jax.random.split(key, 3)))
        return state.replace(log_alpha=t.log_alpha, actor=a.actor, critic=c.critic), m_t | m_a | m_c


FAMILY = Family(CQLConfig, CQL)
# the authors' CQL configs (their CORL fork's configs/cql/door): cql_min_q_weight 10, policy_lr 3e-5, no entropy in
# the backup (CORL's own door/pen configs, added later: cql_alpha 1, policy_lr 1e-4); without its penalty (online-rl
# arm): SAC with twin critics and no entropy in the backup
CQL_VALUES = {"num_critics": 2, "eta": 0.0, "cql_alpha": 10.0, "backup_entropy": False, "pretrain": "none",
              "actor_lr": 3e-5, "simultaneous_update": True}
ALGOS = {
    # SAC-N's per-env values (`sacn`'s sections: lam, Adroit's pre-training length) as when CQL was one of its variants
    "cql": Algo("cql", CQL_VALUES, sections=("sacn",), without_behaviour={"cql_alpha": 0.0}),
    # CORL's cal_ql.py TrainConfig (no MuJoCo configs of its own): cql_alpha 10 offline and online, policy_lr 3e-5,
    # no entropy backup, the rest CQL's; online its mixing_ratio 0.5 and one update per env step (replay "mix",
    # online_mix 0.5, --utd 1: the fine-tuning study's defaults)
    "calql": Algo("cql", CQL_VALUES | {"calibration": True}, sections=("sacn",),
                  without_behaviour={"cql_alpha": 0.0, "calibration": False}),
}
ENV_DEFAULTS: dict = {}
# "authors": CORL's cql.py as the authors ran it, for both: orthogonal init of every layer (cal_ql.py's init too),
# log-std offset -1 within [-20, 2], temperature learning rate = policy learning rate, terminals only in the TD target,
# no EDAC-style output init
PRESETS = {
    "authors": {
        "cql": AUTHORS_CODE | {"init": "orthogonal_all", "out_init": False, "log_std_bounds": (-20.0, 2.0),
                               "log_std_offset": -1.0, "alpha_lr": 3e-5, "timeouts": "bootstrap"},
    },
}
