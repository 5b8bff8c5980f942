"""Every loss against a value computed by hand (the arithmetic is in the comments)."""
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from offrl_jax import losses as L

A = np.testing.assert_allclose


def test_bc_loss():
    # mean((0-1)^2, (1-1)^2) = 0.5
    A(L.bc_loss(jnp.array([[0.0, 1.0]]), jnp.array([[1.0, 1.0]])), 0.5)


def test_soft_bc_loss():
    # mean(2*1 - 0.5, 2*2 - 1) = mean(1.5, 3) = 2.25
    A(L.soft_bc_loss(jnp.array([1.0, 2.0]), jnp.array([0.5, 1.0]), jnp.array(2.0)), 2.25)


def test_mc_critic_loss_sums_critics_of_batch_means():
    # critic 0: mean(0, 1) = 0.5; critic 1: mean(4, 9) = 6.5; sum = 7
    A(L.mc_critic_loss(jnp.array([[1.0, 2.0], [3.0, 4.0]]), jnp.array([1.0, 1.0])), 7.0)


def test_td_target_bootstraps_unless_terminal():
    # [1 + 0.9*10, 1 + 0] = [10, 1]
    A(L.td_target(jnp.array([1.0, 1.0]), jnp.array([0.0, 1.0]), jnp.array([10.0, 10.0]), 0.9), [10.0, 1.0])


def test_clipped_double_q_and_soft_value():
    q = jnp.array([[1.0, 5.0], [3.0, 2.0]])
    A(L.clipped_double_q(q), [1.0, 2.0])
    # min - alpha*logp = [1 - 2*0.5, 2 - 2*(-1)] = [0, 4]
    A(L.soft_value(q, jnp.array([0.5, -1.0]), 2.0), [0.0, 4.0])


def test_target_policy_smoothing_bounds():
    a = jnp.full((1000, 3), 0.9)
    smoothed = L.target_policy_smoothing(jax.random.PRNGKey(0), a, noise=0.2, clip=0.5)
    assert float(jnp.max(smoothed)) <= 1.0 and float(jnp.min(smoothed)) >= 0.4 - 1e-6
    A(L.target_policy_smoothing(jax.random.PRNGKey(0), a, noise=0.0), a)


def test_mix_targets_and_q_transformer():
    # 0.9*10 + 0.1*0 = 9
    A(L.mix_targets(jnp.array([10.0]), jnp.array([0.0]), 0.1), [9.0])
    A(L.q_transformer_target(jnp.array([1.0, 5.0]), jnp.array([3.0, 2.0])), [3.0, 5.0])


def test_critic_regression_loss_stops_target_gradient():
    grad = jax.grad(lambda t: L.critic_regression_loss(jnp.array([[0.0]]), t))(jnp.array([1.0]))
    A(grad, [0.0])


def test_normalized_never_flips_the_gradient():
    # x / sg|x| at x = -2: value -1, gradient 1/|x| = +0.5 (the authors' x / sg(x) would give -0.5)
    value, grad = jax.value_and_grad(L.normalized)(jnp.array(-2.0))
    A(value, -1.0, rtol=1e-6)
    A(grad, 0.5, rtol=1e-6)
    assert grad > 0


def test_balance_losses_value_and_gradient_signs():
    # a = 2, b = -4, c = 3: value 1 + 3*(-1) = -2; d/da = 1/2, d/db = 3/4 (both positive: minimising still lowers b)
    value, grads = jax.value_and_grad(L.balance_losses, argnums=(0, 1))(jnp.array(2.0), jnp.array(-4.0), 3.0)
    A(value, -2.0, rtol=1e-6)
    A(grads, (0.5, 0.75), rtol=1e-6)


def test_mix_losses():
    # lam = 0.25, L_MC = 4, L_TD = 2: value 0.75 + 0.25 = 1; d/dL_MC = 0.75/4, d/dL_TD = 0.25/2
    value, grads = jax.value_and_grad(L.mix_losses, argnums=(0, 1))(jnp.array(4.0), jnp.array(2.0), 0.25)
    A(value, 1.0, rtol=1e-6)
    A(grads, (0.1875, 0.125), rtol=1e-6)


def test_pretrain_critic_loss_modes():
    # q = [[1, 3], [2, 2]] (2 critics, batch 2), R = [1, 1], y = [3, 1]
    q, mc, td = jnp.array([[1.0, 3.0], [2.0, 2.0]]), jnp.array([1.0, 1.0]), jnp.array([3.0, 1.0])

    def never():
        raise AssertionError("lam = 0 must not compute the TD target")

    # lam = 0: MC error per critic (0 + 4) / 2 = 2 and (1 + 1) / 2 = 1 -> sum 3, mean 1.5
    A(L.pretrain_critic_loss(q, mc, never, 0.0), 3.0)
    A(L.pretrain_critic_loss(q, mc, never, 0.0, per_critic="mean"), 1.5)
    # target mode, lam = 0.5: target [2, 1]; errors (1 + 4) / 2 = 2.5 and (0 + 1) / 2 = 0.5 -> sum 3, mean 1.5
    A(L.pretrain_critic_loss(q, mc, lambda: td, 0.5, "target"), 3.0)
    A(L.pretrain_critic_loss(q, mc, lambda: td, 0.5, "target", per_critic="mean"), 1.5)
    # loss mode: normalised, so 0.5 * 1 + 0.5 * 1 = 1 whatever the reduction over critics
    A(L.pretrain_critic_loss(q, mc, lambda: td, 0.5), 1.0)
    A(L.pretrain_critic_loss(q, mc, lambda: td, 0.5, per_critic="mean"), 1.0)
    # ...so its gradient is what it says: L_MC = 3, L_TD = (4 + 4) / 2 + (1 + 1) / 2 = 5, d/dq of a batch-mean square
    # over B = 2 is (q - target); 0.5 / 3 * (q - R) + 0.5 / 5 * (q - y)
    expected = [[0 / 6 - 2 / 10, 2 / 6 + 2 / 10], [1 / 6 - 1 / 10, 1 / 6 + 1 / 10]]
    for per_critic in ("sum", "mean"):
        grad = jax.grad(L.pretrain_critic_loss)(q, mc, lambda: td, 0.5, per_critic=per_critic)
        A(grad, expected, rtol=1e-5)


def test_td3bc_actor_loss():
    # q = [2, 4]: lmbda = 2.5 / mean|q| = 2.5/3; -lmbda * 3 = -2.5; MSE([[0],[0]], [[1],[0]]) = 0.5 -> -2.0
    loss = L.td3bc_actor_loss(jnp.array([2.0, 4.0]), jnp.zeros((2, 1)), jnp.array([[1.0], [0.0]]), 2.5)
    A(loss, -2.0, rtol=1e-6)
    # lmbda is a constant: d loss / d q = -lmbda / B = -(2.5/3)/2
    grad = jax.grad(lambda q: L.td3bc_actor_loss(q, jnp.zeros((2, 1)), jnp.zeros((2, 1)), 2.5))(jnp.array([2.0, 4.0]))
    A(grad, [-2.5 / 6, -2.5 / 6], rtol=1e-6)
    # bc_weight scales the MSE alone: 0.5 x 0.5 = 0.25 -> -2.25; 0 leaves TD3's -lmbda mean Q = -2.5
    A(L.td3bc_actor_loss(jnp.array([2.0, 4.0]), jnp.zeros((2, 1)), jnp.array([[1.0], [0.0]]), 2.5, bc_weight=0.5),
      -2.25, rtol=1e-6)
    A(L.td3bc_actor_loss(jnp.array([2.0, 4.0]), jnp.zeros((2, 1)), jnp.array([[1.0], [0.0]]), 2.5, bc_weight=0.0),
      -2.5, rtol=1e-6)


def test_sac_actor_and_temperature_losses():
    # min_i Q = [1, 2]; mean(2*0.5 - 1, 2*(-1) - 2) = mean(0, -4) = -2
    A(L.sac_actor_loss(jnp.array([[1.0, 5.0], [3.0, 2.0]]), jnp.array([0.5, -1.0]), 2.0), -2.0)
    # -mean(0.5 * ([1, 2] - 1)) = -0.25; d/dlog_alpha = -mean([0, 1]) = -0.5
    value, grad = jax.value_and_grad(L.temperature_loss)(jnp.array(0.5), jnp.array([1.0, 2.0]), -1.0)
    A(value, -0.25)
    A(grad, -0.5)


@pytest.mark.parametrize(
    "grads, expected",
    [
        ([[[1.0, 0.0]], [[0.0, 2.0]]], 0.0),  # orthogonal: cos 0
        ([[[1.0, 0.0]], [[3.0, 0.0]]], 2.0),  # aligned, N = 2: cos(1,2) + cos(2,1) = 2, / (N - 1) = 2
        ([[[1.0, 0.0]], [[-1.0, 0.0]]], -2.0),  # opposite: (-1 - 1) / 1
        ([[[1.0, 0.0]], [[2.0, 0.0]], [[5.0, 0.0]]], 3.0),  # N = 3 aligned: 6 off-diagonal ones / 2
    ],
)
def test_edac_diversity_loss(grads, expected):
    A(L.edac_diversity_loss(jnp.array(grads)), expected, rtol=1e-6)


def test_edac_diversity_gradient_is_finite_at_a_zero_action_gradient():
    grads = jnp.array([[[0.0, 0.0]], [[1.0, 0.0]]])  # member 0's dQ/da is exactly zero
    d = jax.grad(L.edac_diversity_loss)(grads)
    assert np.all(np.isfinite(d))
    A(L.edac_diversity_loss(grads), 0.0, atol=1e-12)


def test_cql_uniform_penalty():
    # logsumexp(0, ln 3) = ln 4; q_data = ln 4 - 1 -> penalty 1 (one critic, one state)
    q_u = jnp.array([[[0.0, np.log(3.0)]]])
    A(L.cql_uniform_penalty(q_u, jnp.array([[np.log(4.0) - 1.0]])), 1.0, rtol=1e-6)
    # temperature 2: 2 * logsumexp(0, ln 9 / 2) = 2 ln(1 + 3) = 2 ln 4; q_data = 0
    q_u = jnp.array([[[0.0, np.log(9.0)]]])
    A(L.cql_uniform_penalty(q_u, jnp.zeros((1, 1)), temperature=2.0), 2 * np.log(4.0), rtol=1e-6)
    # two critics sum (a mean would give 1.5): (0 + 1) + (0 + 2)
    A(L.cql_uniform_penalty(jnp.zeros((2, 1, 1)), jnp.array([[-1.0], [-2.0]])), 3.0, rtol=1e-6)
    # the batch is averaged (a sum would give 2): mean(0 - 0, 0 + 2)
    A(L.cql_uniform_penalty(jnp.zeros((1, 2, 1)), jnp.array([[0.0, -2.0]])), 1.0, rtol=1e-6)


def test_cql_importance_penalty():
    # A = 1, all Q and log-probs 0: logsumexp(-ln 0.5, 0, 0) = ln(2 + 1 + 1) = ln 4
    z3, z2 = jnp.zeros((1, 1, 1)), jnp.zeros((1, 1))
    A(L.cql_importance_penalty(z3, z3, z2, z3, z2, z2, act_dim=1), np.log(4.0), rtol=1e-6)
    # A = 2: -2 ln 0.5 = ln 4 -> ln(4 + 1 + 1) = ln 6
    A(L.cql_importance_penalty(z3, z3, z2, z3, z2, z2, act_dim=2), np.log(6.0), rtol=1e-6)
    # signs and the sum over critics: log pi = -ln 3 adds ln 3 (exp: 3), random adds ln 2 (exp: 2), next-policy
    # exp 0 = 1 -> ln 6 per critic; q_data 1 and 2 -> 2 ln 6 - 3 (a flipped log-prob sign gives 2 ln(10/3) - 3)
    lp = jnp.full((1, 1), -np.log(3.0))
    q_data = jnp.array([[1.0], [2.0]])
    z3 = jnp.zeros((2, 1, 1))
    A(L.cql_importance_penalty(z3, z3, lp, z3, z2, q_data, act_dim=1), 2 * np.log(6.0) - 3, rtol=1e-6)
    # the policy's log-probs are constants here (CORL detaches them)
    grad = jax.grad(lambda lp: L.cql_importance_penalty(z3, z3, lp, z3, z2, q_data, act_dim=1))(lp)
    A(grad, [[0.0]])


def test_calibrated_q_bounds_policy_values_by_the_state_return():
    # critic 0 / 1, state 0 (bound 1) / state 1 (bound -5), two policy actions each
    q = jnp.array([[[0.0, 2.0], [-6.0, -4.0]], [[1.5, -1.0], [3.0, -5.5]]])
    bound = jnp.array([1.0, -5.0])
    A(L.calibrated_q(q, bound), [[[1.0, 2.0], [-5.0, -4.0]], [[1.5, 1.0], [3.0, -5.0]]])
    # the push-down's gradient reaches Q only where Q is above its bound
    grad = jax.grad(lambda q: jnp.sum(L.calibrated_q(q, bound)))(q)
    A(grad, [[[0.0, 1.0], [0.0, 1.0]], [[1.0, 0.0], [1.0, 0.0]]])


def test_edac_diversity_is_a_batch_mean():
    # state 0: aligned (2 / (N - 1) = 2), state 1: orthogonal (0) -> 1 (a batch sum would give 2)
    A(L.edac_diversity_loss(jnp.array([[[1.0, 0.0], [1.0, 0.0]], [[3.0, 0.0], [0.0, 2.0]]])), 1.0, rtol=1e-6)


def test_target_policy_smoothing_noise_and_clip():
    a = jnp.zeros((10_000, 1))
    assert float(jnp.std(L.target_policy_smoothing(jax.random.PRNGKey(0), a, noise=0.2, clip=10.0))) == (
        pytest.approx(0.2, abs=0.01))  # noise * N(0, 1), unclipped
    smoothed = L.target_policy_smoothing(jax.random.PRNGKey(0), a, noise=1.0, clip=0.3)
    A([smoothed.min(), smoothed.max()], [-0.3, 0.3])  # the noise is clipped to +-clip
    A(L.target_policy_smoothing(jax.random.PRNGKey(0), jnp.full((100, 1), 0.9), 1.0, 0.5).max(), 1.0)  # then to [-1, 1]


def test_temperature_is_a_constant_in_the_actor_losses():
    lp = jnp.array([0.5, -1.0])
    A(jax.grad(lambda a: L.soft_bc_loss(lp, lp, a))(jnp.array(2.0)), 0.0)
    A(jax.grad(lambda a: L.sac_actor_loss(jnp.ones((2, 2)), lp, a))(jnp.array(2.0)), 0.0)


def test_action_penalty_sums_over_action_dims():
    # rows: (0-1)^2 + (2-0)^2 = 5;  (1-1)^2 + (-1-1)^2 = 4
    A(L.action_penalty(jnp.array([[0.0, 2.0], [1.0, -1.0]]), jnp.array([[1.0, 0.0], [1.0, 1.0]])), [5.0, 4.0])


def test_rebrac_next_value():
    # critic 0: (1, 0), critic 1: (3, 2) -> min (1, 0); penalties 5 and 4 (above); beta 0.1 -> (1 - 0.5, 0 - 0.4)
    next_q = jnp.array([[1.0, 0.0], [3.0, 2.0]])  # (N, B)
    value = L.rebrac_next_value(next_q, jnp.array([[0.0, 2.0], [1.0, -1.0]]), jnp.array([[1.0, 0.0], [1.0, 1.0]]),
                                0.1)
    A(value, [0.5, -0.4], rtol=1e-6)


def test_rebrac_actor_loss_value_and_gradient():
    q = jnp.array([2.0, -4.0])  # mean|Q| = 3
    pi, a = jnp.array([[0.0, 2.0], [1.0, -1.0]]), jnp.array([[1.0, 0.0], [1.0, 1.0]])  # penalties 5, 4
    # mean(0.1 * (5, 4) - (2, -4) / 3) = mean(0.5 - 2/3, 0.4 + 4/3) = (0.5 + 0.4 + 2/3) / 2
    A(L.rebrac_actor_loss(q, pi, a, 0.1), (0.9 + 2 / 3) / 2, rtol=1e-6)
    A(L.rebrac_actor_loss(q, pi, a, 0.1, normalize_q=False), (0.9 + 2.0) / 2, rtol=1e-6)  # lmbda = 1
    # the scale is a constant: d/dq = -(1/3) / B per row, not also through mean|Q|
    A(jax.grad(lambda x: L.rebrac_actor_loss(x, pi, a, 0.1))(q), [-1 / 6, -1 / 6], rtol=1e-6)
    # d/dpi = beta * 2 (pi - a) / B
    A(jax.grad(lambda p: L.rebrac_actor_loss(q, p, a, 0.1))(pi), 0.1 * 2 * (pi - a) / 2, rtol=1e-6)


def test_expectile_loss_is_minimised_at_the_expectile():
    # targets 1 and 3: the 0.7-expectile v solves 0.7 (3 - v) = 0.3 (v - 1), v = 2.4; the 0.5-expectile is the mean
    targets = jnp.array([1.0, 3.0])
    grad = lambda v, e: jax.grad(lambda x: L.expectile_loss(targets - x, e))(v)  # noqa: E731
    A(grad(2.4, 0.7), 0.0, atol=1e-6)
    A(grad(2.0, 0.5), 0.0, atol=1e-6)
    # at v = 2, expectile 0.7: mean(0.3 * 1^2, 0.7 * 1^2) = 0.5; expectile 0.5 is half the MSE
    A(L.expectile_loss(targets - 2.0, 0.7), 0.5, rtol=1e-6)
    A(L.expectile_loss(targets - 2.0, 0.5), 0.5 * jnp.mean((targets - 2.0) ** 2), rtol=1e-6)


def test_awr_actor_loss_weights_and_clip():
    # weights exp(2 * (0, 1, 10)) clipped at 100: (1, e^2, 100); nll (1, 2, 3) -> mean(1 + 2 e^2 + 300)
    nll, adv = jnp.array([1.0, 2.0, 3.0]), jnp.array([0.0, 1.0, 10.0])
    A(L.awr_actor_loss(nll, adv, 2.0), (1 + 2 * np.exp(2.0) + 300) / 3, rtol=1e-6)
    A(L.awr_actor_loss(nll, adv, 0.0), 2.0, rtol=1e-6)  # beta = 0: behaviour cloning, every row weighs 1
    A(jax.grad(lambda a: L.awr_actor_loss(nll, a, 2.0))(adv), 0.0)  # the advantage is a constant


def test_awac_advantage_is_min_q_of_the_data_action_less_min_q_of_the_policy_action():
    # q_data rows (1, 4) and (3, 2): mins (1, 2); q_pi rows (2, 0) and (5, 1): mins (2, 0); A = (1 - 2, 2 - 0) = (-1, 2)
    q_data, q_pi = jnp.array([[1.0, 4.0], [3.0, 2.0]]), jnp.array([[2.0, 0.0], [5.0, 1.0]])
    A(L.awac_advantage(q_data, q_pi), [-1.0, 2.0])
    # AWAC's weights exp(A / lambda) at lambda 0.5: (e^-2, e^4), neither clipped at 100
    A(L.awr_actor_loss(jnp.ones(2), L.awac_advantage(q_data, q_pi), 1 / 0.5), (np.exp(-2.0) + np.exp(4.0)) / 2,
      rtol=1e-6)
    A(jax.grad(lambda q: jnp.sum(L.awac_advantage(q, q_pi)))(q_data), 0.0)  # a constant of the actor loss


def test_gaussian_log_prob():
    from offrl_jax.nets import gaussian_log_prob

    # N(1; 0, e^0) in each of 2 dims: 2 * (-0.5 - 0.5 log 2 pi)
    A(gaussian_log_prob(jnp.zeros((1, 2)), jnp.zeros(2), jnp.ones((1, 2))), [-1.0 - np.log(2 * np.pi)], rtol=1e-6)


Z = jnp.zeros


@pytest.mark.parametrize("argument, call", [
    ("returns", lambda: L.mc_critic_loss(Z((2, 5)), Z((5, 1)))),  # returns (B, 1) would broadcast to (2, 5, 5)
    ("q", lambda: L.td3bc_actor_loss(Z((2, 5)), Z((5, 3)), Z((5, 3)), 2.5)),  # all critics' Q
    ("actions", lambda: L.bc_loss(Z((5, 3)), Z((5, 1)))),
    ("advantage", lambda: L.awr_actor_loss(Z(5), Z((5, 1)), 3.0)),
    ("q_pi", lambda: L.awac_advantage(Z((2, 5)), Z((2, 5, 1)))),
    ("pred_actions", lambda: L.rebrac_actor_loss(Z(4), Z((5, 3)), Z((5, 3)), 0.1)),
    ("log_prob_data", lambda: L.soft_bc_loss(Z(5), Z((5, 1)), 1.0)),
    ("next_value", lambda: L.td_target(Z(5), Z(5), Z((5, 1)), 0.99)),  # V(s') (B, 1): a (B, B) target
    ("terminal", lambda: L.td_target(Z(5), Z(4), Z(5), 0.99)),
    ("next_q", lambda: L.clipped_double_q(Z((2, 5, 1)))),
    ("next_log_prob", lambda: L.soft_value(Z((2, 5)), Z((5, 1)), 0.1)),
    ("alpha", lambda: L.soft_value(Z((2, 5)), Z(5), Z(5))),
    ("td", lambda: L.mix_targets(Z(5), Z((5, 1)), 0.5)),
    ("mc_return", lambda: L.q_transformer_target(Z((5, 1)), Z(5))),
    ("target", lambda: L.critic_regression_loss(Z((2, 5)), Z((5, 1)))),
    ("mc_return", lambda: L.pretrain_critic_loss(Z((2, 5)), Z((5, 1)), lambda: Z(5), 0.5)),
    ("actions", lambda: L.action_penalty(Z((5, 3)), Z((5, 1)))),
    ("next_actions", lambda: L.rebrac_next_value(Z((2, 5)), Z((5, 3)), Z((5, 1)), 0.1)),
    ("diff", lambda: L.expectile_loss(Z((5, 1)), 0.7)),
    ("log_prob", lambda: L.sac_actor_loss(Z((2, 5)), Z((5, 1)), 1.0)),
    ("log_alpha", lambda: L.temperature_loss(Z(5), Z(5), -3.0)),  # one log alpha per row
    ("action_grads", lambda: L.edac_diversity_loss(Z((2, 5)))),
    ("q_data", lambda: L.cql_uniform_penalty(Z((2, 5, 10)), Z((2, 5, 1)))),
    ("log_prob_next_policy", lambda: L.cql_importance_penalty(Z((2, 5, 10)), Z((2, 5, 10)), Z((5, 10)),
                                                              Z((2, 5, 10)), Z((5, 1)), Z((2, 5)), 3)),
    ("lower_bound", lambda: L.calibrated_q(Z((2, 5, 10)), Z((5, 1)))),
], ids=lambda a: a if isinstance(a, str) else "")
def test_a_wrong_shape_fails_when_traced_naming_the_argument(argument, call):
    named = rf"\[{argument}: \("  # chex's message ends with the argument's documented shape, e.g. [returns: (B,)]
    with pytest.raises(AssertionError, match=named):
        call()
    with pytest.raises(AssertionError, match=named):
        jax.jit(lambda: call())()
