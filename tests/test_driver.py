"""The driver end to end: phases chained, S seeds in one program, seed i of the program == a single run with seed i."""
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from offrl_jax.algos import make_algorithm, make_config
from offrl_jax.data.device import device_data
from offrl_jax.driver import Driver


def run(ds, algo_name, seeds, total=400, chunk=100, members=None, **overrides):
    config = make_config(algo_name, ds.env, **overrides)
    algo = make_algorithm(config, ds.obs_dim, ds.act_dim, len(ds))
    data = device_data(ds, config.gamma).arrays
    chunks = list(Driver(algo, data, seeds, batch_size=32, members=members).run(algo.phases(total), chunk))
    return algo, chunks


@pytest.mark.parametrize("pretrain", ["actor+critic", "none"])
def test_td3bc_runs_with_three_vmapped_seeds(tiny_dataset, pretrain):
    algo, chunks = run(tiny_dataset, "td3bc", (0, 1, 2), pretrain=pretrain, pretrain_updates=200, hidden=(32, 32))
    assert [c.update for c in chunks] == [100, 200, 300, 400]
    phases = [c.phase for c in chunks]
    assert phases == (["pretrain"] * 2 + ["offline_rl"] * 2 if pretrain != "none" else ["offline_rl"] * 4)
    for c in chunks:
        assert all(v.shape == (3,) for v in c.metrics.values())
        assert c.metrics["finite"].all()
    if pretrain == "actor+critic":  # the MC regression and BC both go down during pre-training
        assert (chunks[1].metrics["bc_loss"] < chunks[0].metrics["bc_loss"]).all()
        assert (chunks[1].metrics["critic_loss"] < chunks[0].metrics["critic_loss"]).all()
    seeds_differ = not np.allclose(chunks[-1].metrics["critic_loss"][0], chunks[-1].metrics["critic_loss"][1])
    assert seeds_differ


def test_vmapped_seed_equals_single_seed_run(tiny_dataset):
    kw = dict(pretrain="actor+critic", pretrain_updates=100, hidden=(32, 32))
    _, vmapped = run(tiny_dataset, "td3bc", (0, 1, 2), total=200, **kw)
    _, single = run(tiny_dataset, "td3bc", (1,), total=200, **kw)
    for a, b in zip(vmapped, single):
        for name in b.metrics:
            np.testing.assert_allclose(a.metrics[name][1], b.metrics[name][0], rtol=1e-4, atol=1e-5, err_msg=name)
    leaves_v = jax.tree.leaves(vmapped[-1].states)
    leaves_s = jax.tree.leaves(single[-1].states)
    for lv, ls in zip(leaves_v, leaves_s):
        np.testing.assert_allclose(lv[1], ls[0], rtol=1e-3, atol=1e-4)


def test_edac_soft_pretraining_computes_per_seed_soft_returns(tiny_dataset):
    algo, chunks = run(tiny_dataset, "edac", (0, 1), total=300, pretrain_updates=200, num_critics=3,
                       hidden=(32, 32))
    assert [c.phase for c in chunks] == ["actor_pretrain", "critic_pretrain", "offline_rl"]
    soft = np.asarray(chunks[-1].states.soft_returns)
    assert soft.shape == (2, len(tiny_dataset)) and np.isfinite(soft).all()
    assert not np.allclose(soft[0], soft[1])  # each seed's own actor and alpha
    hard = device_data(tiny_dataset, 0.99).arrays
    assert not np.allclose(soft[0], np.asarray(hard["returns"]))  # the entropy bonus is in there
    assert "diversity" in chunks[1].metrics and "mc_error" in chunks[1].metrics


def test_normalized_rewards_give_episode_returns_a_range_of_1000():
    from offrl_jax.data.dataset import Dataset
    # two episodes (a terminal at row 1, a time-out at row 4) with returns 1 + 3 = 4 and 2 + 2 + 2 = 6
    rewards = np.array([1, 3, 2, 2, 2], np.float32)
    terminals = np.array([0, 1, 0, 0, 0], np.float32)
    obs = np.zeros((5, 1), np.float32)
    ds = Dataset(obs, np.zeros((5, 1), np.float32), rewards, obs, terminals, np.array([0, 0, 0, 0, 1], np.float32),
                 env="hopper")
    assert ds.reward_scale() == 1000 / (6 - 4) == 500
    assert ds.select(slice(2, 5)).reward_scale() == 1.0  # one return: nothing to spread
    # a last episode that the data cuts off (return 2 so far) is left out, as CORL's loader does: one return left
    assert ds.select(slice(0, 3)).reward_scale() == 1.0 and list(ds.select(slice(0, 3)).episode_returns()) == [4, 2]
    plain = device_data(ds, 0.5).arrays
    scaled = device_data(ds, 0.5, normalize_reward=True).arrays
    np.testing.assert_allclose(np.asarray(scaled["rewards"]), 500 * rewards)
    np.testing.assert_allclose(np.asarray(scaled["returns"]), 500 * np.asarray(plain["returns"]), rtol=1e-6)
    np.testing.assert_allclose(np.asarray(plain["returns"])[:2], [1 + 0.5 * 3, 3])


def test_device_forms_are_made_once_per_discount_and_reward_scaling(tiny_dataset):
    from offrl_jax.data.device import DeviceForms

    forms = DeviceForms(tiny_dataset)
    data = forms(0.99)
    assert forms(0.99, False) is data  # the groups of a run share it
    assert forms(0.9) is not data and forms(0.99, True) is not data and len(forms.forms) == 3
    fresh = device_data(tiny_dataset, 0.99)
    assert list(data.arrays) == list(fresh.arrays)
    for name, array in fresh.arrays.items():
        np.testing.assert_array_equal(np.asarray(data.arrays[name]), np.asarray(array), err_msg=name)
    mean, std = tiny_dataset.obs_stats()
    np.testing.assert_array_equal(data.obs_mean, mean)
    np.testing.assert_array_equal(data.obs_std, std)
    np.testing.assert_allclose(np.asarray(data.arrays["observations"]) * std + mean, tiny_dataset.observations,
                               atol=1e-4)


@pytest.mark.parametrize("algo_name, name, values, kw", [
    ("td3bc", "alpha", (1.0, 10.0), dict(pretrain="actor+critic", pretrain_updates=100, hidden=(32, 32))),
    pytest.param("edac", "eta", (0.0, 5.0), dict(pretrain="actor+critic", pretrain_updates=100, num_critics=3,
                                                 hidden=(32, 32)), marks=pytest.mark.slow),  # the same mechanism
])
def test_vmapped_sweep_member_equals_single_run(tiny_dataset, algo_name, name, values, kw):
    """Member (value j, seed i) of a swept program equals a run with seed i and that value (the soft-return hook
    and the offline-RL phase included)."""
    config = make_config(algo_name, tiny_dataset.env, **kw, **{name: values[0]})
    algo = make_algorithm(config, tiny_dataset.obs_dim, tiny_dataset.act_dim, len(tiny_dataset))
    data = device_data(tiny_dataset, config.gamma).arrays
    driver = Driver(algo, data, (0, 1), batch_size=32, sweep=(name, values))
    swept = list(driver.run(algo.phases(200), 100))
    assert swept[-1].metrics["finite"].shape == (4,)
    _, single = run(tiny_dataset, algo_name, (1,), total=200, **kw, **{name: values[1]})
    for a, b in zip(swept, single):
        for metric in b.metrics:
            np.testing.assert_allclose(a.metrics[metric][3], b.metrics[metric][0], rtol=1e-4, atol=1e-5, err_msg=metric)
    assert not np.allclose(swept[-1].metrics["actor_loss"][1], swept[-1].metrics["actor_loss"][3])  # values differ


def test_unsweepable_field_is_refused(tiny_dataset):
    from offrl_jax.algos.common import with_hparams

    algo = make_algorithm(make_config("td3bc", "hopper"), 11, 3, 10)
    with pytest.raises(ValueError, match="'hidden' cannot be swept"):
        with_hparams(algo, hidden=(3,))


def test_evaluation_interval_does_not_change_training(tiny_dataset):
    """Randomness is a function of (seed, update): cutting the same run into chunks of 100 or of 300 updates (an
    evaluation interval that does not divide the pre-training phase, too) gives the same parameters."""
    config = make_config("td3bc", tiny_dataset.env, pretrain="actor+critic", pretrain_updates=200, hidden=(32, 32))
    algo = make_algorithm(config, tiny_dataset.obs_dim, tiny_dataset.act_dim, len(tiny_dataset))
    data = device_data(tiny_dataset, config.gamma).arrays

    def states_by_update(chunk):  # copied as they come: the next chunk donates (deletes) the states it is given
        driver = Driver(algo, data, (0, 1), batch_size=32)
        return {c.update: [np.array(x) for x in jax.tree.leaves(c.states)] for c in driver.run(algo.phases(600), chunk)}

    every_100, every_300 = states_by_update(100), states_by_update(300)
    assert sorted(every_300) == [200, 300, 600]
    for update in (200, 300, 600):
        for a, b in zip(every_100[update], every_300[update]):
            np.testing.assert_array_equal(a, b)


def leaves_as_they_come(driver, phases, chunk, states=None):
    """(update, every state leaf as numpy) per chunk: the next chunk donates (deletes) the states it is given."""
    return [(c.update, [np.array(x) for x in jax.tree.leaves(c.states)])
            for c in driver.run(phases, chunk, states=states)]


def to64(tree):
    return jax.tree.map(lambda x: jnp.asarray(x, jnp.float64) if jnp.issubdtype(x.dtype, jnp.floating) else x, tree)


def test_seed_of_a_batched_run_is_the_single_run_up_to_rounding_over_3000_updates(tiny_dataset):
    """Seed i of a 3-seed run against a single run with seed i, 1k pre-training + 2k TD3+BC updates.

    The keys are the same, so seeds run one after another (`lax.map`, the CPU's layout) give the single run's
    numbers, and batched seeds (`vmap`, a GPU's layout) differ only in how XLA rounds a batched matmul.  That gap is
    checked in float64, where it stays at rounding (~1e-14 of the largest leaf over 6k updates).  In float32 it does
    not: Adam's step m / (sqrt(v) + eps) is about lr * sign(g) for a near-zero gradient, so rounding noise in such a
    coordinate becomes a full step, and RL training carries it on (0.6% of a parameter after 3k updates on an AMD
    EPYC, 4.5% after 6k): batched seeds agree with single ones as runs on two machines do, in level, not in bits."""
    config = make_config("td3bc", tiny_dataset.env, pretrain="actor+critic", pretrain_updates=1000, hidden=(32, 32))
    algo = make_algorithm(config, tiny_dataset.obs_dim, tiny_dataset.act_dim, len(tiny_dataset))
    data = device_data(tiny_dataset, config.gamma).arrays
    phases = algo.phases(3000)
    single = leaves_as_they_come(Driver(algo, data, (1,), batch_size=32), phases, 1000)
    mapped = leaves_as_they_come(Driver(algo, data, (0, 1, 2), batch_size=32, members="map"), phases, 1000)
    for m, s in zip(mapped[-1][1], single[-1][1]):
        np.testing.assert_allclose(m[1], s[0], rtol=1e-6, atol=1e-7)
    with jax.enable_x64(True):
        runs = [Driver(algo, to64(data), seeds, batch_size=32, members=members)
                for seeds, members in (((0, 1, 2), "vmap"), ((1,), None))]
        vmapped, single64 = (leaves_as_they_come(d, phases, 1000, states=to64(d.init())) for d in runs)
    assert not jax.config.jax_enable_x64
    assert vmapped[-1][1][0].dtype == np.float64
    for (update, v), (_, s) in zip(vmapped, single64):
        gap = max(float(np.max(np.abs(a[1] - b[0])) / np.max(np.abs(b[0]))) for a, b in zip(v, s) if b.any())
        assert gap < 1e-12, (update, gap)


def test_a_chunk_runs_in_slices_that_change_nothing_but_when_the_caller_hears(tiny_dataset):
    """A chunk of 1,000 TD3+BC calls (2,000 updates) runs as 10 slices of 100 calls: the same parameters as ten
    chunks of 200 updates, its metrics their mean, `on_slice` called after each slice; what `on_slice` raises
    stops the run within the chunk."""
    from offrl_jax.driver import slice_calls
    assert [slice_calls(c) for c in (1, 200, 1000, 1250, 2477)] == [1, 200, 100, 125, 2477]
    config = make_config("td3bc", tiny_dataset.env, pretrain="none", hidden=(32, 32))
    algo = make_algorithm(config, tiny_dataset.obs_dim, tiny_dataset.act_dim, len(tiny_dataset))
    data = device_data(tiny_dataset, config.gamma).arrays
    heard = []
    (whole,) = [(c, [np.array(x) for x in jax.tree.leaves(c.states)])
                for c in Driver(algo, data, (0, 1), batch_size=32).run(algo.phases(2000), 2000, on_slice=heard.append)]
    assert heard == [200] * 10
    pieces = [(c.metrics, [np.array(x) for x in jax.tree.leaves(c.states)])
              for c in Driver(algo, data, (0, 1), batch_size=32).run(algo.phases(2000), 200)]
    for a, b in zip(whole[1], pieces[-1][1]):
        np.testing.assert_array_equal(a, b)
    for name, value in whole[0].metrics.items():
        expected = np.all([m[name] for m, _ in pieces], axis=0) if name == "finite" else \
            np.mean([m[name] for m, _ in pieces], axis=0)
        np.testing.assert_allclose(value, expected, rtol=1e-6, err_msg=name)

    def stop_after_three(updates):
        heard.append(updates)
        if len(heard) == 3:
            raise KeyboardInterrupt
    heard.clear()
    with pytest.raises(KeyboardInterrupt):
        list(Driver(algo, data, (0, 1), batch_size=32).run(algo.phases(2000), 2000, on_slice=stop_after_three))
    assert heard == [200] * 3


def test_what_an_algorithms_updates_read_is_declared_by_its_config_and_built_by_the_data_layer(tiny_dataset):
    """`Config.needs()` declares what the updates read beyond the device form; `for_updates` builds exactly that:
    ReBRAC's next actions and, with timeouts "drop", the rows that may be drawn; nothing more for TD3+BC."""
    from offrl_jax.algos.common import DataNeeds
    from offrl_jax.data.device import for_updates, next_actions

    arrays = device_data(tiny_dataset, 0.99).arrays
    assert make_config("td3bc", "hopper").needs() == DataNeeds()
    assert for_updates(arrays, DataNeeds()) is arrays
    assert make_config("td3bc", "hopper", target="max_mc").needs() == DataNeeds(returns=True)
    rebrac = make_config("rebrac", "hopper")
    assert rebrac.timeouts == "drop" and rebrac.needs() == DataNeeds(next_actions=True, cut_rows=False)
    built = for_updates(arrays, rebrac.needs())
    np.testing.assert_array_equal(built["next_actions"],
                                  next_actions(arrays["actions"], arrays["terminals"], arrays["timeouts"]))
    timeouts = np.asarray(arrays["timeouts"])
    assert timeouts.any() and not timeouts.all()
    np.testing.assert_array_equal(built["rows"], np.flatnonzero(timeouts == 0))
    kept = for_updates(arrays, make_config("rebrac", "hopper", timeouts="bootstrap").needs())
    assert "rows" not in kept and "next_actions" in kept
