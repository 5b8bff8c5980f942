"""The IQL family: its update order, its value pre-training by hand on two states, its checks, and a run."""
import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from offrl_jax import losses as L
from offrl_jax.algos import make_algorithm, make_config


def _batch(batch=6, obs_dim=3, act_dim=2):
    keys = jax.random.split(jax.random.PRNGKey(0), 5)
    return {"observations": jax.random.normal(keys[0], (batch, obs_dim)),
            "actions": jnp.tanh(jax.random.normal(keys[1], (batch, act_dim))),
            "next_observations": jax.random.normal(keys[3], (batch, obs_dim)),
            "rewards": jax.random.normal(keys[4], (batch,)),
            "terminals": jnp.zeros(batch), "timeouts": jnp.zeros(batch), "returns": jnp.ones(batch)}


def test_published_defaults_and_one_line_checks():
    cfg = make_config("iql", "halfcheetah")
    assert (cfg.expectile, cfg.beta, cfg.tau, cfg.deterministic) == (0.7, 3.0, 0.005, False)
    assert cfg.hidden == (256, 256) and not cfg.actor_layer_norm and not cfg.critic_layer_norm
    hopper = make_config("iql", "hopper")
    assert hopper.deterministic and hopper.tau == 0.001 and hopper.normalize_reward  # CORL's hopper config
    assert not cfg.normalize_reward and not make_config("iql", "walker2d").normalize_reward
    with pytest.raises(ValueError, match="IQLConfig.expectile = 1.0 must be in"):
        make_config("iql", "hopper", expectile=1.0)


@pytest.mark.parametrize("deterministic", [False, True])
def test_one_update_is_v_then_q_then_the_actor_on_the_same_minibatch(deterministic):
    """V regresses on the target critics' min Q; Q on r + gamma V(s') with V from before the step; the actor's
    weights use the advantage against the V before the step."""
    cfg = make_config("iql", "walker2d", hidden=(8, 8), pretrain="none", deterministic=deterministic)
    algo = make_algorithm(cfg, 3, 2, 0)
    state = algo.init(jax.random.PRNGKey(1))
    batch = _batch()
    new, metrics = algo.rl_update(state, batch, jax.random.PRNGKey(2))
    assert {"value_loss", "critic_loss", "actor_loss"} <= set(metrics)

    def step(model, tx, loss_fn):
        grads = jax.grad(loss_fn)(model.params)
        updates, _ = tx.update(grads, model.opt_state, model.params)
        return optax.apply_updates(model.params, updates)

    target_q = jnp.min(algo.critic.apply(state.critic.target, batch["observations"], batch["actions"]), axis=0)
    v_old = algo.value.apply(state.value.params, batch["observations"])
    value = step(state.value, algo.value_tx,
                 lambda p: L.expectile_loss(target_q - algo.value.apply(p, batch["observations"]), 0.7))
    y = batch["rewards"] + 0.99 * algo.value.apply(state.value.params, batch["next_observations"])
    critic = step(state.critic, algo.critic_tx,
                  lambda p: jnp.mean((algo.critic.apply(p, batch["observations"], batch["actions"]) - y) ** 2))
    actor = step(state.actor, algo.actor_tx,
                 lambda p: L.awr_actor_loss(algo.neg_log_lik(p, batch), target_q - v_old, 3.0))
    for got, want in [(new.value.params, value), (new.critic.params, critic), (new.actor.params, actor)]:
        for a, b in zip(jax.tree.leaves(got), jax.tree.leaves(want)):
            np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6)


def test_value_pretraining_reaches_the_behaviour_value_of_two_states():
    """State 0 is seen with returns 1 and 3, state 1 with 10: pre-trained V is their mean per state, (2, 10), not
    an expectile (which would put state 0 at 2.4 for 0.7)."""
    obs = jnp.array([[1.0, 0.0], [1.0, 0.0], [0.0, 1.0], [0.0, 1.0]])
    batch = {"observations": obs, "actions": jnp.zeros((4, 1)), "next_observations": obs,
             "rewards": jnp.zeros(4), "terminals": jnp.ones(4), "timeouts": jnp.zeros(4),
             "returns": jnp.array([1.0, 3.0, 10.0, 10.0])}
    cfg = make_config("iql", "hopper", hidden=(16,), value_lr=3e-2, critic_lr=3e-2, pretrain="critic")
    algo = make_algorithm(cfg, 2, 1, 0)
    state = algo.init(jax.random.PRNGKey(0))
    update = jax.jit(algo.mc_update)
    for _ in range(1500):
        state, _ = update(state, batch, jax.random.PRNGKey(0))
    v = algo.value.apply(state.value.params, jnp.eye(2))
    np.testing.assert_allclose(v, [2.0, 10.0], atol=0.05)


def test_pretrained_iql_runs_through_the_runner(tmp_path, tiny_dataset):
    from offrl_jax.run.results import read_curves
    from offrl_jax.run.runner import run_study
    from offrl_jax.run.study import Study, Variant

    study = Study(name="t", dataset="synthetic", env="hopper", seeds=(0,), updates=400, eval_every=200,
                  eval_episodes=1, batch_size=32,
                  variants=(Variant.of("pretrained", "iql", pretrain_updates=200, hidden=(16, 16),
                                       deterministic=False),))
    run_study(study, tmp_path, tiny_dataset, progress=False)
    rows = read_curves(tmp_path / "curves.csv")
    assert [(r["update"], r["phase"]) for r in rows] == [(200, "pretrain"), (400, "offline_rl")]
