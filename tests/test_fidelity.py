"""The authors' mode, switch by switch: every config field that reproduces a detail of the authors' code does what
docs/fidelity.md says, and `--preset authors` sets them all."""
import math
from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from offrl_jax import losses as L
from offrl_jax.algos import PRESETS, make_algorithm, make_config
from offrl_jax.algos.common import DataNeeds, Phase, done_flags
from offrl_jax.driver import Driver, make_chunk_fn
from offrl_jax.nets import MLP, Arch, sample_tanh_gaussian, tanh_gaussian_log_prob


def test_layer_norm_eps_reaches_the_layer():
    x = jnp.array([[1e-3, -2e-3, 0.5e-3]])  # pre-activations ~1e-3: their variance is comparable to eps
    mlp = MLP((3,), 1, arch=Arch(layer_norm_affine=False, layer_norm_eps=1e-5))
    params = mlp.init(jax.random.PRNGKey(0), x)
    h = x @ params["params"]["Dense_0"]["kernel"] + params["params"]["Dense_0"]["bias"]
    for eps, close in ((1e-5, True), (1e-6, False)):
        normed = (h - h.mean(-1, keepdims=True)) / jnp.sqrt(h.var(-1, keepdims=True) + eps)
        want = jax.nn.relu(normed) @ params["params"]["Dense_1"]["kernel"] + params["params"]["Dense_1"]["bias"]
        assert np.allclose(mlp.apply(params, x), want, rtol=1e-5, atol=1e-6) == close


def test_torch_init_is_uniform_within_one_over_sqrt_fan_in_and_hidden_bias_constant():
    x = jnp.ones((1, 64))
    params = MLP((512,), 4, layer_norm=False, arch=Arch(init="torch")).init(jax.random.PRNGKey(0), x)["params"]
    bound = 1 / math.sqrt(64)
    for name in ("kernel", "bias"):
        w = np.asarray(params["Dense_0"][name])
        assert np.abs(w).max() <= bound and np.abs(w).max() > 0.95 * bound  # U(-1/sqrt(fan_in), 1/sqrt(fan_in))
        assert abs(w.std() - bound / math.sqrt(3)) < 0.05 * bound
    assert np.abs(params["Dense_1"]["kernel"]).max() <= 1 / math.sqrt(512)
    params = MLP((16,), 2, arch=Arch(init="torch", hidden_bias=0.1)).init(jax.random.PRNGKey(0), x)["params"]
    np.testing.assert_allclose(params["Dense_0"]["bias"], 0.1)  # CORL's EDAC hidden bias
    assert not np.allclose(params["Dense_1"]["bias"], 0.1)  # not the output layer
    orth = MLP((16,), 2, layer_norm=False, arch=Arch(init="orthogonal")).init(jax.random.PRNGKey(0), jnp.ones((1, 8)))
    k = np.asarray(orth["params"]["Dense_0"]["kernel"])  # (8, 16): orthonormal rows scaled by sqrt(2)
    np.testing.assert_allclose(k @ k.T, 2.0 * np.eye(8), atol=1e-5)
    out = np.asarray(orth["params"]["Dense_1"]["kernel"])  # (16, 2): orthonormal columns scaled by 1e-2
    np.testing.assert_allclose(out.T @ out, 1e-4 * np.eye(2), atol=1e-8)
    every = MLP((16,), 2, layer_norm=False, arch=Arch(init="orthogonal_all")).init(jax.random.PRNGKey(0),
                                                                                    jnp.ones((1, 8)))
    out = np.asarray(every["params"]["Dense_1"]["kernel"])  # the authors' cql.py: sqrt(2) for the output too
    np.testing.assert_allclose(out.T @ out, 2.0 * np.eye(2), atol=1e-5)


def test_authors_edac_critics_read_the_torch_bound_from_the_output_width():
    # CORL's VectorizedLinear: kaiming_uniform on an (in, out) weight takes fan_in = out, U(+-1/sqrt(256)) in the
    # first critic layer of 14 inputs (nn.Linear: U(+-1/sqrt(14))); the actor (nn.Linear) keeps its fan_in
    def first_layers(**kw):
        cfg = make_config("edac", "hopper", num_critics=3, hidden=(256, 256), **kw)
        state = make_algorithm(cfg, 11, 3, 8).init(jax.random.PRNGKey(0))
        critic = state.critic.params["params"]["VmapCritic_0"]["MLP_0"]["Dense_0"]["kernel"]
        actor = state.actor.params["params"]["MLP_0"]["Dense_0"]["kernel"]
        return float(jnp.abs(critic).max()), float(jnp.abs(actor).max())

    critic, actor = first_layers(preset="authors")
    assert 0.95 / 16 < critic <= 1 / 16 and 0.95 / math.sqrt(11) < actor <= 1 / math.sqrt(11)
    critic, _ = first_layers(preset="authors", critic_fan="in")
    assert 0.95 / math.sqrt(14) < critic <= 1 / math.sqrt(14)
    with pytest.raises(ValueError, match="critic_fan = 'both' must be in or out"):
        make_config("edac", "hopper", critic_fan="both")


def test_done_flags_per_timeout_mode():
    batch = {"terminals": jnp.array([0.0, 1.0, 0.0]), "timeouts": jnp.array([0.0, 0.0, 1.0])}
    np.testing.assert_array_equal(done_flags(batch, "bootstrap"), [0, 1, 0])
    np.testing.assert_array_equal(done_flags(batch, "drop"), [0, 1, 0])  # dropped rows are never sampled
    np.testing.assert_array_equal(done_flags(batch, "stop"), [0, 1, 1])


def test_timeouts_drop_never_samples_a_timeout_row():
    n = 50
    timeouts = jnp.zeros(n).at[jnp.arange(4, n, 5)].set(1.0)  # every 5th row
    data = {k: jnp.zeros((n, 2)) for k in ("observations", "next_observations", "actions")}
    data |= {"rewards": jnp.arange(n, dtype=jnp.float32), "terminals": jnp.zeros(n), "timeouts": timeouts,
             "returns": jnp.zeros(n)}
    data["rows"] = jnp.asarray(np.flatnonzero(np.asarray(timeouts) == 0), jnp.int32)

    def update(state, batch, key):
        return state, {"timeout_rows": jnp.sum(batch["timeouts"]), "rows_seen": jnp.sum(batch["idx"] % 5 == 4)}

    fn = make_chunk_fn(Phase("probe", update, 100), batch_size=64, num_calls=100)
    _, metrics = fn(jnp.zeros((1,)), data, jax.random.split(jax.random.PRNGKey(0), 1), jnp.int32(0))
    assert float(metrics["timeout_rows"][0]) == 0 and float(metrics["rows_seen"][0]) == 0


def test_a_driver_refuses_data_left_empty_by_dropping_time_outs():
    """Called from Python, without the command's batch-size check: one line, not a gather on zero rows."""
    n = 4
    data = {k: jnp.zeros((n, 2)) for k in ("observations", "next_observations", "actions")}
    data |= {k: jnp.zeros(n) for k in ("rewards", "terminals", "returns")} | {"timeouts": jnp.ones(n)}
    algo = SimpleNamespace(cfg=SimpleNamespace(needs=lambda: DataNeeds(cut_rows=False)))  # timeouts "drop"
    with pytest.raises(ValueError, match="every transition is a time-out row"):
        Driver(algo, data, seeds=(0,), batch_size=2)


def test_signed_balance_reverses_the_gradient_of_a_negative_term():
    value, grad = jax.value_and_grad(lambda x: L.normalized(x, "signed"))(jnp.array(-2.0))
    assert float(value) == 1.0 and float(grad) == pytest.approx(-0.5)  # d/dx x/sg(x) = 1/x
    value, grad = jax.value_and_grad(lambda x: L.normalized(x, "abs"))(jnp.array(-2.0))
    assert float(value) == pytest.approx(-1.0) and float(grad) == pytest.approx(0.5)
    # the hybrid: a / sg(a) + w b / sg(b) with b < 0: b's gradient is w / b
    grads = jax.grad(L.balance_losses, argnums=(0, 1))(jnp.array(2.0), jnp.array(-4.0), 3.0, "signed")
    assert [float(g) for g in grads] == pytest.approx([0.5, -0.75])


def test_td3bc_lambda_without_epsilon():
    q, pi, a = jnp.array([2.0, -4.0]), jnp.zeros((2, 1)), jnp.zeros((2, 1))
    assert float(L.td3bc_actor_loss(q, pi, a, 2.5, q_scale_eps=0.0)) == pytest.approx(-2.5 * (-1.0) / 3.0, abs=1e-7)
    small = jnp.array([1e-7, -1e-7])  # |Q| ~ eps: the default epsilon halves lmbda, CORL's form does not
    assert float(L.td3bc_actor_loss(small, pi, a, 1.0, q_scale_eps=0.0)) == pytest.approx(-1e7 * 0.0, abs=1e-6)
    assert float(jax.grad(lambda q: L.td3bc_actor_loss(q, pi, a, 1.0, q_scale_eps=0.0))(small)[0]) == \
        pytest.approx(-0.5 / 1e-7, rel=1e-4)
    assert float(jax.grad(lambda q: L.td3bc_actor_loss(q, pi, a, 1.0))(small)[0]) == pytest.approx(
        -0.5 / 1.1e-7, rel=1e-4)


def test_tanh_log_det_forms():
    # u = 1: exact correction log(1 - tanh(1)^2); "eps" adds 1e-6 inside the log (CORL)
    mean, log_std, u = jnp.zeros((1, 1)), jnp.zeros((1, 1)), 1.0
    gauss = -0.5 - 0.5 * np.log(2 * np.pi)
    exact = tanh_gaussian_log_prob(mean, log_std, jnp.full((1, 1), np.tanh(u)))
    eps = tanh_gaussian_log_prob(mean, log_std, jnp.full((1, 1), np.tanh(u)), log_det="eps")
    np.testing.assert_allclose(exact, [gauss - np.log(1 - np.tanh(u) ** 2)], rtol=1e-5)
    np.testing.assert_allclose(eps, [gauss - np.log(1 - np.tanh(u) ** 2 + 1e-6)], rtol=1e-5)
    # far in the tail (tanh(u) = 1 in float32) the eps form caps the correction at -log(1e-6); exact keeps growing
    mean, log_std = jnp.full((1, 1), 30.0), jnp.full((1, 1), -5.0)
    _, lp_eps = sample_tanh_gaussian(jax.random.PRNGKey(0), mean, log_std, "eps")
    _, lp_exact = sample_tanh_gaussian(jax.random.PRNGKey(0), mean, log_std, "exact")
    assert float(lp_exact[0] - lp_eps[0]) > 40.0


def tiny_batch(obs_dim=3, act_dim=2, b=8, k=None, seed=0):
    rng = np.random.default_rng(seed)
    shape = (b,) if k is None else (k, b)
    batch = {"observations": rng.normal(size=(*shape, obs_dim)),
             "next_observations": rng.normal(size=(*shape, obs_dim)),
             "actions": rng.uniform(-1, 1, size=(*shape, act_dim)), "rewards": rng.normal(size=shape),
             "terminals": np.zeros(shape), "timeouts": np.zeros(shape), "returns": rng.normal(size=shape) * 10}
    batch = {k2: jnp.asarray(v, jnp.float32) for k2, v in batch.items()}
    return batch | {"idx": jnp.zeros(shape, jnp.int32)}


def test_log_alpha_bound_clips_the_temperature_used_in_offline_rl_not_the_parameter():
    # the authors' update: alpha = exp(clip(log_alpha, -10, 10)); log_alpha itself keeps its Adam steps
    cfg = make_config("edac", "hopper", num_critics=2, hidden=(8,), log_alpha_bound=10.0)
    algo = make_algorithm(cfg, 3, 2, 8)
    state = algo.init(jax.random.PRNGKey(0))
    state = state.replace(log_alpha=state.log_alpha.replace(params=jnp.float32(-12.0)))
    batch, key = tiny_batch(), jax.random.PRNGKey(1)
    new, metrics = algo.temperature_update(state, batch, key, clip=True)
    assert abs(float(new.log_alpha.params) + 12.0) < 1e-3  # Adam's first step: lr 3e-4; not clipped to -10
    np.testing.assert_allclose(metrics["alpha"], math.exp(-10.0), rtol=1e-6)
    np.testing.assert_allclose(algo.alpha(state, clip=True), math.exp(-10.0), rtol=1e-6)
    np.testing.assert_allclose(algo.alpha(state, clip=False), math.exp(-12.0), rtol=1e-6)
    # the actor's loss in offline RL uses the clipped temperature
    action, log_prob = algo.sample_policy(state.actor.params, batch["observations"], key)
    q = algo.critic.apply(state.critic.params, batch["observations"], action)
    loss, _ = algo.actor_loss(state.actor.params, state, batch, key)
    np.testing.assert_allclose(loss, L.sac_actor_loss(q, log_prob, jnp.float32(math.exp(-10.0))), rtol=1e-6)
    # soft BC (pre-training) uses the unclipped one, and so does a TD target during critic pre-training
    assert not np.isclose(float(L.sac_actor_loss(q, log_prob, jnp.float32(math.exp(-12.0)))), float(loss))
    np.testing.assert_allclose(algo.td_target(state, batch, key, clip=False) - algo.td_target(state, batch, key),
                               0.99 * (math.exp(-10.0) - math.exp(-12.0)) * algo.sample_policy(
                                   state.actor.params, batch["next_observations"], key)[1], rtol=0, atol=1e-6)
    # soft BC's temperature steps are not clipped either
    free = make_config("edac", "hopper", num_critics=2, hidden=(8,), log_alpha_bound=0.1, alpha_lr=1.0)
    algo = make_algorithm(free, 3, 2, 8)
    state = algo.init(jax.random.PRNGKey(0))
    for _ in range(3):  # lr 1: log alpha moves by ~1 per step
        state, metrics = algo.temperature_update(state, batch, jax.random.PRNGKey(1))
    assert abs(float(state.log_alpha.params)) > 0.1 and abs(math.log(float(metrics["alpha"]))) > 0.1


def test_authors_pretraining_schedule_10k_soft_bc_then_11k_critic():
    # their loop: soft BC while epoch < 20 // 2, the critic while epoch <= 20 (epochs of 1k updates), EDAC after
    plan = lambda cfg, total: [(s.name, s.steps) for s in cfg.phases(total)]  # noqa: E731
    authors = make_config("edac", "hopper", preset="authors")
    assert plan(authors, 3_000_000) == [("actor_pretrain", 10_000), ("critic_pretrain", 11_000),
                                        ("offline_rl", 2_979_000)]
    # --pretrain_epochs 200 (Adroit): 100k + 101k
    assert plan(make_config("edac_bc", "door", preset="authors"), 300_000) == [
        ("actor_pretrain", 100_000), ("critic_pretrain", 101_000), ("offline_rl", 99_000)]
    assert plan(make_config("edac", "hopper"), 30_000) == [("actor_pretrain", 10_000), ("critic_pretrain", 10_000),
                                                           ("offline_rl", 10_000)]
    # the extra epoch goes to the last pre-training phase, and only as far as the budget has it (their loop too)
    assert plan(make_config("edac", "hopper", preset="authors", pretrain="actor"), 50_000) == [
        ("actor_pretrain", 21_000), ("offline_rl", 29_000)]
    assert plan(authors, 20_400) == [("actor_pretrain", 10_000), ("critic_pretrain", 10_400), ("offline_rl", 0)]
    assert plan(make_config("edac", "hopper", preset="authors", pretrain="none"), 5_000) == [("offline_rl", 5_000)]
    with pytest.raises(ValueError, match="pretrain_extra = -1 must be >= 0"):
        make_config("edac", "hopper", pretrain_extra=-1)


def test_edac_hand_over_keeps_every_adam_state_and_freezes_actor_and_alpha_in_critic_pretraining():
    # the authors build each optimiser once: soft BC, critic pre-training and EDAC step the same Adam states
    cfg = make_config("edac", "hopper", preset="authors", num_critics=2, hidden=(8,), pretrain_updates=4,
                      pretrain_extra=1)
    algo = make_algorithm(cfg, 3, 2, 8)
    phases = {p.name: p for p in algo.phases(10)}
    assert [(p.name, p.steps) for p in phases.values()] == [("actor_pretrain", 2), ("critic_pretrain", 3),
                                                            ("offline_rl", 5)]
    count = lambda model: int(model.opt_state[0].count)  # noqa: E731  optax.adam's step counter
    state, batch = algo.init(jax.random.PRNGKey(0)), {k: v[None] for k, v in tiny_batch().items()}
    for name, steps in (("actor_pretrain", 2), ("critic_pretrain", 3)):
        before = state
        for i in range(steps):
            state, _ = phases[name].update(state, batch, jax.random.PRNGKey(i))
    assert (count(state.actor), count(state.log_alpha), count(state.critic)) == (2, 2, 3)
    # the critic phase moved neither the actor nor the temperature
    assert all(np.array_equal(a, b) for a, b in zip(jax.tree.leaves((before.actor, before.log_alpha)),
                                                      jax.tree.leaves((state.actor, state.log_alpha))))
    state, _ = phases["offline_rl"].update(state, batch, jax.random.PRNGKey(9))
    assert (count(state.actor), count(state.log_alpha), count(state.critic)) == (3, 3, 4)


def test_soft_returns_entropies_at_the_observations_or_the_next_observations():
    n = 6
    rng = np.random.default_rng(0)
    data = {"observations": rng.normal(size=(n, 3)), "next_observations": rng.normal(size=(n, 3)),
            "rewards": rng.normal(size=n), "terminals": np.zeros(n), "timeouts": np.array([0, 0, 1.0, 0, 0, 0])}
    data = {k: jnp.asarray(v, jnp.float32) for k, v in data.items()}
    moved = data | {"next_observations": data["next_observations"] + 5.0}
    key = jax.random.PRNGKey(2)
    for where, changes in (("observations", False), ("next_observations", True)):
        algo = make_algorithm(make_config("edac", "hopper", num_critics=2, hidden=(8,), soft_entropy_at=where),
                              3, 2, n)
        state = algo.init(jax.random.PRNGKey(0))
        a, b = (np.asarray(algo.compute_soft_returns(state, d, key).soft_returns) for d in (data, moved))
        assert (not np.allclose(a, b)) == changes
    with pytest.raises(ValueError, match="soft_entropy_at = 'states' must be next_observations or observations"):
        make_config("edac", "hopper", soft_entropy_at="states")


def test_figure2_authors_preset_gives_the_authors_edac_schedule():
    from experiments import figure2

    def edac(argv):
        return {s.env: s for s in figure2.build(figure2.make_parser().parse_args(["--algos", "edac", *argv]))}

    for env, (critics, budget) in {"hopper": (50, 3_000_000), "halfcheetah": (10, 1_000_000),
                                   "walker2d": (10, 12_000_000)}.items():
        study = edac(["--preset", "authors"])[env]
        cfg = study.config("pretrained")
        assert (study.updates, cfg.num_critics, cfg.eta) == (budget, critics, 1.0)
        assert [(s.name, s.steps) for s in cfg.phases(study.updates)][:2] == [("actor_pretrain", 10_000),
                                                                                ("critic_pretrain", 11_000)]
        assert (cfg.timeouts, cfg.soft_entropy_at, cfg.log_alpha_bound) == ("stop", "observations", 10.0)
    # flags still win; without the preset, the CPU-sized study
    study = edac(["--preset", "authors", "--edac-updates", "30000", "--num-critics", "4", "--envs", "hopper"])["hopper"]
    assert (study.updates, study.config("pretrained").num_critics) == (30_000, 4)
    study = edac(["--envs", "hopper"])["hopper"]
    cfg = study.config("pretrained")
    assert (study.updates, cfg.num_critics, cfg.pretrain_updates, cfg.pretrain_extra) == (16_000, 10, 12_000, 0)


def test_actor_only_pretraining_without_target_updates_keeps_the_init():
    for flag, moved in ((True, True), (False, False)):
        cfg = make_config("td3bc", "hopper", pretrain="actor", hidden=(8,), bc_target_updates=flag)
        algo = make_algorithm(cfg, 3, 2, 8)
        state = algo.init(jax.random.PRNGKey(0))
        new, _ = algo.bc_update(state, tiny_batch(), jax.random.PRNGKey(1))
        changed = any(not np.allclose(a, b) for a, b in zip(jax.tree.leaves(new.actor.target),
                                                               jax.tree.leaves(state.actor.target)))
        assert changed == moved
    # actor+critic pre-training updates the actor target either way (the authors' pretrain_actorcritic does)
    cfg = make_config("td3bc", "hopper", pretrain="actor+critic", hidden=(8,), bc_target_updates=False)
    algo = make_algorithm(cfg, 3, 2, 8)
    state = algo.init(jax.random.PRNGKey(0))
    new, _ = algo.bc_update(state, tiny_batch(), jax.random.PRNGKey(1))
    assert not np.allclose(jax.tree.leaves(new.actor.target)[0], jax.tree.leaves(state.actor.target)[0])


def test_actor_and_critic_widths_are_separate():
    cfg = make_config("td3bc", "hopper", actor_hidden=(16, 16, 16), hidden=(8, 8))
    algo = make_algorithm(cfg, 3, 2, 8)
    state = algo.init(jax.random.PRNGKey(0))
    actor_dense = [k for k in state.actor.params["params"]["MLP_0"] if k.startswith("Dense")]
    assert len(actor_dense) == 4 and state.actor.params["params"]["MLP_0"]["Dense_0"]["kernel"].shape == (3, 16)
    critic = state.critic.params["params"]["VmapCritic_0"]["MLP_0"]
    assert len([k for k in critic if k.startswith("Dense")]) == 3 and critic["Dense_0"]["kernel"].shape == (2, 5, 8)


def test_cql_log_std_offset_and_bounds():
    cfg = make_config("cql", "door", hidden=(8,), preset="authors")
    algo = make_algorithm(cfg, 3, 2, 8)
    state = algo.init(jax.random.PRNGKey(0))
    _, log_std = algo.actor.apply(state.actor.params, jnp.zeros((1, 3)))
    raw_out = state.actor.params["params"]["MLP_0"]["Dense_1"]["bias"]  # zero bias at init (orthogonal scheme)
    np.testing.assert_allclose(raw_out, 0.0)
    np.testing.assert_allclose(log_std, -1.0, atol=1e-6)  # offset -1 on a zero output
    _, log_std = algo.actor.apply(state.actor.params, jnp.full((1, 3), -1e6))
    assert float(log_std.min()) >= -20.0


def test_authors_preset_values_and_precedence():
    td3 = make_config("td3bc", "hopper", preset="authors")
    assert (td3.alpha, td3.actor_hidden, td3.hidden, td3.layer_norm_affine, td3.layer_norm_eps, td3.init,
            td3.timeouts, td3.q_scale_eps, td3.balance, td3.bc_target_updates) == (
        10.0, (256, 256, 256), (256, 256), False, 1e-5, "torch", "stop", 0.0, "signed", False)
    edac = make_config("edac_bc", "walker2d", preset="authors")
    assert (edac.hidden_bias, edac.tanh_log_det, edac.log_alpha_bound, edac.timeouts, edac.balance,
            edac.pretrain_extra, edac.soft_entropy_at, edac.critic_fan) == (
        0.1, "eps", 10.0, "stop", "signed", 1000, "observations", "out")
    assert make_config("td3bc", "door", preset="authors").alpha == 0.1  # the paper's Table 3, not their config's 1.0
    assert make_config("td3bc", "hopper", preset="authors", timeouts="drop").timeouts == "drop"  # flags win
    assert make_config("cql", "door", preset="authors").alpha_lr == 3e-5
    with pytest.raises(ValueError, match="unknown preset"):
        make_config("td3bc", "hopper", preset="nope")
    assert set(PRESETS) == {"authors", "published"}


def test_authors_preset_from_the_command_line():
    from experiments import adroit_door, mujoco_medium

    def resolved(study, label=None):  # {field: (value, where it came from)} of a variant
        label = label or study.variants[0].label
        return {k: (getattr(study.config(label), k), source) for k, source in study.sources()[label].items()}

    default = resolved(mujoco_medium.build(mujoco_medium.make_parser().parse_args([])))
    # the main job's own alpha (its default preset), the library's defaults
    assert default["alpha"] == (2.5, "preset") and default["init"] == ("flax", "default")
    study = mujoco_medium.build(mujoco_medium.make_parser().parse_args(["--preset", "authors", "--timeouts", "drop"]))
    for v in study.variants:
        r = resolved(study, v.label)
        assert r["alpha"] == (10.0, "per-env") and r["init"] == ("torch", "preset")  # per-env alpha: hopper 10
        assert r["timeouts"] == ("drop", "flag") and r["actor_hidden"] == ((256, 256, 256), "preset")
    p = mujoco_medium.make_parser()
    studies = mujoco_medium.build(p.parse_args(["--study", "paper", "--preset", "authors"]))
    assert len(studies) == 6 and all(s.config(v.label).balance == "signed" for s in studies for v in s.variants)
    (study,) = [adroit_door.build(adroit_door.make_parser().parse_args(
        ["--preset", "authors", "--variants", "TD3+BC+CQL", "--balance", "abs"]))]
    o = resolved(study)
    assert o["balance"] == ("abs", "flag") and o["init"] == ("torch", "preset")
