"""Every loss and target as a small pure function of arrays (jit-able, no networks, no hidden state).

Shapes: B = batch, A = action dim, N = ensemble size, M = sampled actions per state.  Q-values of an ensemble are
(N, B).  Each loss returns a scalar; targets return (B,).  `sg` = `jax.lax.stop_gradient`.  The documented shapes are
asserted (`assert_shapes`, chex) where a wrong one would broadcast silently: they fail when the function is traced,
naming the argument.
"""
from __future__ import annotations

from collections.abc import Callable

import chex
import jax
import jax.numpy as jnp

sg = jax.lax.stop_gradient


def assert_shapes(**arrays: tuple[jax.Array | float, str]) -> None:
    """Assert the shapes a docstring gives: `q=(q, "NB")` is q: (N, B), `alpha=(alpha, "")` a scalar, and a letter
    has one size across the arguments.  Shapes are static, so this runs when the function is traced; chex's
    AssertionError names the argument and its documented shape."""
    sizes: dict[str, tuple[str, int]] = {}
    for name, (x, dims) in arrays.items():
        documented = f"{name}: ({', '.join(dims)}{',' if len(dims) == 1 else ''})"
        chex.assert_rank(x, len(dims), custom_message=documented)
        for axis, letter in enumerate(dims):
            first, size = sizes.setdefault(letter, (name, x.shape[axis]))
            chex.assert_axis_dimension(x, axis, size, custom_message=f"{documented}, {letter} as in {first}")


# --------------------------------------------------------------------------------------------- supervised losses


def bc_loss(pred_actions: jax.Array, actions: jax.Array) -> jax.Array:
    """Behaviour cloning, MSE over every element.  pred_actions, actions: (B, A) -> ()."""
    assert_shapes(pred_actions=(pred_actions, "BA"), actions=(actions, "BA"))
    return jnp.mean((pred_actions - actions) ** 2)


def soft_bc_loss(log_prob_sampled: jax.Array, log_prob_data: jax.Array, alpha: jax.Array) -> jax.Array:
    """Soft BC (eq. 9): E[alpha log pi(a~|s) - log pi(a|s)].  log probs: (B,), alpha: () -> ().

    `log_prob_data` is log pi of the dataset action (clipped to +-(1-1e-6) before atanh by the caller's
    `tanh_gaussian_log_prob`); alpha is treated as a constant here (its own loss is `temperature_loss`).
    """
    assert_shapes(log_prob_sampled=(log_prob_sampled, "B"), log_prob_data=(log_prob_data, "B"), alpha=(alpha, ""))
    return jnp.mean(sg(alpha) * log_prob_sampled - log_prob_data)


def mc_critic_loss(q: jax.Array, returns: jax.Array) -> jax.Array:
    """Monte-Carlo value error: sum over critics of the batch-mean squared error.  q: (N, B), returns: (B,) -> ()."""
    assert_shapes(q=(q, "NB"), returns=(returns, "B"))
    return jnp.sum(jnp.mean((q - returns[None]) ** 2, axis=-1))


# ----------------------------------------------------------------------------------------------------- TD targets


def td_target(reward: jax.Array, terminal: jax.Array, next_value: jax.Array, gamma: float) -> jax.Array:
    """One-step target r + gamma (1 - terminal) V(s').  (B,) each -> (B,).

    `terminal` is 1.0 where the target stops bootstrapping, as the algorithm's `timeouts` says
    (`offrl_jax.algos.common.done_flags`): by default the terminal flag alone, since a time-out is not the end of the
    task and its successor's value is bootstrapped through; terminal-or-timeout under timeouts "stop" (the authors'
    code, their `authors` preset).
    """
    assert_shapes(reward=(reward, "B"), terminal=(terminal, "B"), next_value=(next_value, "B"))
    return reward + gamma * (1.0 - terminal) * next_value


def clipped_double_q(next_q: jax.Array) -> jax.Array:
    """TD3 / SAC-N pessimism: min over the ensemble.  (N, B) -> (B,)."""
    assert_shapes(next_q=(next_q, "NB"))
    return jnp.min(next_q, axis=0)


def target_policy_smoothing(key: jax.Array, action: jax.Array, noise: float = 0.2, clip: float = 0.5) -> jax.Array:
    """TD3's smoothed target action clip(a + clip(noise * eps, -clip, clip), -1, 1).  (B, A) -> (B, A)."""
    eps = jnp.clip(noise * jax.random.normal(key, action.shape), -clip, clip)
    return jnp.clip(action + eps, -1.0, 1.0)


def soft_value(next_q: jax.Array, next_log_prob: jax.Array, alpha: jax.Array) -> jax.Array:
    """SAC / EDAC soft value min_i Q_i(s', a') - alpha log pi(a'|s').  next_q (N, B), next_log_prob (B,) -> (B,)."""
    assert_shapes(next_q=(next_q, "NB"), next_log_prob=(next_log_prob, "B"), alpha=(alpha, ""))
    return clipped_double_q(next_q) - alpha * next_log_prob


def mix_targets(mc_return: jax.Array, td: jax.Array, lam: float) -> jax.Array:
    """Eq. 5 target mixing R~ = (1 - lam) R + lam (r + gamma Q').  (B,), (B,) -> (B,)."""
    assert_shapes(mc_return=(mc_return, "B"), td=(td, "B"))
    return (1.0 - lam) * mc_return + lam * td


def q_transformer_target(mc_return: jax.Array, td: jax.Array) -> jax.Array:
    """Q-Transformer / Wilcox et al. target max(MC, r + gamma Q') (Appendix F).  (B,), (B,) -> (B,)."""
    assert_shapes(mc_return=(mc_return, "B"), td=(td, "B"))
    return jnp.maximum(mc_return, td)


def critic_regression_loss(q: jax.Array, target: jax.Array) -> jax.Array:
    """TD (or any target) regression: sum over critics of the batch-mean squared error.  (N, B), (B,) -> ().

    The target is treated as a constant.  Same arithmetic as `mc_critic_loss`; kept separate by name for clarity.
    """
    assert_shapes(q=(q, "NB"), target=(target, "B"))
    return mc_critic_loss(q, sg(target))


# ------------------------------------------------------------------------------------------- loss normalisation


BALANCES = ("abs", "signed")  # x / sg|x| (ours), x / sg(x) (the authors' code)


def normalized(x: jax.Array, form: str = "abs", eps: float = 1e-8) -> jax.Array:
    """Unit-scale loss.  form "abs": x / (sg|x| + eps), value +-1, gradient grad(x)/|x|, never sign-flipped.
    form "signed": x / sg(x), the authors' code: value 1 and gradient grad(x)/x, which points the other way when
    x < 0 (a negative CQL penalty or SAC loss is then pushed back up, not further down).  () -> ()."""
    if form == "signed":
        return x / sg(x)
    return x / (sg(jnp.abs(x)) + eps)


def balance_losses(primary: jax.Array, auxiliary: jax.Array, weight: float, form: str = "abs") -> jax.Array:
    """Loss balancing of the hybrids (Appendix G.3): a / sg|a| + c * b / sg|b| (`form` "signed": sg(a), sg(b)).
    (), () -> ()."""
    return normalized(primary, form) + weight * normalized(auxiliary, form)


def mix_losses(mc_loss: jax.Array, td_loss: jax.Array, lam: float, form: str = "abs") -> jax.Array:
    """The authors' lambda mixing on normalised losses: (1-lam) L_MC/sg|L_MC| + lam L_TD/sg|L_TD|.  (), () -> ().
    Both losses are squared errors (>= 0), so `form` changes nothing but the epsilon."""
    return (1.0 - lam) * normalized(mc_loss, form) + lam * normalized(td_loss, form)


def pretrain_critic_loss(q: jax.Array, mc_return: jax.Array, td_fn: Callable[[], jax.Array], lam: float,
                         mode: str = "loss", per_critic: str = "sum", form: str = "abs") -> jax.Array:
    """Critic pre-training on Monte-Carlo returns, with a share lam of TD (eq. 5).  q: (N, B), mc_return: (B,) -> ().

    lam = 0: the MC error alone (`td_fn` is not called).  mode "target": regression on (1 - lam) R + lam y;
    mode "loss": `mix_losses` of the MC and TD errors (the authors').  `td_fn() -> (B,)` gives the TD target y.
    per_critic: "sum" (TD3+BC's twin critics) or "mean" (EDAC's ensemble, as the authors' `pretrain_soft_critic`)
    over the N critics; normalised losses ("loss" mode, lam > 0) are the same either way.
    """
    assert_shapes(q=(q, "NB"), mc_return=(mc_return, "B"))
    scale = 1.0 if per_critic == "sum" else 1.0 / q.shape[0]
    if lam == 0.0:
        return scale * mc_critic_loss(q, mc_return)
    if mode == "target":
        return scale * critic_regression_loss(q, mix_targets(mc_return, td_fn(), lam))
    return mix_losses(mc_critic_loss(q, mc_return), critic_regression_loss(q, td_fn()), lam, form)


def action_penalty(pred_actions: jax.Array, actions: jax.Array) -> jax.Array:
    """ReBRAC's behaviour penalty per row, ||a~ - a||^2 summed over the action dims.  (B, A), (B, A) -> (B,)."""
    assert_shapes(pred_actions=(pred_actions, "BA"), actions=(actions, "BA"))
    return jnp.sum((pred_actions - actions) ** 2, axis=-1)


def rebrac_next_value(next_q: jax.Array, next_pred_actions: jax.Array, next_actions: jax.Array,
                      beta: float) -> jax.Array:
    """ReBRAC's penalised next value min_i Q'_i(s', a~') - beta ||a~' - a'||^2, a~' the target policy's (smoothed)
    action, a' the dataset's next action.  next_q (N, B), actions (B, A) -> (B,)."""
    assert_shapes(next_q=(next_q, "NB"), next_pred_actions=(next_pred_actions, "BA"),
                  next_actions=(next_actions, "BA"))
    return clipped_double_q(next_q) - beta * action_penalty(next_pred_actions, next_actions)


def expectile_loss(diff: jax.Array, expectile: float) -> jax.Array:
    """IQL's asymmetric squared error mean(|expectile - 1(diff < 0)| diff^2), diff = target - prediction: its
    minimiser is the target's `expectile` (0.5: half the mean squared error, minimised by the mean).  (B,) -> ()."""
    assert_shapes(diff=(diff, "B"))
    weight = jnp.where(diff < 0, 1.0 - expectile, expectile)
    return jnp.mean(weight * diff ** 2)


# ---------------------------------------------------------------------------------------------------- actor losses


def td3bc_actor_loss(q: jax.Array, pred_actions: jax.Array, actions: jax.Array, alpha: float,
                     q_scale_eps: float = 1e-8, bc_weight: float = 1.0) -> jax.Array:
    """TD3+BC actor: -lmbda mean Q(s, pi(s)) + bc_weight MSE(pi(s), a), lmbda = alpha / (sg(mean |Q|) + q_scale_eps).

    q: (B,) (the first critic's value of the policy action), pred_actions, actions: (B, A) -> ().  CORL and the
    authors divide by mean|Q| alone (q_scale_eps = 0); bc_weight 0 is TD3's actor (with Q normalised).
    """
    assert_shapes(q=(q, "B"), pred_actions=(pred_actions, "BA"), actions=(actions, "BA"))
    lmbda = alpha / (sg(jnp.mean(jnp.abs(q))) + q_scale_eps)
    return -lmbda * jnp.mean(q) + bc_weight * bc_loss(pred_actions, actions)


def rebrac_actor_loss(q: jax.Array, pred_actions: jax.Array, actions: jax.Array, beta: float,
                      normalize_q: bool = True) -> jax.Array:
    """ReBRAC actor: mean(beta ||pi(s) - a||^2 - lmbda Q(s, pi(s))), lmbda = 1 / sg(mean |Q|) (1 without
    normalize_q).  q: (B,) (min over the ensemble of the policy action's value), actions: (B, A) -> ()."""
    assert_shapes(q=(q, "B"), pred_actions=(pred_actions, "BA"), actions=(actions, "BA"))
    lmbda = 1.0 / sg(jnp.mean(jnp.abs(q))) if normalize_q else 1.0
    return jnp.mean(beta * action_penalty(pred_actions, actions) - lmbda * q)


def awr_actor_loss(neg_log_lik: jax.Array, advantage: jax.Array, beta: float, max_weight: float = 100.0) -> jax.Array:
    """IQL's and AWAC's (beta = 1 / lambda) advantage-weighted regression: mean(min(exp(beta sg(A)), max_weight) *
    nll), nll the per-row negative log-likelihood of the dataset action (or its squared error, for a deterministic
    actor).  (B,), (B,) -> ().
    beta = 0 weighs every row 1: behaviour cloning."""
    assert_shapes(neg_log_lik=(neg_log_lik, "B"), advantage=(advantage, "B"))
    return jnp.mean(jnp.minimum(jnp.exp(beta * sg(advantage)), max_weight) * neg_log_lik)


def awac_advantage(q_data: jax.Array, q_pi: jax.Array) -> jax.Array:
    """AWAC's advantage, a constant of the actor loss: sg(min_i Q_i(s, a) - min_i Q_i(s, a~)), a the data's action,
    a~ the policy's (CORL: a clipped sample).  q_data, q_pi: (N, B) -> (B,)."""
    assert_shapes(q_data=(q_data, "NB"), q_pi=(q_pi, "NB"))
    return sg(jnp.min(q_data, axis=0) - jnp.min(q_pi, axis=0))


def sac_actor_loss(q: jax.Array, log_prob: jax.Array, alpha: jax.Array) -> jax.Array:
    """SAC-N / EDAC actor: E[alpha log pi(a~|s) - min_i Q_i(s, a~)].  q: (N, B), log_prob: (B,) -> ()."""
    assert_shapes(q=(q, "NB"), log_prob=(log_prob, "B"), alpha=(alpha, ""))
    return jnp.mean(sg(alpha) * log_prob - clipped_double_q(q))


def temperature_loss(log_alpha: jax.Array, log_prob: jax.Array, target_entropy: float) -> jax.Array:
    """SAC temperature: -E[log_alpha * sg(log pi + H_target)].  log_alpha: (), log_prob: (B,) -> ()."""
    assert_shapes(log_alpha=(log_alpha, ""), log_prob=(log_prob, "B"))
    return -jnp.mean(log_alpha * sg(log_prob + target_entropy))


# ---------------------------------------------------------------------------------------------- critic regularisers


def edac_diversity_loss(action_grads: jax.Array) -> jax.Array:
    """EDAC ensemble diversity: mean over the batch of sum_{i != j} <g_i, g_j> / (N - 1), g = normalised dQ_i/da.

    action_grads: (N, B, A), the gradient of each member's Q at the dataset action -> ().  Multiply by eta outside.
    """
    assert_shapes(action_grads=(action_grads, "NBA"))
    n = action_grads.shape[0]
    # ||g|| with a zero-safe gradient: d||g||/dg at g = 0 is NaN in JAX (torch's norm, in the authors' code, gives 0)
    sq = jnp.sum(action_grads**2, axis=-1, keepdims=True)
    norm = jnp.where(sq > 0, jnp.sqrt(jnp.where(sq > 0, sq, 1.0)), 0.0)
    g = action_grads / (norm + 1e-10)
    gram = jnp.einsum("iba,jba->bij", g, g)  # (B, N, N)
    off_diagonal = jnp.sum(gram, axis=(1, 2)) - jnp.trace(gram, axis1=1, axis2=2)
    return jnp.mean(off_diagonal) / (n - 1)


def cql_uniform_penalty(q_uniform: jax.Array, q_data: jax.Array, temperature: float = 1.0) -> jax.Array:
    """The simple CQL regulariser of the authors' TD3+BC+CQL.

    sum over critics of mean_b [ T logsumexp_m(Q(s_b, a_u^m) / T) - Q(s_b, a_b) ], a_u ~ U[-1, 1]^A.
    q_uniform: (N, B, M), q_data: (N, B) -> ().
    """
    assert_shapes(q_uniform=(q_uniform, "NBM"), q_data=(q_data, "NB"))
    lse = temperature * jax.nn.logsumexp(q_uniform / temperature, axis=-1)
    return jnp.sum(jnp.mean(lse - q_data, axis=-1))


def cql_importance_penalty(
    q_random: jax.Array,
    q_policy: jax.Array,
    log_prob_policy: jax.Array,
    q_next_policy: jax.Array,
    log_prob_next_policy: jax.Array,
    q_data: jax.Array,
    act_dim: int,
    temperature: float = 1.0,
) -> jax.Array:
    """CORL's CQL(H) regulariser with importance-sampled logsumexp over random and policy actions.

    q_random (N, B, M) at a ~ U[-1,1]^A (log density A log 0.5); q_policy / q_next_policy (N, B, M) at a ~ pi(.|s)
    and a ~ pi(.|s') (both evaluated at s); log_prob_* (B, M); q_data (N, B).  Returns the sum over critics of
    mean_b [T logsumexp(cat(Q_rand - A log 0.5, Q_pi - log pi, Q_pi' - log pi') / T) - Q(s, a_data)] -> ().
    Multiply by alpha_cql outside.
    """
    assert_shapes(q_random=(q_random, "NBM"), q_policy=(q_policy, "NBM"), log_prob_policy=(log_prob_policy, "BM"),
                  q_next_policy=(q_next_policy, "NBM"), log_prob_next_policy=(log_prob_next_policy, "BM"),
                  q_data=(q_data, "NB"))
    cat = jnp.concatenate(
        [
            q_random - act_dim * jnp.log(0.5),
            q_policy - sg(log_prob_policy)[None],
            q_next_policy - sg(log_prob_next_policy)[None],
        ],
        axis=-1,
    )
    lse = temperature * jax.nn.logsumexp(cat / temperature, axis=-1)
    return jnp.sum(jnp.mean(lse - q_data, axis=-1))


def calibrated_q(q_policy: jax.Array, lower_bound: jax.Array) -> jax.Array:
    """Cal-QL's calibration: max(Q(s, a~pi), V_MC(s)), the policy-action values under CQL's push-down bounded below
    by the Monte-Carlo return-to-go of the row's state (the data's, or a finished online episode's).  Where the
    bound is above Q the push-down no longer lowers Q there (its gradient is 0).  q_policy (N, B, M),
    lower_bound (B,) -> (N, B, M)."""
    assert_shapes(q_policy=(q_policy, "NBM"), lower_bound=(lower_bound, "B"))
    return jnp.maximum(q_policy, lower_bound[None, :, None])
