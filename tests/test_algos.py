"""Loss conventions of the algorithms against the authors' code, on tiny networks."""
import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from offrl_jax.algos import make_algorithm, make_config


def tiny_batch(obs_dim=3, act_dim=2, batch=5, rows=7):
    ks = jax.random.split(jax.random.PRNGKey(0), 4)
    return {
        "observations": jax.random.normal(ks[0], (batch, obs_dim)),
        "actions": jnp.tanh(jax.random.normal(ks[1], (batch, act_dim))),
        "next_observations": jax.random.normal(ks[2], (batch, obs_dim)),
        "rewards": jax.random.normal(ks[3], (batch,)),
        "terminals": jnp.array([0.0, 0.0, 1.0, 0.0, 0.0]),
        "idx": jnp.array([0, 2, 4, 6, 1]),
    }


def test_edac_critic_losses_mean_over_critics_in_pretraining_and_sum_in_td():
    """The authors' EDAC: pre-training MC loss ((q - R)^2).mean() over critics and batch; TD loss
    ((q - y)^2).mean(dim=1).sum(dim=0) (CORL).  eta = 0 isolates the regression terms."""
    cfg = make_config("edac", "hopper", num_critics=3, eta=0.0, hidden=(8, 8), lam=0.0)
    algo = make_algorithm(cfg, 3, 2, 7)
    state = algo.init(jax.random.PRNGKey(1))
    state = state.replace(soft_returns=jnp.arange(7.0) * 10.0)
    batch, key = tiny_batch(), jax.random.PRNGKey(2)
    q = algo.critic.apply(state.critic.params, batch["observations"], batch["actions"])  # (3, 5)

    pre, _ = algo.critic_loss(state.critic.params, state, batch, key, True)
    np.testing.assert_allclose(pre, jnp.mean((q - state.soft_returns[batch["idx"]][None]) ** 2), rtol=1e-6)

    td, _ = algo.critic_loss(state.critic.params, state, batch, key, False)
    target = algo.td_target(state, batch, jax.random.split(key)[0])
    np.testing.assert_allclose(td, jnp.sum(jnp.mean((q - target[None]) ** 2, axis=1)), rtol=1e-6)


def test_cql_baseline_follows_the_authors_configs():
    """configs/cql/{door,pen}/human_v1.yaml: cql_min_q_weight 10, policy_lr 3e-5, qf_lr 3e-4, no entropy backup."""
    for env in ("door", "pen", "hopper"):
        cfg = make_config("cql", env)
        assert (cfg.cql_alpha, cfg.actor_lr, cfg.critic_lr, cfg.backup_entropy) == (10.0, 3e-5, 3e-4, False)
        assert cfg.num_critics == 2 and cfg.pretrain == "none" and cfg.simultaneous_update
    assert "simultaneous_update" not in {f.name for f in dataclasses.fields(make_config("edac", "hopper"))}


def test_edac_target_mode_is_continuous_at_lambda_zero():
    """lambda_mode="target" regresses on one mixed target; as lam -> 0 it must tend to the lam = 0 MC loss (both
    averaged over critics), not to N times it."""
    losses = {}
    for lam, mode in ((0.0, "loss"), (1e-7, "target")):
        cfg = make_config("edac", "hopper", num_critics=3, eta=0.0, hidden=(8, 8), lam=lam, lambda_mode=mode)
        algo = make_algorithm(cfg, 3, 2, 7)
        state = algo.init(jax.random.PRNGKey(1)).replace(soft_returns=jnp.arange(7.0) * 10.0)
        losses[mode], _ = algo.critic_loss(state.critic.params, state, tiny_batch(), jax.random.PRNGKey(2), True)
    np.testing.assert_allclose(losses["target"], losses["loss"], rtol=1e-4)


def test_driver_refuses_an_evaluation_grid_off_the_delayed_update():
    import pytest

    from offrl_jax.algos.common import Phase
    from offrl_jax.driver import check_call_grid

    step = lambda *a: a  # noqa: E731  (never called)
    check_call_grid([Phase("pretrain", step, 1000), Phase("offline_rl", step, 2000, updates_per_call=2)], 500)
    with pytest.raises(ValueError, match="the updates before it \\(1001\\)"):
        check_call_grid([Phase("pretrain", step, 1001), Phase("offline_rl", step, 2000, updates_per_call=2)], 500)
    with pytest.raises(ValueError, match="evaluation interval \\(501\\)"):
        check_call_grid([Phase("offline_rl", step, 2000, updates_per_call=2)], 501)


def test_cql_update_computes_every_loss_from_the_incoming_state():
    """CORL's cql.py: the critic's loss uses the actor and temperature from before the step, so the simultaneous
    update's critic loss is exactly a critic-only step's from the same state; EDAC's sequential one is not."""
    batch, key = tiny_batch(), jax.random.PRNGKey(3)
    for simultaneous in (True, False):
        cfg = make_config("cql", "door", hidden=(8, 8), simultaneous_update=simultaneous, cql_actions=2)
        algo = make_algorithm(cfg, 3, 2, 7)
        state = algo.init(jax.random.PRNGKey(1))
        new, metrics = algo.rl_update(state, batch, key)
        _, alone = algo.td_update(state, batch, jax.random.split(key, 3)[2])
        assert {"alpha_loss", "actor_loss", "critic_loss", "cql_penalty"} <= set(metrics)
        assert (float(metrics["critic_loss"]) == float(alone["critic_loss"])) == simultaneous
        kernel = lambda s: s.actor.params["params"]["MLP_0"]["Dense_0"]["kernel"]  # noqa: E731
        assert not np.allclose(kernel(new), kernel(state))  # the actor did step


def test_edac_logs_the_hand_over_diagnostics():
    """EDAC logs how far its actions are from the data (bc_mse, also without a BC term) and the ensemble's spread
    at the data actions (q_std: the std over critics, batch-mean)."""
    batch = tiny_batch()
    cfg = make_config("edac", "door", hidden=(8, 8), num_critics=3)
    algo = make_algorithm(cfg, 3, 2, 7)
    state = algo.init(jax.random.PRNGKey(1))
    _, metrics = algo.rl_update(state, batch, jax.random.PRNGKey(2))
    q = algo.critic_per_member.apply(state.critic.params, batch["observations"],
                                     jnp.broadcast_to(batch["actions"], (3, *batch["actions"].shape)))
    np.testing.assert_allclose(float(metrics["q_std"]), float(jnp.mean(jnp.std(q, axis=0))), rtol=1e-5)
    assert float(metrics["q_std"]) > 0 and float(metrics["bc_mse"]) > 0


def _calql_losses(returns: float, online: bool, **overrides):
    """The critic loss and metrics of CQL and Cal-QL on one minibatch (every return set to `returns`), same key."""
    batch = tiny_batch() | {"returns": jnp.full((5,), returns)}
    if online:
        batch["online"] = jnp.array([0.0, 1.0, 0.0, 1.0, 0.0])
    out = {}
    for algo in ("cql", "calql"):
        cfg = make_config(algo, "hopper", hidden=(8, 8), cql_actions=3, **overrides)
        model = make_algorithm(cfg, 3, 2, 7)
        state = model.init(jax.random.PRNGKey(1))
        out[algo] = model.critic_loss(state.critic.params, state, batch, jax.random.PRNGKey(4), False)
    return out


def test_calql_bounds_the_policy_values_by_the_returns_and_cql_does_not():
    """Returns far below every Q: the bound never binds and Cal-QL's loss is CQL's; far above: it binds everywhere,
    the push-down's policy terms are the returns and the loss differs."""
    low = _calql_losses(-1e4, online=False)
    assert float(low["calql"][0]) == float(low["cql"][0]) and float(low["calql"][1]["calibration_rate"]) == 0.0
    high = _calql_losses(1e2, online=False)
    assert float(high["calql"][1]["calibration_rate"]) == 1.0 and "calibration_rate" not in high["cql"][1]
    assert float(high["calql"][1]["cql_penalty"]) > float(high["cql"][1]["cql_penalty"]) + 50


def test_calql_online_calibration_modes():
    """Online (a minibatch with the `online` field): "episode" (the authors' code) keeps the bound, "off" (CORL's)
    turns it off for every row; only "episode" draws rows of finished episodes alone."""
    episode = _calql_losses(1e2, online=True)
    assert float(episode["calql"][0]) != float(episode["cql"][0])
    off = _calql_losses(1e2, online=True, calibration_online="off")
    assert float(off["calql"][0]) == float(off["cql"][0])
    assert float(off["calql"][1]["calibration_rate"]) == 1.0  # still logged: how often it would have bound
    assert make_config("calql", "hopper").needs().returns
    assert not make_config("calql", "hopper", calibration_online="off").needs().returns
    assert not make_config("cql", "hopper").needs().returns


def test_cql_critic_pretrains_on_the_returns_its_backup_estimates():
    """Without entropy in the backup (CQL, Cal-QL) the critic pre-trains on the data's Monte-Carlo returns and no
    soft returns are computed; with it, on SAC-N's soft returns."""
    batch = tiny_batch() | {"returns": jnp.arange(5.0)}
    cfg = make_config("calql", "hopper", hidden=(8, 8), cql_actions=3, pretrain="actor+critic", lam=0.0,
                      cql_alpha=0.0)
    algo = make_algorithm(cfg, 3, 2, 7)
    state = algo.init(jax.random.PRNGKey(1))
    assert algo.start_hooks() == {}
    loss, _ = algo.critic_loss(state.critic.params, state, batch, jax.random.PRNGKey(2), True)
    q = algo.critic.apply(state.critic.params, batch["observations"], batch["actions"])
    np.testing.assert_allclose(loss, jnp.mean((q - batch["returns"][None]) ** 2), rtol=1e-6)
    soft = make_algorithm(dataclasses.replace(cfg, backup_entropy=True), 3, 2, 7)
    assert set(soft.start_hooks()) == {"critic_pretrain"}
    np.testing.assert_allclose(soft.pretrain_returns(state, batch), state.soft_returns[batch["idx"]])
