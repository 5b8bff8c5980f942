"""The ReBRAC family: its dataset next actions, its update order, its checks, and a run through the runner."""
import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from offrl_jax import losses as L
from offrl_jax.algos import make_algorithm, make_config
from offrl_jax.data.device import next_actions


def test_next_actions_stay_inside_the_episode():
    """Rows 0-1 end at a terminal, rows 2-3 at a time-out, row 4 is the dataset's last: each episode's last row has
    no next action, and its own stands in."""
    actions = jnp.arange(5.0)[:, None] * jnp.ones((1, 2))
    terminals = jnp.array([0.0, 1.0, 0.0, 0.0, 0.0])
    timeouts = jnp.array([0.0, 0.0, 0.0, 1.0, 0.0])
    np.testing.assert_array_equal(next_actions(actions, terminals, timeouts)[:, 0], [1.0, 1.0, 3.0, 3.0, 4.0])


def test_published_defaults_and_one_line_checks():
    cfg = make_config("rebrac", "walker2d")
    assert (cfg.actor_beta, cfg.critic_beta) == (0.05, 0.1)
    assert cfg.hidden == (256, 256, 256) and not cfg.actor_layer_norm and cfg.critic_layer_norm
    assert cfg.actor_lr == cfg.critic_lr == 1e-3 and cfg.timeouts == "drop" and cfg.num_critics == 2
    assert (make_config("rebrac", "halfcheetah").actor_beta, make_config("rebrac", "hopper").critic_beta) == \
        (0.001, 0.01)
    with pytest.raises(ValueError, match="ReBRACConfig.actor_beta = -1.0 must be >= 0"):
        make_config("rebrac", "hopper", actor_beta=-1.0)
    with pytest.raises(ValueError, match="ReBRACConfig.policy_delay = 0 must be >= 1"):
        make_config("rebrac", "hopper", policy_delay=0)


def _batches(k=2, batch=6, obs_dim=3, act_dim=2):
    keys = jax.random.split(jax.random.PRNGKey(0), 5)
    return {"observations": jax.random.normal(keys[0], (k, batch, obs_dim)),
            "actions": jnp.tanh(jax.random.normal(keys[1], (k, batch, act_dim))),
            "next_actions": jnp.tanh(jax.random.normal(keys[2], (k, batch, act_dim))),
            "next_observations": jax.random.normal(keys[3], (k, batch, obs_dim)),
            "rewards": jax.random.normal(keys[4], (k, batch)),
            "terminals": jnp.zeros((k, batch)), "timeouts": jnp.zeros((k, batch)), "returns": jnp.ones((k, batch))}


def _adam_count(model) -> int:
    return int(model.opt_state[0].count)  # optax.adam: (ScaleByAdamState, ...)


def test_one_call_is_two_critic_updates_and_one_actor_update_on_the_first_minibatch():
    cfg = make_config("rebrac", "hopper", hidden=(8, 8), pretrain="none")
    algo = make_algorithm(cfg, 3, 2, 0)
    state = algo.init(jax.random.PRNGKey(1))
    batches, key = _batches(), jax.random.PRNGKey(2)
    new, metrics = algo.rl_update(state, batches, key)
    assert _adam_count(new.critic) == 2 and _adam_count(new.actor) == 1
    assert {"critic_loss", "actor_loss", "bc_mse"} <= set(metrics)
    # the actor step saw the critic after its first update, on the first minibatch
    k0 = jax.random.split(key, 2)[0]
    first = jax.tree.map(lambda x: x[0], batches)
    critic_grads, _ = jax.grad(algo.critic_loss, has_aux=True)(state.critic.params, state, first, k0, False)
    updates, _ = algo.critic_tx.update(critic_grads, state.critic.opt_state, state.critic.params)
    after_first = state.replace(critic=state.critic.replace(params=optax.apply_updates(state.critic.params, updates)))
    actor_grads, _ = jax.grad(algo.actor_loss, has_aux=True)(state.actor.params, after_first, first)
    updates, _ = algo.actor_tx.update(actor_grads, state.actor.opt_state, state.actor.params)
    expected = optax.apply_updates(state.actor.params, updates)
    for a, b in zip(jax.tree.leaves(new.actor.params), jax.tree.leaves(expected)):
        np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6)


def test_the_critic_target_penalises_the_distance_to_the_next_dataset_action():
    """With the critic's beta the TD target drops by beta * ||a~' - a'||^2 where the target bootstraps."""
    algo0 = make_algorithm(make_config("rebrac", "hopper", hidden=(8, 8), critic_beta=0.0), 3, 2, 0)
    algo1 = make_algorithm(make_config("rebrac", "hopper", hidden=(8, 8), critic_beta=0.5), 3, 2, 0)
    state = algo0.init(jax.random.PRNGKey(3))
    batch = jax.tree.map(lambda x: x[0], _batches())
    batch["terminals"] = batch["terminals"].at[0].set(1.0)
    key = jax.random.PRNGKey(4)
    next_pi = L.target_policy_smoothing(key, algo0.actor.apply(state.actor.target, batch["next_observations"]))
    penalty = jnp.sum((next_pi - batch["next_actions"]) ** 2, axis=-1)
    drop = algo0.td_target(state, batch, key) - algo1.td_target(state, batch, key)
    np.testing.assert_allclose(drop, 0.99 * 0.5 * penalty * (1.0 - batch["terminals"]), rtol=1e-5, atol=1e-6)


def test_pretrained_rebrac_runs_through_the_runner(tmp_path, tiny_dataset):
    import json

    from offrl_jax.run.results import read_curves
    from offrl_jax.run.runner import run_study
    from offrl_jax.run.study import Study, Variant

    study = Study(name="t", dataset="synthetic", env="hopper", seeds=(0, 1), updates=400, eval_every=200,
                  eval_episodes=1, batch_size=32, reference="scratch",
                  variants=(Variant.of("pretrained", "rebrac", pretrain_updates=200, hidden=(16, 16)),
                            Variant.of("scratch", "rebrac", pretrain="none", hidden=(16, 16))))
    run_study(study, tmp_path, tiny_dataset, progress=False)
    rows = read_curves(tmp_path / "curves.csv")
    assert [(r["variant"], r["update"], r["phase"]) for r in rows if r["seed"] == 0] == [
        ("pretrained", 200, "pretrain"), ("pretrained", 400, "offline_rl"),
        ("scratch", 200, "offline_rl"), ("scratch", 400, "offline_rl")]
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert [s["variant"] for s in summary] == ["pretrained", "scratch"]
