"""The online pieces compose as docs/online.md plans: on hopper, S members collect a block with their policy plus
exploration noise, insert it, and run K * utd TD3+BC updates (max(MC, TD) target) from mixed minibatches, members
one after another as the driver runs them; a member of the program is the single run with its seed."""
import jax
import jax.numpy as jnp
import numpy as np

from offrl_jax.algos import make_algorithm, make_config
from offrl_jax.data.device import device_data
from offrl_jax.driver import CHUNK, INIT, over_members, seed_keys
from offrl_jax.online.buffer import device_rows, insert, new_buffer
from offrl_jax.online.envs import MemberEnvs, collect, exploration_keys, exploration_policy
from offrl_jax.online.sampling import Replay, sample

K, BATCH = 100, 32


def online_run(ds, seeds, blocks=2, warmup=K):
    config = make_config("td3bc", "hopper", hidden=(32, 32), pretrain="none", target="max_mc")
    algo = make_algorithm(config, ds.obs_dim, ds.act_dim, len(ds))
    form = device_data(ds, config.gamma)
    phase = algo.phases(1_000)[-1]
    replay = Replay("mix", 0.5, ended_only=True)
    calls = K // phase.updates_per_call  # utd 1

    def member(state, data, buffer, key, start):
        def body(state, u):
            k_batch, k_update = jax.random.split(jax.random.fold_in(key, u))
            batch = sample(k_batch, replay, data, buffer, (phase.updates_per_call, BATCH))
            state, metrics = phase.update(state, batch, k_update)
            return state, metrics | {"online": jnp.mean(batch["online"])}
        return jax.lax.scan(body, state, start + phase.updates_per_call * jnp.arange(calls))

    updates = jax.jit(over_members(member, (0, None, 0, 0, None), "map"))
    states = initial = jax.vmap(algo.init)(seed_keys(seeds, INIT, 0))
    envs = MemberEnvs("hopper", seeds)
    explore, explore_keys = exploration_policy(algo.act, form.obs_mean, form.obs_std, 0.1), exploration_keys(seeds)
    buffer = new_buffer(len(seeds), 1_200, ds.obs_dim, ds.act_dim, config.gamma, envs.horizon)
    run_keys, update, metrics, episodes = seed_keys(seeds, CHUNK), 0, None, []
    for _ in range(blocks):
        block, ended = collect(envs, lambda obs, t, s=states: explore(s, explore_keys, obs, t), K)
        episodes += ended
        buffer = insert(buffer, device_rows(block, form.obs_mean, form.obs_std), donate=True)
        if envs.step_count >= warmup:
            states, metrics = updates(states, form.arrays, buffer, run_keys, jnp.int32(update))
            update += K
    envs.close()
    return states, metrics, episodes, initial


def test_online_blocks_train_every_member_as_the_single_run_with_its_seed(tiny_dataset):
    states, metrics, episodes, initial = online_run(tiny_dataset, (0, 1))
    assert all(np.isfinite(np.asarray(m)).all() for m in jax.tree.leaves(metrics))
    assert metrics["critic_loss"].shape == (2, K // 2)
    np.testing.assert_allclose(np.asarray(metrics["online"]), 0.5)  # 16 of 32 rows: ended episodes exist
    assert any(not np.allclose(a, b) for a, b in zip(jax.tree.leaves(states), jax.tree.leaves(initial)))
    assert {e.member for e in episodes} == {0, 1}  # an untrained hopper falls: episodes end
    # member 1 of the program is the single run with seed 1: what it collects and what it learns
    single, single_metrics, single_episodes, _ = online_run(tiny_dataset, (1,))
    for a, b in zip(jax.tree.leaves(states), jax.tree.leaves(single)):
        np.testing.assert_array_equal(np.asarray(a)[1], np.asarray(b)[0])
    np.testing.assert_array_equal(metrics["critic_loss"][1], single_metrics["critic_loss"][0])
    assert [(e.length, e.return_) for e in episodes if e.member == 1] == [(e.length, e.return_)
                                                                         for e in single_episodes]
