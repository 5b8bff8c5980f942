import jax
import jax.numpy as jnp
import numpy as np

from offrl_jax.nets import (
    CriticEnsemble,
    DeterministicActor,
    TanhGaussianActor,
    sample_tanh_gaussian,
    tanh_gaussian_log_prob,
)


def test_shapes_and_layer_norm_flag():
    obs, act = jnp.ones((5, 4)), jnp.ones((5, 2))
    actor = DeterministicActor(2, (8, 8), layer_norm=True)
    params = actor.init(jax.random.PRNGKey(0), obs)
    assert actor.apply(params, obs).shape == (5, 2)
    assert "LayerNorm_0" in params["params"]["MLP_0"] and "LayerNorm_1" in params["params"]["MLP_0"]
    assert "LayerNorm_0" not in DeterministicActor(2, (8,), layer_norm=False).init(jax.random.PRNGKey(0), obs)[
        "params"]["MLP_0"]
    ens = CriticEnsemble(num=3, hidden=(8, 8))
    q_params = ens.init(jax.random.PRNGKey(1), obs, act)
    q = ens.apply(q_params, obs, act)
    assert q.shape == (3, 5)
    assert not np.allclose(q[0], q[1])  # independent members
    # per-member actions use the same parameters
    per_member = CriticEnsemble(num=3, hidden=(8, 8), per_member_actions=True)
    np.testing.assert_allclose(per_member.apply(q_params, obs, jnp.broadcast_to(act, (3, 5, 2))), q, rtol=1e-6)


def test_tanh_gaussian_log_prob_hand_value_and_consistency():
    # mean 0, log_std 0, action 0: per dim -0.5 ln(2 pi) (tanh Jacobian is 1 at 0)
    lp = tanh_gaussian_log_prob(jnp.zeros((1, 2)), jnp.zeros((1, 2)), jnp.zeros((1, 2)))
    np.testing.assert_allclose(lp, [-np.log(2 * np.pi)], rtol=1e-6)
    mean, log_std = jnp.array([[0.3, -0.2]]), jnp.array([[-1.0, 0.5]])
    a, lp = sample_tanh_gaussian(jax.random.PRNGKey(0), mean, log_std)
    np.testing.assert_allclose(tanh_gaussian_log_prob(mean, log_std, a), lp, rtol=1e-4)
    # |a| = 1 is clipped before atanh: finite
    assert np.isfinite(tanh_gaussian_log_prob(mean, log_std, jnp.ones((1, 2)))).all()


def test_gaussian_actor_log_std_clipped():
    actor = TanhGaussianActor(2, (8,))
    params = actor.init(jax.random.PRNGKey(0), jnp.ones((1, 3)))
    _, log_std = actor.apply(params, 1e6 * jnp.ones((1, 3)))
    assert float(log_std.min()) >= -5.0 and float(log_std.max()) <= 2.0
