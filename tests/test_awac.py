"""The AWAC family: CORL's values, its update order and draws by hand, its pre-training, its online form and
exploration, and a run through the runner.  One update against CORL's torch code: tests/test_parity_torch.py."""
import argparse

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from offrl_jax import losses as L
from offrl_jax.algos import ALGOS, make_algorithm, make_config
from offrl_jax.nets import gaussian_log_prob


def _batch(batch=6, obs_dim=3, act_dim=2):
    keys = jax.random.split(jax.random.PRNGKey(0), 5)
    return {"observations": jax.random.normal(keys[0], (batch, obs_dim)),
            "actions": jnp.tanh(jax.random.normal(keys[1], (batch, act_dim))),
            "next_observations": jax.random.normal(keys[3], (batch, obs_dim)),
            "rewards": jax.random.normal(keys[4], (batch,)),
            "terminals": jnp.array([0.0, 1.0, 0.0, 0.0, 0.0, 0.0]), "timeouts": jnp.zeros(batch),
            "returns": jnp.arange(batch, dtype=jnp.float32)}


def test_corls_values_and_one_line_checks():
    cfg = make_config("awac", "hopper")
    assert (cfg.awac_lambda, cfg.max_weight, cfg.actor_lr, cfg.critic_lr, cfg.tau, cfg.gamma) == (
        0.3333, 100.0, 3e-4, 3e-4, 0.005, 0.99)
    assert cfg.hidden == (256, 256, 256) and not cfg.actor_layer_norm and not cfg.critic_layer_norm
    assert (cfg.init, cfg.num_critics, cfg.timeouts, cfg.replay) == ("torch", 2, "drop", "append")
    assert make_config("awac", "walker2d").awac_lambda == make_config("awac", "halfcheetah").awac_lambda == 0.3333
    assert make_config("awac", "door").awac_lambda == make_config("awac", "pen").awac_lambda == 0.1
    assert make_config("awac").awac_lambda == 1.0  # CORL's TrainConfig default, with no env
    for field, value, fragment in (("awac_lambda", 0.0, "must be positive"), ("max_weight", -1.0, "must be positive"),
                                   ("num_critics", 3, "must be 2")):
        with pytest.raises(ValueError, match=f"AWACConfig.{field} = .* {fragment}"):
            make_config("awac", "hopper", **{field: value})


def _step(model, tx, loss_fn):
    grads = jax.grad(loss_fn)(model.params)
    updates, _ = tx.update(grads, model.opt_state, model.params)
    return optax.apply_updates(model.params, updates)


def test_one_update_is_the_critics_then_the_actor_under_them_then_the_targets():
    """The critics regress on r + gamma (1 - d) min Q'(s', a~') (a~' the policy's clipped sample, no entropy);
    then the actor's weights exp(A / lambda), A against a clipped sample at s, come from the critics just updated;
    then the targets move by tau."""
    cfg = make_config("awac", "walker2d", hidden=(8, 8), pretrain="none")
    algo = make_algorithm(cfg, 3, 2, 0)
    state = algo.init(jax.random.PRNGKey(1))
    batch, key = _batch(), jax.random.PRNGKey(2)
    new, metrics = algo.rl_update(state, batch, key)
    assert {"critic_loss", "actor_loss", "advantage"} <= set(metrics)

    k_target, k_pi = jax.random.split(key)
    mean, log_std = algo.actor.apply(state.actor.params, batch["next_observations"])
    next_a = jnp.clip(mean + jnp.exp(log_std) * jax.random.normal(k_target, mean.shape), -1, 1)
    next_q = jnp.min(algo.critic.apply(state.critic.target, batch["next_observations"], next_a), axis=0)
    y = batch["rewards"] + 0.99 * (1 - batch["terminals"]) * next_q
    critic = _step(state.critic, algo.critic_tx, lambda p: jnp.sum(
        jnp.mean((algo.critic.apply(p, batch["observations"], batch["actions"]) - y) ** 2, axis=1)))
    mean, log_std = algo.actor.apply(state.actor.params, batch["observations"])
    a_pi = jnp.clip(mean + jnp.exp(log_std) * jax.random.normal(k_pi, mean.shape), -1, 1)
    q = lambda a: jnp.min(algo.critic.apply(critic, batch["observations"], a), axis=0)  # noqa: E731
    weights = jnp.minimum(jnp.exp((q(batch["actions"]) - q(a_pi)) / 0.3333), 100.0)
    actor = _step(state.actor, algo.actor_tx, lambda p: jnp.mean(
        -weights * gaussian_log_prob(*algo.actor.apply(p, batch["observations"]), batch["actions"])))
    target = optax.incremental_update(critic, state.critic.target, 0.005)
    for got, want in [(new.critic.params, critic), (new.actor.params, actor), (new.critic.target, target)]:
        for a, b in zip(jax.tree.leaves(got), jax.tree.leaves(want)):
            np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6)


def test_a_swept_lambda_computes_what_each_value_does():
    from offrl_jax.algos.common import with_hparams

    algo = make_algorithm(make_config("awac", "hopper", hidden=(8, 8)), 3, 2, 0)
    state, batch, key = algo.init(jax.random.PRNGKey(1)), _batch(), jax.random.PRNGKey(2)
    swept = jax.vmap(lambda lam: with_hparams(algo, awac_lambda=lam).rl_update(state, batch, key)[1]["actor_loss"])
    each = [algo.rl_update(state, batch, key)[1]["actor_loss"] for algo in (
        make_algorithm(make_config("awac", "hopper", hidden=(8, 8), awac_lambda=lam), 3, 2, 0) for lam in (0.1, 1.0))]
    np.testing.assert_allclose(swept(jnp.array([0.1, 1.0])), each, rtol=1e-5)
    assert not np.isclose(each[0], each[1])


def test_pretraining_is_gaussian_bc_and_both_critics_on_the_returns():
    cfg = make_config("awac", "hopper", hidden=(8, 8), pretrain="actor+critic", pretrain_updates=100)
    assert [(p.name, p.steps) for p in cfg.phases(300)] == [("pretrain", 100), ("offline_rl", 200)]
    assert [p.name for p in make_config("awac", "hopper", pretrain="none").phases(300)] == ["offline_rl"]
    algo = make_algorithm(cfg, 3, 2, 0)
    state, batch = algo.init(jax.random.PRNGKey(1)), _batch()
    new, metrics = algo.phases(300)[0].update(state, jax.tree.map(lambda x: x[None], batch), jax.random.PRNGKey(2))
    nll = -gaussian_log_prob(*algo.actor.apply(state.actor.params, batch["observations"]), batch["actions"])
    np.testing.assert_allclose(metrics["bc_loss"], jnp.mean(nll), rtol=1e-6)  # every row weighs 1
    q = algo.critic.apply(state.critic.params, batch["observations"], batch["actions"])
    np.testing.assert_allclose(metrics["critic_loss"], L.mc_critic_loss(q, batch["returns"]), rtol=1e-6)
    moved = lambda a, b: any(not np.allclose(x, y) for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)))  # noqa
    assert moved(new.actor.params, state.actor.params) and moved(new.critic.target, state.critic.target)


def test_acts_with_the_clipped_mean_and_explores_with_a_clipped_sample():
    algo = make_algorithm(make_config("awac", "hopper", hidden=(8, 8)), 3, 2, 0)
    state = algo.init(jax.random.PRNGKey(1))
    params = {"params": state.actor.params["params"] | {"log_std": jnp.array([0.5, 0.5])}}
    state = state.replace(actor=state.actor.replace(params=params))
    obs = 30.0 * jax.random.normal(jax.random.PRNGKey(3), (64, 3))  # far out: the unsquashed mean leaves [-1, 1]
    mean, _ = algo.actor.apply(state.actor.params, obs)
    assert float(jnp.max(jnp.abs(mean))) > 1
    np.testing.assert_array_equal(algo.act(state, obs), jnp.clip(mean, -1, 1))
    a, b = algo.explore(state, obs, jax.random.PRNGKey(4)), algo.explore(state, obs, jax.random.PRNGKey(5))
    assert float(jnp.max(jnp.abs(a))) <= 1 and not np.allclose(a, b)


def test_its_online_rl_arm_is_awac_itself_from_scratch():
    """AWAC has no behaviour term to drop: its online-rl arm is the algorithm with no offline phase."""
    from experiments import finetune

    assert ALGOS["awac"].without_behaviour == {}
    args = finetune.make_parser().parse_args(["--algo", "awac", "--env", "hopper"])
    study = finetune.build(argparse.Namespace(**vars(args), typed=frozenset()))
    arms = {v.label: study.config(v.label) for v in study.variants}
    assert set(arms) == {"pretrained", "scratch", "pretrain-only", "online-rl"}
    assert (arms["online-rl"].offline_updates, arms["online-rl"].pretrain) == (0, "none")
    assert arms["online-rl"].awac_lambda == arms["scratch"].awac_lambda == 0.3333
    assert finetune.samples(arms["scratch"], "hopper")  # a sample explores: --explore-noise is refused


def test_pretrained_awac_runs_through_the_runner(tmp_path, tiny_dataset):
    from offrl_jax.run.results import read_curves
    from offrl_jax.run.runner import run_study
    from offrl_jax.run.study import Study, Variant

    study = Study(name="t", dataset="synthetic", env="hopper", seeds=(0,), updates=400, eval_every=200,
                  eval_episodes=1, batch_size=32,
                  variants=(Variant.of("pretrained", "awac", pretrain_updates=200, hidden=(16, 16)),))
    run_study(study, tmp_path, tiny_dataset, progress=False)
    rows = read_curves(tmp_path / "curves.csv")
    assert [(r["update"], r["phase"]) for r in rows] == [(200, "pretrain"), (400, "offline_rl")]


def test_adroit_door_offers_calql_and_awac_beyond_the_papers_eight():
    """The door study keeps Table 2's eight variants by default; Cal-QL and AWAC, with and without pre-training, on
    request, the pre-trained ones as long as the paper's door pre-training (AWAC has no door value of its own)."""
    from experiments import adroit_door

    parse = adroit_door.make_parser().parse_args
    assert [v.label for v in adroit_door.build(parse([])).variants] == adroit_door.PAPER_VARIANTS
    assert len(adroit_door.PAPER_VARIANTS) == 8
    study = adroit_door.build(parse(["--variants", "Cal-QL", "pre-trained Cal-QL", "AWAC", "pre-trained AWAC"]))
    configs = {v.label: study.config(v.label) for v in study.variants}
    assert {label: (c.pretrain, c.pretrain_updates if c.pretrain != "none" else None) for label, c in configs.items()} \
        == {"Cal-QL": ("none", None), "pre-trained Cal-QL": ("actor+critic", 20_000),
            "AWAC": ("none", None), "pre-trained AWAC": ("actor+critic", 20_000)}
    assert configs["AWAC"].awac_lambda == 0.1 and configs["Cal-QL"].calibration
