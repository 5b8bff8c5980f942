"""Minibatches of the online phase: exact mixing counts, only filled (and, when asked, ended) rows, each member from
its own buffer; and the max(MC, TD) target on online rows."""
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from offrl_jax import losses as L
from offrl_jax.online.buffer import insert, new_buffer
from offrl_jax.online.sampling import Replay, draw_rows, sample
from tests.test_online_buffer import block

A = np.testing.assert_allclose
KEY = jax.random.PRNGKey(0)


def offline_data(rows=6):
    """Offline rows whose reward (and observation) is their index 0..rows-1."""
    b = block([np.arange(rows)])
    data = {f: jnp.asarray(v[0]) for f, v in b.items()}
    return data | {"returns": jnp.zeros(rows)}


def one_member(buf, m=0):
    return jax.tree.map(lambda x: x[m], buf)


def partly_filled():
    """Capacity 8, three rows filled with rewards 101, 102 (a terminal), 103 (pending: its episode goes on)."""
    buf = new_buffer(1, capacity=8, obs_dim=1, act_dim=1, gamma=0.5, horizon=3)
    return insert(buf, block([[101, 102, 103]], terminals=[[0, 1, 0]]))


def test_replay_checks_its_settings_and_counts_online_rows():
    with pytest.raises(ValueError, match="replay must be one of"):
        Replay("both")
    with pytest.raises(ValueError, match=r"in \[0, 1\]"):
        Replay("mix", 1.5)
    # round(f * B), halves up: .25 * 10 = 2.5 -> 3, .04 * 10 = .4 -> 0
    assert [Replay("mix", f).online_rows(10) for f in (0.0, 0.04, 0.25, 0.5, 1.0)] == [0, 0, 3, 5, 10]
    assert Replay("online-only").online_rows(10) == 10 and Replay("append").online_rows(10) is None


@pytest.mark.parametrize("fraction,count", [(0.25, 3), (0.5, 5), (0.0, 0), (1.0, 10)])
def test_mix_takes_exactly_round_f_b_online_rows_per_minibatch(fraction, count):
    batch = jax.jit(sample, static_argnums=(1, 4))(KEY, Replay("mix", fraction), offline_data(), one_member(
        partly_filled()), (50, 10))
    online = np.asarray(batch["online"]) > 0
    assert (online.sum(-1) == count).all()
    assert set(np.asarray(batch["rewards"])[online].tolist()) <= {101, 102, 103}
    assert set(np.asarray(batch["rewards"])[~online].tolist()) <= set(range(6))


def test_only_filled_rows_and_with_ended_only_only_ended_episodes():
    buf = one_member(partly_filled())
    every = np.asarray(sample(KEY, Replay("online-only"), offline_data(), buf, (1000,))["rewards"])
    assert set(every.tolist()) == {101, 102, 103}  # never an unfilled row (reward 0), every filled one
    ended = np.asarray(sample(KEY, Replay("online-only", ended_only=True), offline_data(), buf, (1000,))["rewards"])
    assert set(ended.tolist()) == {101, 102}  # 103's episode has not ended: its return is not known


def test_a_wrapped_ring_draws_its_newest_rows():
    buf = new_buffer(1, capacity=4, obs_dim=1, act_dim=1, gamma=0.5, horizon=1)
    for rewards in ([1, 2, 3], [4, 5, 6]):
        buf = insert(buf, block([rewards], terminals=[[1, 1, 1]]))
    drawn = np.asarray(sample(KEY, Replay("online-only"), offline_data(), one_member(buf), (1000,))["rewards"])
    assert set(drawn.tolist()) == {3, 4, 5, 6}


def test_fields_idx_and_online_flag_come_from_the_row_drawn():
    data, buf = offline_data(), one_member(partly_filled())
    batch = sample(KEY, Replay("mix", 0.5), data, buf, (200,))
    online = np.asarray(batch["online"]) > 0
    idx = np.asarray(batch["idx"])
    A(np.asarray(batch["rewards"])[~online], idx[~online])  # offline row i has reward i
    A(idx[online], 6 + np.asarray(batch["rewards"])[online] - 101)  # T + ring position; 101 is at position 0
    A(np.asarray(batch["observations"])[:, 0], batch["rewards"])
    A(np.asarray(batch["actions"])[:, 0], -np.asarray(batch["rewards"]))


def test_append_is_uniform_over_offline_and_drawable_online_rows():
    # 6 offline rows + 2 drawable online rows (ended_only): each of the 8 rows has probability 1/8
    batch = sample(KEY, Replay("append", ended_only=True), offline_data(), one_member(partly_filled()), (40_000,))
    counts = np.unique(np.asarray(batch["rewards"]), return_counts=True)
    assert counts[0].tolist() == [0, 1, 2, 3, 4, 5, 101, 102]
    A(counts[1] / 40_000, np.full(8, 1 / 8), atol=0.01)


def test_an_empty_buffer_leaves_every_row_offline():
    empty = one_member(new_buffer(1, capacity=8, obs_dim=1, act_dim=1, gamma=0.5, horizon=3))
    for replay in (Replay("mix"), Replay("append"), Replay("online-only")):
        batch = sample(KEY, replay, offline_data(), empty, (100,))
        assert not np.asarray(batch["online"]).any()
        assert set(np.asarray(batch["rewards"]).tolist()) == set(range(6))


def test_offline_rows_left_out_are_never_drawn():
    data = offline_data() | {"rows": jnp.asarray([1, 4], jnp.int32)}
    batch = sample(KEY, Replay("mix", 0.5), data, one_member(partly_filled()), (500,))
    online = np.asarray(batch["online"]) > 0
    assert set(np.asarray(batch["rewards"])[~online].tolist()) == {1, 4}


def test_draw_rows_is_a_pure_function_of_the_key():
    a = draw_rows(KEY, Replay("append"), (3, 7), 6, jnp.int32(2))
    b = draw_rows(KEY, Replay("append"), (3, 7), 6, jnp.int32(2))
    c = draw_rows(jax.random.PRNGKey(1), Replay("append"), (3, 7), 6, jnp.int32(2))
    assert all((np.asarray(x) == np.asarray(y)).all() for x, y in zip(a, b))
    assert any((np.asarray(x) != np.asarray(y)).any() for x, y in zip(a, c))


def test_each_member_draws_from_its_own_buffer_inside_jit():
    buf = new_buffer(2, capacity=8, obs_dim=1, act_dim=1, gamma=0.5, horizon=2)
    buf = insert(buf, block([[1, 2], [50, 60]], terminals=[[1, 1], [1, 1]]))
    keys = jax.random.split(KEY, 2)
    draw = jax.jit(jax.vmap(lambda k, b: sample(k, Replay("online-only"), offline_data(), b, (2, 100))))
    rewards = np.asarray(draw(keys, buf)["rewards"])
    assert rewards.shape == (2, 2, 100)
    assert set(rewards[0].ravel().tolist()) == {1, 2} and set(rewards[1].ravel().tolist()) == {50, 60}


def test_max_mc_target_lifts_online_rows_to_their_returns():
    # an ended online episode, rewards 1, 2, 3 (terminal), gamma .5: returns 2.75, 3.5, 3 (tests/test_online_buffer);
    # with a TD target of 3 everywhere, max(MC, TD) is 3 for rewards 1 and 3 and the MC return 3.5 for reward 2
    buf = insert(new_buffer(1, capacity=8, obs_dim=1, act_dim=1, gamma=0.5, horizon=3),
                 block([[1, 2, 3]], terminals=[[0, 0, 1]]))
    batch = sample(KEY, Replay("online-only", ended_only=True), offline_data(), one_member(buf), (300,))
    target = np.asarray(L.q_transformer_target(batch["returns"], jnp.full(300, 3.0)))
    expected = {1.0: 3.0, 2.0: 3.5, 3.0: 3.0}
    A(target, [expected[r] for r in np.asarray(batch["rewards"]).tolist()])
    assert set(np.asarray(batch["rewards"]).tolist()) == {1, 2, 3}
