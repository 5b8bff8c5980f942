"""Float64 parity: our TD3+BC, EDAC, ReBRAC, IQL, AWAC, CQL and Cal-QL updates equal a PyTorch reference update
(`tests/torch_reference.py`, written the way CORL writes them, from Fujimoto & Gu 2021, An et al. 2021, Tarasov et
al. 2023, Kostrikov et al. 2022, Nair et al. 2020, Kumar et al. 2020 and Nakamoto et al. 2023) to rounding.  ReBRAC,
IQL and AWAC are built from their own per-env defaults (their LayerNorm and epsilon as they ship), with the
target-policy noise off; each test also checks that every network moved, so agreement is not two sides standing still.

Each test builds our algorithm with `make_config(..., preset="authors")` (torch's LayerNorm epsilon 1e-5, the authors'
LayerNorm without affine parameters, lambda = alpha / mean|Q| with no epsilon, ...), copies its initial parameters
into the torch modules (flax Dense kernels are (in, out), torch Linear weights (out, in); the critic ensemble's
parameters carry a leading axis N), checks the forward passes agree, runs the same minibatches through both, and
compares every parameter, every target network and log alpha afterwards.  A correct float64 update agrees to ~1e-12;
the tests assert 1e-9.

Why float64: Adam's step is lr * m / (sqrt(v) + eps), about lr * g / |g| per coordinate, whatever the size of g.  A
gradient that is zero up to rounding (a coordinate the loss barely depends on) then takes a full-size step whose
sign is the sign of the rounding noise, so in float32 two correct implementations that merely sum in a different
order drift apart by ~lr per step in such coordinates, and no float32 tolerance separates a real change in the update
from that noise.  In float64 the same noise stays ~1e-12 for these few updates.

The JAX side runs under `jax.enable_x64(True)` (a context manager: x64 does not leak into other tests in the same
process).  EDAC's sampling noise is made identical by recording every `jax.random.normal` draw of
`offrl_jax.nets` (through a proxy for that module's `jax` name, so nothing else is patched) while our update runs
eagerly, and feeding the recorded draws to the torch actor in the same order (temperature, actor, TD target).  CQL's
and Cal-QL's uniform actions are recorded the same way, through `offrl_jax.algos.cql.uniform_actions`.

Needs torch (`pip install -e .[torch]`); skipped without it.  Run: pytest -m parity -s (prints the max differences).
"""
from __future__ import annotations

import contextlib
import types

import numpy as np
import pytest

torch = pytest.importorskip("torch")

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
from torch import nn  # noqa: E402

from offrl_jax import nets  # noqa: E402
from offrl_jax.algos import awac, make_algorithm, make_config  # noqa: E402
from tests import torch_reference as ref  # noqa: E402

pytestmark = pytest.mark.parity

OBS, ACT, ROWS, B = 11, 3, 400, 128
ATOL = 1e-9


# ------------------------------------------------------------------------------------------------------- helpers


@contextlib.contextmanager
def float64():
    """x64 for JAX and float64 as torch's default dtype, both restored on exit."""
    torch_dtype = torch.get_default_dtype()
    torch.set_default_dtype(torch.float64)
    try:
        with jax.enable_x64(True):
            yield
    finally:
        torch.set_default_dtype(torch_dtype)
    assert not jax.config.jax_enable_x64


def to64(tree):
    """Every floating leaf as float64 (flax initialises float32 parameters whatever the x64 flag)."""
    return jax.tree.map(lambda x: jnp.asarray(x, jnp.float64) if jnp.issubdtype(x.dtype, jnp.floating) else x, tree)


def dataset(seed: int = 0) -> dict[str, np.ndarray]:
    """Random transitions (float64) with some terminals and time-outs, and arbitrary Monte-Carlo returns."""
    rng = np.random.default_rng(seed)
    flags = rng.random(ROWS)
    return {
        "observations": rng.normal(size=(ROWS, OBS)),
        "actions": rng.uniform(-1, 1, (ROWS, ACT)),
        "rewards": 1.0 + 0.5 * rng.normal(size=ROWS),
        "next_observations": rng.normal(size=(ROWS, OBS)),
        "terminals": (flags < 0.1).astype(np.float64),
        "timeouts": (flags > 0.9).astype(np.float64),
        "returns": 20.0 + 5.0 * rng.normal(size=ROWS),
    }


def minibatches(data, num: int, seed: int = 1) -> list[dict[str, np.ndarray]]:
    idx = np.random.default_rng(seed).integers(0, ROWS, (num, B))
    return [{k: v[i] for k, v in data.items()} | {"idx": i.astype(np.int32)} for i in idx]


def stack(batches) -> dict[str, jax.Array]:
    """The driver's (k, B, ...) stacked minibatches."""
    return {k: jnp.asarray(np.stack([b[k] for b in batches])) for k in batches[0]}


def torch_batch(b, timeouts: str):
    """(state, action, reward (B, 1), next_state, done (B, 1)); done = terminal, or terminal or time-out ("stop")."""
    done = np.maximum(b["terminals"], b["timeouts"]) if timeouts == "stop" else b["terminals"]
    t = lambda x: torch.tensor(x, dtype=torch.float64)  # noqa: E731
    return t(b["observations"]), t(b["actions"]), t(b["rewards"])[:, None], t(b["next_observations"]), t(done)[:, None]


def layers(mlp: dict) -> tuple[list[dict], list[dict | None]]:
    """A flax MLP's Dense layers and the LayerNorm after each hidden one (None without affine parameters)."""
    dense = [mlp[f"Dense_{i}"] for i in range(sum(k.startswith("Dense_") for k in mlp))]
    return dense, [mlp.get(f"LayerNorm_{i}") for i in range(len(dense) - 1)]


def torch_layers(module: nn.Module, kind: type) -> list[nn.Module]:
    return [m for m in module.modules() if isinstance(m, kind)]


def mlp_pairs(prefix: str, mlp: dict, linears, norms, member: int | None = None):
    """(name, our array in torch layout, torch parameter) for an MLP of nn.Linear (member: one critic of our
    ensemble)."""
    pick = (lambda x: np.asarray(x)) if member is None else (lambda x: np.asarray(x)[member])
    dense, flax_norms = layers(mlp)
    assert len(dense) == len(linears)
    pairs = []
    for i, (d, lin) in enumerate(zip(dense, linears)):
        pairs += [(f"{prefix}.Dense_{i}.kernel", pick(d["kernel"]).T, lin.weight),
                  (f"{prefix}.Dense_{i}.bias", pick(d["bias"]), lin.bias)]
    if not norms:  # no LayerNorm on the torch side: none with parameters on ours either
        flax_norms = [n for n in flax_norms if n is not None]
    assert len(flax_norms) == len(norms)
    for i, (n, norm) in enumerate(zip(flax_norms, norms)):
        assert (n is None) == (norm.weight is None), "LayerNorm affine parameters on one side only"
        if n is not None:
            pairs += [(f"{prefix}.LayerNorm_{i}.scale", pick(n["scale"]), norm.weight),
                      (f"{prefix}.LayerNorm_{i}.bias", pick(n["bias"]), norm.bias)]
    return pairs


def copy_in(pairs) -> None:
    with torch.no_grad():
        for name, ours, param in pairs:
            assert tuple(param.shape) == ours.shape, f"{name}: {tuple(param.shape)} vs {ours.shape}"
            assert param.dtype == torch.float64, name
            param.copy_(torch.tensor(ours))


def compare(label: str, pairs) -> float:
    """Assert every pair agrees to ATOL; print and return the largest difference."""
    diffs = {name: float(np.max(np.abs(ours - param.detach().numpy()))) for name, ours, param in pairs}
    worst = max(diffs, key=diffs.get)
    print(f"\n{label}: {len(diffs)} arrays, max |jax - torch| = {diffs[worst]:.3e} ({worst})")
    bad = {k: v for k, v in diffs.items() if not v <= ATOL}
    assert not bad, f"{label}: differences above {ATOL}: {bad}"
    return diffs[worst]


def delayed_rl_updates(algo, state, data, torch_update, calls: int = 5):
    """`calls` calls of our offline-RL update, each on 2 minibatches (critic steps on both, the delayed actor and
    the targets once), with `torch_update(minibatch)` run on each minibatch in the same order; our new state."""
    phase = algo.phases(20_000)[-1]
    assert phase.name == "offline_rl" and phase.updates_per_call == 2
    update = jax.jit(phase.update)
    batches = minibatches(data, 2 * calls)
    for call in range(calls):
        pair = batches[2 * call:2 * call + 2]
        state, _ = update(state, stack(pair), jax.random.key(call))
        for b in pair:
            torch_update(b)
    return state


# ----------------------------------------------------------------------------------------------------- TD3+BC


def td3bc_pairs(state, agent: ref.TD3BC):
    """Every parameter and target of both sides, paired."""
    pairs = []
    for tag, ours_actor, ours_critic, actor, critics in (
        ("", state.actor.params, state.critic.params, agent.actor, (agent.critic_1, agent.critic_2)),
        ("target.", state.actor.target, state.critic.target, agent.actor_target,
         (agent.critic_1_target, agent.critic_2_target)),
    ):
        pairs += mlp_pairs(f"{tag}actor", ours_actor["params"]["MLP_0"], torch_layers(actor, nn.Linear),
                           torch_layers(actor, nn.LayerNorm))
        for i, critic in enumerate(critics):
            pairs += mlp_pairs(f"{tag}critic{i}", ours_critic["params"]["VmapCritic_0"]["MLP_0"],
                               torch_layers(critic, nn.Linear), torch_layers(critic, nn.LayerNorm), member=i)
    return pairs


def td3bc_setup(affine: bool, timeouts: str, **overrides):
    cfg = make_config("td3bc", preset="authors", alpha=2.5, policy_noise=0.0, hidden=(32, 32),
                      actor_hidden=(32, 32, 32), layer_norm_affine=affine, timeouts=timeouts, **overrides)
    assert (cfg.layer_norm_eps, cfg.q_scale_eps, cfg.num_critics, cfg.policy_delay) == (1e-5, 0.0, 2, 2)
    algo = make_algorithm(cfg, OBS, ACT, ROWS)
    state = to64(algo.init(jax.random.key(0)))
    agent = ref.TD3BC(alpha=cfg.alpha, gamma=cfg.gamma, tau=cfg.tau, policy_noise=0.0, noise_clip=cfg.noise_clip,
                      policy_freq=cfg.policy_delay, lr=cfg.actor_lr, obs_dim=OBS, act_dim=ACT, hidden=cfg.hidden,
                      actor_hidden=cfg.actor_hidden, ln_affine=affine, ln_eps=cfg.layer_norm_eps)
    assert cfg.critic_lr == cfg.actor_lr
    copy_in(td3bc_pairs(state, agent))
    # forward passes first: a difference here is in the networks, not in the update
    b = minibatches(dataset(), 1, seed=7)[0]
    s, a = torch_batch(b, timeouts)[:2]
    with torch.no_grad():
        ours_pi = np.asarray(algo.actor.apply(state.actor.params, jnp.asarray(b["observations"])))
        ours_q = np.asarray(algo.critic.apply(state.critic.params, jnp.asarray(b["observations"]),
                                              jnp.asarray(b["actions"])))
        np.testing.assert_allclose(ours_pi, torch.tanh(agent.actor(s)).numpy(), rtol=0, atol=1e-12)
        torch_q = np.stack([agent.critic_1(s, a)[:, 0].numpy(), agent.critic_2(s, a)[:, 0].numpy()])
        np.testing.assert_allclose(ours_q, torch_q, rtol=0, atol=1e-12)
    return cfg, algo, state, agent


@pytest.mark.parametrize("affine,timeouts", [(False, "stop"), (True, "bootstrap")])
def test_td3bc_rl_update_matches_torch(affine, timeouts):
    """10 offline-RL updates (5 calls of our rl_update: 2 critic steps, then the actor step and every target)."""
    data = dataset()
    with float64():
        cfg, algo, state, agent = td3bc_setup(affine, timeouts)
        state = delayed_rl_updates(algo, state, data, lambda b: agent.train(torch_batch(b, timeouts)))
        compare(f"td3bc rl (affine={affine}, timeouts={timeouts})", td3bc_pairs(state, agent))


@pytest.mark.parametrize("lam", [0.0, 0.5])
def test_td3bc_pretrain_update_matches_torch(lam):
    """10 pre-training updates (BC on the actor, then MC regression on the critics, lambda-mixed with TD when lam > 0,
    each with its targets), then 4 offline-RL updates from there."""
    data = dataset()
    with float64():
        cfg, algo, state, agent = td3bc_setup(False, "stop", lam=lam)
        phases = algo.phases(20_000)
        assert [p.name for p in phases] == ["pretrain", "offline_rl"] and cfg.pretrain == "actor+critic"
        pretrain, rl = jax.jit(phases[0].update), jax.jit(phases[1].update)
        batches = minibatches(data, 14)
        for i, b in enumerate(batches[:10]):
            state, _ = pretrain(state, stack([b]), jax.random.key(i))
            tb = torch_batch(b, "stop")
            agent.bc_update(tb)
            agent.mc_update(tb, torch.tensor(b["returns"])[:, None], lam)
        compare(f"td3bc pretrain (lam={lam})", td3bc_pairs(state, agent))
        for call in range(2):
            pair = batches[10 + 2 * call:12 + 2 * call]
            state, _ = rl(state, stack(pair), jax.random.key(100 + call))
            for b in pair:
                agent.train(torch_batch(b, "stop"))
        compare(f"td3bc pretrain (lam={lam}) + rl", td3bc_pairs(state, agent))


# ------------------------------------------------------------------------------------------------------- EDAC


class _Proxy(types.SimpleNamespace):
    """A module with some of its attributes replaced."""

    def __init__(self, module, **replaced):
        super().__init__(**replaced)
        self._module = module

    def __getattr__(self, name):  # only for names not replaced
        return getattr(self._module, name)


class _NoiseRecorder:
    """Stands in for the `jax` name inside offrl_jax.nets: `random.normal` draws as JAX would and records the draw;
    everything else is jax's own."""

    def __init__(self):
        self.draws: list[np.ndarray] = []
        self.random = _Proxy(jax.random, normal=self.normal)

    def normal(self, key, shape=(), dtype=None):
        draw = jax.random.normal(key, shape) if dtype is None else jax.random.normal(key, shape, dtype)
        self.draws.append(np.asarray(draw))  # fails on a tracer: run the update eagerly, not under jit
        return draw

    def take(self, count: int, shape: tuple[int, ...] = (B, ACT)) -> list[torch.Tensor]:
        assert len(self.draws) >= count, f"expected {count} more noise draws, {len(self.draws)} recorded"
        out, self.draws = self.draws[:count], self.draws[count:]
        assert all(d.shape == shape for d in out), [d.shape for d in out]
        return [torch.tensor(d) for d in out]

    def __getattr__(self, name):  # everything but `random`
        return getattr(jax, name)


def edac_pairs(state, agent: ref.EDAC):
    n = agent.num_critics
    dense, norms = layers(state.actor.params["params"]["MLP_0"])
    # CORL's ensemble shares its LayerNorms' affine parameters across members (ours are per member): affine=False only
    assert all(x is None for x in norms)
    trunk = torch_layers(agent.actor.trunk, nn.Linear)
    pairs = []
    for i, (d, lin) in enumerate(zip(dense[:-1], trunk, strict=True)):
        pairs += [(f"actor.Dense_{i}.kernel", np.asarray(d["kernel"]).T, lin.weight),
                  (f"actor.Dense_{i}.bias", np.asarray(d["bias"]), lin.bias)]
    head_kernel, head_bias = np.asarray(dense[-1]["kernel"]), np.asarray(dense[-1]["bias"])
    act = head_bias.shape[0] // 2
    pairs += [("actor.mu.kernel", head_kernel[:, :act].T, agent.actor.mu.weight),
              ("actor.mu.bias", head_bias[:act], agent.actor.mu.bias),
              ("actor.log_std.kernel", head_kernel[:, act:].T, agent.actor.log_sigma.weight),
              ("actor.log_std.bias", head_bias[act:], agent.actor.log_sigma.bias)]
    for tag, ours, critic in (("critic", state.critic.params, agent.critic),
                              ("target_critic", state.critic.target, agent.target_critic)):
        dense, norms = layers(ours["params"]["VmapCritic_0"]["MLP_0"])
        assert all(x is None for x in norms)
        for i, (d, lin) in enumerate(zip(dense, torch_layers(critic, ref.VectorizedLinear), strict=True)):
            kernel, bias = np.asarray(d["kernel"]), np.asarray(d["bias"])
            assert kernel.shape[0] == n
            pairs += [(f"{tag}.Dense_{i}.kernel", kernel, lin.weight),
                      (f"{tag}.Dense_{i}.bias", bias[:, None, :], lin.bias)]
    pairs.append(("log_alpha", np.asarray(state.log_alpha.params).reshape(1), agent.log_alpha))
    return pairs


def edac_setup(log_det: str, recorder: _NoiseRecorder):
    cfg = make_config("edac", preset="authors", num_critics=5, eta=1.0, hidden=(32, 32, 32), tanh_log_det=log_det)
    assert (cfg.layer_norm_eps, cfg.layer_norm_affine, cfg.backup_entropy) == (1e-5, False, True)
    assert not hasattr(cfg, "simultaneous_update")  # EDAC's losses in turn (CQL's all from the incoming state)
    assert cfg.actor_lr == cfg.critic_lr == cfg.alpha_lr and cfg.init_alpha == 1.0
    algo = make_algorithm(cfg, OBS, ACT, ROWS)
    state = to64(algo.init(jax.random.key(0)))
    agent = ref.EDAC(num_critics=cfg.num_critics, eta=cfg.eta, gamma=cfg.gamma, tau=cfg.tau, lr=cfg.actor_lr,
                     obs_dim=OBS, act_dim=ACT, hidden=cfg.hidden, actor_hidden=cfg.actor_hidden, ln_affine=False,
                     ln_eps=cfg.layer_norm_eps, log_det=log_det, log_alpha_bound=cfg.log_alpha_bound)
    copy_in(edac_pairs(state, agent))
    # forward passes first
    b = minibatches(dataset(), 1, seed=7)[0]
    s, a = torch_batch(b, cfg.timeouts)[:2]
    obs, actions = jnp.asarray(b["observations"]), jnp.asarray(b["actions"])
    with torch.no_grad():
        np.testing.assert_allclose(np.asarray(algo.critic.apply(state.critic.params, obs, actions)),
                                   agent.critic(s, a).numpy(), rtol=0, atol=1e-12)
        mean, log_std = algo.actor.apply(state.actor.params, obs)
        dist = agent.actor.dist(s)
        np.testing.assert_allclose(np.asarray(mean), dist.loc.numpy(), rtol=0, atol=1e-12)
        np.testing.assert_allclose(np.asarray(jnp.exp(log_std)), dist.scale.numpy(), rtol=0, atol=1e-12)
        action, log_prob = algo.sample_policy(state.actor.params, obs, jax.random.key(3))
        (noise,) = recorder.take(1)
        torch_action, torch_log_prob = agent.actor(s, noise)
        np.testing.assert_allclose(np.asarray(action), torch_action.numpy(), rtol=0, atol=1e-12)
        np.testing.assert_allclose(np.asarray(log_prob), torch_log_prob.numpy(), rtol=0, atol=1e-10)
    return cfg, algo, state, agent


@pytest.mark.parametrize("log_det", ["eps", "exact"])
def test_edac_rl_update_matches_torch(log_det, monkeypatch):
    """10 offline-RL updates: temperature (clipped log alpha), actor, critic with eta * diversity, Polyak."""
    recorder = _NoiseRecorder()
    monkeypatch.setattr(nets, "jax", recorder)
    data = dataset()
    with float64():
        cfg, algo, state, agent = edac_setup(log_det, recorder)
        phase = algo.phases(50_000)[-1]
        assert phase.name == "offline_rl" and phase.updates_per_call == 1
        for i, b in enumerate(minibatches(data, 10)):
            state, _ = phase.update(state, stack([b]), jax.random.key(i))  # eagerly: the noise is recorded
            agent.update(torch_batch(b, cfg.timeouts), recorder.take(3))  # temperature, actor, TD target
        assert not recorder.draws
        compare(f"edac rl (log_det={log_det})", edac_pairs(state, agent))


def test_edac_pretrain_updates_match_torch(monkeypatch):
    """5 actor pre-training updates (temperature, soft BC), 5 critic pre-training updates (regression on soft
    returns, mean over critics, + eta * diversity, Polyak), then 2 offline-RL updates."""
    recorder = _NoiseRecorder()
    monkeypatch.setattr(nets, "jax", recorder)
    data = dataset()
    soft_returns = 10.0 + 3.0 * np.random.default_rng(5).normal(size=ROWS)
    with float64():
        cfg, algo, state, agent = edac_setup("eps", recorder)
        phases = {p.name: p for p in algo.phases(50_000)}
        assert list(phases) == ["actor_pretrain", "critic_pretrain", "offline_rl"]
        batches = minibatches(data, 12)
        for i, b in enumerate(batches[:5]):
            state, _ = phases["actor_pretrain"].update(state, stack([b]), jax.random.key(i))
            agent.pretrain_actor_update(torch_batch(b, cfg.timeouts), recorder.take(2))  # temperature, soft BC
        compare("edac actor pretrain", edac_pairs(state, agent))
        state = state.replace(soft_returns=jnp.asarray(soft_returns))  # in place of on_start's computed returns
        for i, b in enumerate(batches[5:10]):
            state, _ = phases["critic_pretrain"].update(state, stack([b]), jax.random.key(10 + i))
            agent.pretrain_critic_update(torch_batch(b, cfg.timeouts), torch.from_numpy(soft_returns[b["idx"]]))
        for i, b in enumerate(batches[10:]):
            state, _ = phases["offline_rl"].update(state, stack([b]), jax.random.key(20 + i))
            agent.update(torch_batch(b, cfg.timeouts), recorder.take(3))
        assert not recorder.draws
        compare("edac pretrain + rl", edac_pairs(state, agent))


# ----------------------------------------------------------------------------------------------------- ReBRAC


def assert_moved(before, after, groups) -> None:
    """Every group of arrays (names starting with one of `groups`) changed in the updates: agreement is not two
    sides standing still."""
    old = {name: ours for name, ours, _ in before}
    for group in groups:
        change = max(float(np.max(np.abs(ours - old[name]))) for name, ours, _ in after if name.startswith(group))
        assert change > 1e-5, f"{group}: the updates did not change it ({change:.1e})"


def critic_pairs(prefix: str, params, critics):
    return [p for i, c in enumerate(critics) for p in mlp_pairs(
        f"{prefix}{i}", params["params"]["VmapCritic_0"]["MLP_0"], torch_layers(c, nn.Linear),
        torch_layers(c, nn.LayerNorm), member=i)]


def rebrac_pairs(state, agent: ref.ReBRAC):
    pairs = []
    for tag, actor_params, critic_params, actor, critics in (
        ("", state.actor.params, state.critic.params, agent.actor, agent.critics),
        ("target.", state.actor.target, state.critic.target, agent.actor_target, agent.critics_target),
    ):
        pairs += mlp_pairs(f"{tag}actor", actor_params["params"]["MLP_0"], torch_layers(actor, nn.Linear), [])
        pairs += critic_pairs(f"{tag}critic", critic_params, critics)
    return pairs


def test_rebrac_rl_update_matches_torch():
    """10 offline-RL updates (5 calls: the critics on both minibatches, the actor and every target after the first),
    with both behaviour penalties on and the dataset's next actions in the critic's target."""
    from offrl_jax.data.device import next_actions

    data = dataset()
    data["next_actions"] = np.asarray(next_actions(jnp.asarray(data["actions"]), jnp.asarray(data["terminals"]),
                                                   jnp.asarray(data["timeouts"])))
    with float64():
        cfg = make_config("rebrac", "walker2d", hidden=(32, 32, 32), policy_noise=0.0, timeouts="stop")
        assert (cfg.actor_beta, cfg.critic_beta, cfg.policy_delay) == (0.05, 0.1, 2)
        algo = make_algorithm(cfg, OBS, ACT, ROWS)
        state = to64(algo.init(jax.random.key(0)))
        agent = ref.ReBRAC(cfg.actor_beta, cfg.critic_beta, cfg.gamma, cfg.tau, cfg.policy_delay, cfg.actor_lr,
                           cfg.critic_lr, OBS, ACT, cfg.hidden, cfg.layer_norm_affine, cfg.layer_norm_eps)
        copy_in(rebrac_pairs(state, agent))
        before = rebrac_pairs(state, agent)
        b = minibatches(data, 1, seed=7)[0]
        s, a = torch_batch(b, "stop")[:2]
        with torch.no_grad():
            ours_q = algo.critic.apply(state.critic.params, jnp.asarray(b["observations"]), jnp.asarray(b["actions"]))
            torch_q = ref.ensemble_q(agent.critics, s, a).numpy()
            np.testing.assert_allclose(np.asarray(ours_q), torch_q, rtol=0, atol=1e-12)
        state = delayed_rl_updates(algo, state, data,
                                   lambda b: agent.update(torch_batch(b, "stop"), torch.tensor(b["next_actions"])))
        compare("rebrac rl", rebrac_pairs(state, agent))
        assert_moved(before, rebrac_pairs(state, agent), ("actor", "critic", "target.actor", "target.critic"))


# -------------------------------------------------------------------------------------------------------- IQL


def iql_pairs(state, agent: ref.IQL):
    pairs = mlp_pairs("actor", state.actor.params["params"]["MLP_0"], torch_layers(agent.actor, nn.Linear), [])
    if not agent.deterministic:
        pairs.append(("actor.log_std", np.asarray(state.actor.params["params"]["log_std"]), agent.log_std))
    pairs += critic_pairs("critic", state.critic.params, agent.critics)
    pairs += critic_pairs("target.critic", state.critic.target, agent.critics_target)
    pairs += mlp_pairs("value", state.value.params["params"]["MLP_0"], torch_layers(agent.value, nn.Linear), [])
    return pairs


@pytest.mark.parametrize("env", ["halfcheetah", "hopper"])  # a Gaussian actor; CORL's deterministic hopper actor
def test_iql_rl_update_matches_torch(env):
    """10 IQL updates (V, then Q with V(s') from before the V step and its Polyak, then advantage-weighted regression
    with the actor's cosine learning rate over 20 steps, so the schedule shows)."""
    data = dataset()
    with float64():
        cfg = make_config("iql", env, hidden=(32, 32), actor_lr_decay=20, timeouts="stop")
        assert cfg.actor_lr == cfg.critic_lr == cfg.value_lr and cfg.deterministic == (env == "hopper")
        algo = make_algorithm(cfg, OBS, ACT, ROWS)
        state = to64(algo.init(jax.random.key(0)))
        agent = ref.IQL(cfg.expectile, cfg.beta, cfg.gamma, cfg.tau, cfg.actor_lr, cfg.actor_lr_decay,
                        cfg.deterministic, OBS, ACT, cfg.hidden)
        copy_in(iql_pairs(state, agent))
        with torch.no_grad():  # a log_std away from 0, so that the Gaussian's gradient through it is exercised
            agent.log_std.copy_(torch.linspace(-0.5, 0.3, ACT))
        if not cfg.deterministic:
            params = state.actor.params
            params = {"params": params["params"] | {"log_std": jnp.linspace(-0.5, 0.3, ACT)}}
            state = state.replace(actor=state.actor.replace(params=params))
        before = iql_pairs(state, agent)
        update = jax.jit(algo.phases(20_000)[-1].update)
        for i, b in enumerate(minibatches(data, 10)):
            state, _ = update(state, stack([b]), jax.random.key(i))
            agent.update(torch_batch(b, "stop"))
        compare(f"iql rl ({env})", iql_pairs(state, agent))
        assert_moved(before, iql_pairs(state, agent), ("actor", "critic", "target.critic", "value"))


# ------------------------------------------------------------------------------------------------------- AWAC


def awac_pairs(state, agent: ref.AWAC):
    pairs = mlp_pairs("actor", state.actor.params["params"]["MLP_0"], torch_layers(agent.actor, nn.Linear), [])
    pairs.append(("actor.log_std", np.asarray(state.actor.params["params"]["log_std"]), agent.actor._log_std))
    pairs += critic_pairs("critic", state.critic.params, agent.critics)
    pairs += critic_pairs("target.critic", state.critic.target, agent.critics_target)
    return pairs


@pytest.mark.parametrize("awac_lambda", [None, 0.003])  # hopper's 0.3333: no weight clipped at first; 0.003: 1 in 6
def test_awac_rl_update_matches_torch(awac_lambda, monkeypatch):
    """10 AWAC updates (the twin critics on a sampled next action without entropy, then the actor's exp(A / lambda)
    weighted likelihood with A against a sampled action under the updated critics, then the targets), with the
    policy's two draws per update recorded on our side and fed to CORL's."""
    recorder = _NoiseRecorder()
    monkeypatch.setattr(awac, "jax", recorder)
    data = dataset()
    with float64():
        cfg = make_config("awac", "hopper", hidden=(32, 32, 32), awac_lambda=awac_lambda)
        assert (cfg.awac_lambda, cfg.max_weight, cfg.actor_lr, cfg.critic_lr) == (
            awac_lambda or 0.3333, 100.0, 3e-4, 3e-4)
        algo = make_algorithm(cfg, OBS, ACT, ROWS)
        state = to64(algo.init(jax.random.key(0)))
        agent = ref.AWAC(cfg.awac_lambda, cfg.gamma, cfg.tau, cfg.actor_lr, OBS, ACT, cfg.hidden, cfg.max_weight)
        log_std = np.linspace(-0.5, 0.3, ACT)  # away from 0, so that the gradient through it is exercised
        params = {"params": state.actor.params["params"] | {"log_std": jnp.asarray(log_std)}}
        state = state.replace(actor=state.actor.replace(params=params))
        copy_in(awac_pairs(state, agent))
        before = awac_pairs(state, agent)
        b = minibatches(data, 1, seed=7)[0]
        s, a = torch_batch(b, cfg.timeouts)[:2]
        with torch.no_grad():
            ours_q = algo.critic.apply(state.critic.params, jnp.asarray(b["observations"]), jnp.asarray(b["actions"]))
            np.testing.assert_allclose(np.asarray(ours_q), ref.ensemble_q(agent.critics, s, a).numpy(), rtol=0,
                                       atol=1e-12)
            mean, _ = algo.actor.apply(state.actor.params, jnp.asarray(b["observations"]))
            np.testing.assert_allclose(np.asarray(mean), agent.actor._get_policy(s).loc.numpy(), rtol=0, atol=1e-12)
        phase = algo.phases(20_000)[-1]
        assert phase.name == "offline_rl" and phase.updates_per_call == 1
        for i, b in enumerate(minibatches(data, 10)):
            state, _ = phase.update(state, stack([b]), jax.random.key(i))  # eagerly: the noise is recorded
            agent.update(torch_batch(b, cfg.timeouts), recorder.take(2))  # TD target's, then the actor's
        assert not recorder.draws
        compare(f"awac rl (lambda {cfg.awac_lambda})", awac_pairs(state, agent))
        assert_moved(before, awac_pairs(state, agent), ("actor", "critic", "target.critic"))


# ---------------------------------------------------------------------------------------------------- CQL, Cal-QL

CQL_ACTIONS = 4


def calql_pairs(state, agent: ref.CalQL):
    pairs = mlp_pairs("actor", state.actor.params["params"]["MLP_0"], torch_layers(agent.actor, nn.Linear), [])
    pairs += critic_pairs("critic", state.critic.params, agent.critics)
    pairs += critic_pairs("target.critic", state.critic.target, agent.critics_target)
    return pairs + [("log_alpha", np.asarray(state.log_alpha.params), agent.log_alpha)]


@pytest.mark.parametrize("algo", ["calql", "cql"])
def test_calql_rl_update_matches_torch(algo, monkeypatch):
    """10 simultaneous updates of CORL's Cal-QL (and, without the bound, its CQL): temperature, actor and critic
    losses from the incoming state, the importance-sampled penalty over random actions and policy actions at s and
    s', the policy terms bounded by the rows' returns for Cal-QL; Polyak.  The returns are drawn around the initial
    Q-values, so that the bound binds for some rows and not for others."""
    recorder, uniforms = _NoiseRecorder(), []
    monkeypatch.setattr(nets, "jax", recorder)
    from offrl_jax.algos import cql

    def recorded_uniform(*args):
        draw = cql_uniform(*args)
        uniforms.append(torch.tensor(np.asarray(draw)))
        return draw

    cql_uniform = cql.uniform_actions
    monkeypatch.setattr(cql, "uniform_actions", recorded_uniform)
    data = dataset()
    data["returns"] = 0.3 * np.random.default_rng(5).normal(size=ROWS)
    with float64():
        cfg = make_config(algo, preset="authors", hidden=(32, 32), actor_hidden=(32, 32, 32), actor_layer_norm=False,
                          critic_layer_norm=False, cql_actions=CQL_ACTIONS)
        assert (cfg.simultaneous_update, cfg.backup_entropy, cfg.calibration, cfg.timeouts, cfg.tanh_log_det) == (
            True, False, algo == "calql", "bootstrap", "exact")
        assert cfg.alpha_lr == cfg.actor_lr and cfg.log_std_bounds == (-20.0, 2.0) and cfg.log_alpha_bound == 0
        model = make_algorithm(cfg, OBS, ACT, ROWS)
        state = to64(model.init(jax.random.key(0)))
        agent = ref.CalQL(OBS, ACT, cfg.hidden, cfg.actor_hidden, cfg.actor_lr, cfg.critic_lr, cfg.gamma, cfg.tau,
                          cfg.cql_alpha, cfg.cql_temperature, cfg.log_std_offset, calibrate=cfg.calibration)
        copy_in(calql_pairs(state, agent))
        before = calql_pairs(state, agent)
        phase = model.phases(50_000)[-1]
        assert phase.name == "offline_rl" and phase.updates_per_call == 1
        rates = []
        for i, b in enumerate(minibatches(data, 10)):
            state, metrics = phase.update(state, stack([b]), jax.random.key(i))  # eagerly: the noise is recorded
            rates.append(float(metrics.get("calibration_rate", 0.5)))
            noise = recorder.take(3) + recorder.take(2, (B, CQL_ACTIONS, ACT))
            (random_actions,) = uniforms
            uniforms.clear()
            agent.update(torch_batch(b, cfg.timeouts), torch.tensor(b["returns"]), noise, random_actions)
        assert not recorder.draws
        assert 0.1 < np.mean(rates) < 0.9, rates  # the bound binds for some policy actions, not for all
        compare(f"{algo} rl", calql_pairs(state, agent))
        assert_moved(before, calql_pairs(state, agent), ("actor", "critic", "target.critic", "log_alpha"))
