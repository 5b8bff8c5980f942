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
    # action tanh(1) (u = 1): per dim -0.5 - 0.5 ln(2 pi) - ln(1 - tanh(1)^2) = -0.5 - 0.5 ln(2 pi) + 2 ln cosh(1)
    lp = tanh_gaussian_log_prob(jnp.zeros((1, 2)), jnp.zeros((1, 2)), jnp.full((1, 2), np.tanh(1.0)))
    np.testing.assert_allclose(lp, [2 * (-0.5 - 0.5 * np.log(2 * np.pi) + 2 * np.log(np.cosh(1.0)))], rtol=1e-5)
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


def test_layer_norm_without_affine_has_no_scale_or_bias_and_normalises():
    """layer_norm_affine=False is the authors' nn.LayerNorm(elementwise_affine=False): no parameters, and the
    pre-activations of each row have mean 0 and variance 1 (flax eps 1e-6)."""
    from offrl_jax.nets import MLP, Arch

    x = jax.random.normal(jax.random.PRNGKey(0), (4, 3)) * 5.0 + 2.0
    mlp = MLP((6,), 1, layer_norm=True, arch=Arch(layer_norm_affine=False))
    params = mlp.init(jax.random.PRNGKey(1), x)
    assert "LayerNorm_0" not in params["params"]  # nothing to learn
    h = x @ params["params"]["Dense_0"]["kernel"] + params["params"]["Dense_0"]["bias"]
    normed = (h - h.mean(-1, keepdims=True)) / jnp.sqrt(h.var(-1, keepdims=True) + 1e-6)
    want = jax.nn.relu(normed) @ params["params"]["Dense_1"]["kernel"] + params["params"]["Dense_1"]["bias"]
    np.testing.assert_allclose(mlp.apply(params, x), want, rtol=1e-5, atol=1e-6)
    ens = CriticEnsemble(num=2, hidden=(8, 8), arch=Arch(layer_norm_affine=False))
    leaves = jax.tree.leaves(ens.init(jax.random.PRNGKey(2), x, jnp.ones((4, 2))))
    assert len(leaves) == 2 * 3  # kernel + bias of 3 Dense layers, stacked over members; no LayerNorm leaves


def test_an_ensemble_member_applied_alone_equals_its_row_of_the_ensemble():
    """CriticEnsemble.member(i): a plain Critic with member i's parameters (what TD3+BC's actor loss applies)."""
    ensemble = CriticEnsemble(3, (32, 32))
    obs, act = jax.random.normal(jax.random.PRNGKey(1), (5, 11)), jax.random.normal(jax.random.PRNGKey(2), (5, 3))
    variables = ensemble.init(jax.random.PRNGKey(0), obs, act)
    for i in range(3):
        critic, member = ensemble.member(variables, i)
        np.testing.assert_array_equal(critic.apply(member, obs, act), ensemble.apply(variables, obs, act)[i])
