"""The online buffer and the Monte-Carlo returns of online episodes, against values worked out by hand."""
import jax
import numpy as np
import pytest

from offrl_jax.data.returns import returns_to_go
from offrl_jax.online.buffer import check_block, device_rows, insert, member_rows, new_buffer
from offrl_jax.online.returns import episode_returns

A = np.testing.assert_allclose


def block(rewards, terminals=None, timeouts=None, obs_dim=1, act_dim=1):
    """A block for S members of K steps each: rewards (S, K); observations = rewards (a marker), actions = -rewards."""
    r = np.asarray(rewards, np.float32)
    zeros = np.zeros_like(r)
    return {"observations": r[..., None].repeat(obs_dim, -1), "next_observations": r[..., None].repeat(obs_dim, -1),
            "actions": -r[..., None].repeat(act_dim, -1), "rewards": r,
            "terminals": zeros if terminals is None else np.asarray(terminals, np.float32),
            "timeouts": zeros if timeouts is None else np.asarray(timeouts, np.float32)}


# ---------------------------------------------------------------------------------------- one episode's returns


def test_episode_returns_terminal():
    # gamma .5, rewards [1, 2, 3]: G2 = 3, G1 = 2 + .5*3 = 3.5, G0 = 1 + .5*3.5 = 2.75
    A(episode_returns([1.0, 2.0, 3.0], terminal=True, gamma=0.5), [2.75, 3.5, 3.0])


def test_episode_returns_time_out_gets_the_tail():
    # the time limit cut it: G2 = 3 / (1 - .5) = 6, G1 = 2 + .5*6 = 5, G0 = 1 + .5*5 = 3.5
    A(episode_returns([1.0, 2.0, 3.0], terminal=False, gamma=0.5), [3.5, 5.0, 6.0])
    # without the tail a time-out ends the sum like a terminal, as offline
    A(episode_returns([1.0, 2.0, 3.0], terminal=False, gamma=0.5, timeout_tail=False), [2.75, 3.5, 3.0])


def test_episode_returns_rejects_an_empty_episode():
    with pytest.raises(ValueError, match="at least one step"):
        episode_returns([], terminal=True, gamma=0.5)


# ---------------------------------------------------------------------------------------------------- the buffer


def test_insert_wraps_around_and_writes_returns_when_episodes_end():
    # capacity 4, blocks of K = 2, episodes of at most 3 steps, gamma .5.  Member 0:
    #   block 1: r 1, 2            -> ring [1, 2, ., .], both pending (their episode goes on)
    #   block 2: r 3 (terminal), 4 -> episode 1, 2, 3 ends: returns 2.75, 3.5, 3 (as above); 4 pending
    #   block 3: r 5 (time-out), 6 -> overwrites 1, 2: ring [5, 6, 3, 4]; episode 4, 5 ends: G5 = 5/.5 = 10,
    #                                 G4 = 4 + .5*10 = 9; 6 pending
    # Member 1: every step a terminal, so a row's return is its reward and nothing is pending.
    buf = new_buffer(2, capacity=4, obs_dim=1, act_dim=1, gamma=0.5, horizon=3)
    buf = insert(buf, block([[1, 2], [10, 20]], terminals=[[0, 0], [1, 1]]))
    assert buf.insert_at.tolist() == [2, 2] and buf.size.tolist() == [2, 2] and buf.pending.tolist() == [2, 0]
    A(buf.arrays["returns"][0], [0, 0, 0, 0])
    buf = insert(buf, block([[3, 4], [30, 40]], terminals=[[1, 0], [1, 1]]))
    assert buf.insert_at.tolist() == [0, 0] and buf.size.tolist() == [4, 4] and buf.pending.tolist() == [1, 0]
    A(buf.arrays["returns"][0], [2.75, 3.5, 3.0, 0.0])
    after_two = buf
    buf = insert(buf, block([[5, 6], [50, 60]], terminals=[[0, 0], [1, 1]], timeouts=[[1, 0], [0, 0]]))
    assert buf.insert_at.tolist() == [2, 2] and buf.size.tolist() == [4, 4] and buf.pending.tolist() == [1, 0]
    A(buf.arrays["rewards"][0], [5, 6, 3, 4])
    A(buf.arrays["returns"][0], [10.0, 0.0, 3.0, 9.0])
    A(buf.arrays["observations"][0, :, 0], [5, 6, 3, 4])
    A(buf.arrays["actions"][0, :, 0], [-5, -6, -3, -4])
    A(buf.arrays["timeouts"][0], [1, 0, 0, 0])
    A(buf.arrays["rewards"][1], [50, 60, 30, 40])
    A(buf.arrays["returns"][1], [50, 60, 30, 40])
    rows = member_rows(buf, 0)  # oldest first: ring position 2, 3, 0, 1
    A(rows["rewards"], [3, 4, 5, 6])
    A(rows["returns"], [3.0, 9.0, 10.0, 0.0])
    A(after_two.arrays["rewards"][0], [1, 2, 3, 4])  # insert is pure: the buffer passed in is unchanged
    donated = insert(after_two, block([[5, 6], [50, 60]], terminals=[[0, 0], [1, 1]], timeouts=[[1, 0], [0, 0]]),
                     donate=True)  # in place: the same buffer
    assert all((np.asarray(x) == np.asarray(y)).all() for x, y in zip(jax.tree.leaves(donated), jax.tree.leaves(buf)))


def test_partly_filled_member_rows():
    buf = insert(new_buffer(1, capacity=8, obs_dim=1, act_dim=1, gamma=0.5, horizon=3),
                 block([[1, 2, 3]], terminals=[[0, 1, 0]]))
    rows = member_rows(buf, 0)
    A(rows["rewards"], [1, 2, 3])
    A(rows["returns"], [2.0, 2.0, 0.0])  # 1 + .5*2 and 2 end an episode; 3's goes on
    assert int(buf.pending[0]) == 1 and int(buf.drawable(True)[0]) == 2 and int(buf.drawable(False)[0]) == 3


def test_a_block_that_ends_no_episode_leaves_the_pending_rows_unwritten():
    # horizon 5, blocks of 2, no episode ends in either block: the four rows stay pending, their returns 0 (the
    # second insert once wrote partial returns with a tail over the two rows pending before it), until a block ends
    # the episode: then 1 + .5*(2 + .5*(3 + .5*(4 + .5*5))) = 3.5625 for a terminal at reward 5
    buf = new_buffer(1, capacity=8, obs_dim=1, act_dim=1, gamma=0.5, horizon=5)
    buf = insert(buf, block([[1, 2]]))
    buf = insert(buf, block([[3, 4]]))
    assert int(buf.pending[0]) == 4
    A(member_rows(buf, 0)["returns"], [0, 0, 0, 0])
    buf = insert(buf, block([[5, 6]], terminals=[[1, 0]]))
    A(member_rows(buf, 0)["returns"], [3.5625, 5.125, 6.25, 6.5, 5.0, 0.0])


def test_returns_match_the_offline_returns_of_the_whole_stream():
    # random episodes of at most 5 steps, blocks of 3, a ring of 16 that wraps many times: every ended episode's
    # rows hold what returns_to_go of the whole stream gives them
    rng = np.random.default_rng(0)
    horizon, k, cap, steps = 5, 3, 16, 60
    rewards = rng.normal(size=steps).astype(np.float32)
    terminals, timeouts, length = np.zeros(steps, np.float32), np.zeros(steps, np.float32), 0
    for t in range(steps):
        length += 1
        if length == horizon or rng.random() < 0.2:
            (terminals if rng.random() < 0.5 else timeouts)[t] = 1.0
            length = 0
    buf = new_buffer(1, cap, 1, 1, gamma=0.9, horizon=horizon)
    for start in range(0, steps, k):
        part = slice(start, start + k)
        buf = insert(buf, block([rewards[part]], [terminals[part]], [timeouts[part]]))
    expected = np.asarray(returns_to_go(rewards, terminals, timeouts, 0.9))
    ended = int(buf.size[0] - buf.pending[0])
    A(member_rows(buf, 0)["returns"][:ended], expected[steps - cap:][:ended], rtol=1e-5)
    assert int(buf.pending[0]) == steps - 1 - np.flatnonzero(terminals + timeouts)[-1]


def test_check_block_rejects_a_ring_too_small_and_a_misshaped_block():
    buf = new_buffer(2, capacity=4, obs_dim=1, act_dim=1, gamma=0.5, horizon=3)
    with pytest.raises(ValueError, match="at least 5"):  # an episode of 3 steps ending in a block of 3: 2 + 3 rows
        check_block(buf, block([[1, 2, 3], [1, 2, 3]]))
    with pytest.raises(ValueError, match="'observations' has shape"):
        check_block(buf, block([[1, 2], [1, 2]], obs_dim=2))
    with pytest.raises(ValueError, match="needs rewards"):
        check_block(buf, {k: v for k, v in block([[1, 2], [1, 2]]).items() if k != "rewards"})


def test_device_rows_normalise_like_the_offline_data():
    raw = block([[2.0, 4.0]], obs_dim=2)
    rows = device_rows(raw, obs_mean=np.array([1.0, 0.0], np.float32), obs_std=np.array([2.0, 4.0], np.float32),
                       reward_scale=0.5)
    A(rows["observations"][0], [[0.5, 0.5], [1.5, 1.0]])  # (2 - 1)/2, 2/4; (4 - 1)/2, 4/4
    A(rows["next_observations"][0], rows["observations"][0])
    A(rows["rewards"][0], [1.0, 2.0])
    A(rows["actions"], raw["actions"])
    assert all(v.dtype == np.float32 for v in rows.values())


def test_a_buffer_round_trips_through_a_checkpoint(tmp_path):
    from offrl_jax.system.checkpoint import load_checkpoint, save_checkpoint

    buf = insert(new_buffer(2, capacity=5, obs_dim=1, act_dim=1, gamma=0.5, horizon=3),
                 block([[1, 2, 3], [4, 5, 6]], terminals=[[0, 1, 0], [0, 0, 1]]))
    save_checkpoint(tmp_path / "ckpt.msgpack", buf, update=7, seconds=1.0, history=[])
    template = new_buffer(2, capacity=5, obs_dim=1, act_dim=1, gamma=0.5, horizon=3)
    restored, update, _, _ = load_checkpoint(tmp_path / "ckpt.msgpack", template)
    assert update == 7 and restored.gamma == 0.5 and restored.horizon == 3
    for x, y in zip(jax.tree.leaves(restored), jax.tree.leaves(buf)):
        A(x, y)


def test_an_episode_longer_than_the_horizon_is_refused():
    buf = new_buffer(2, capacity=8, obs_dim=1, act_dim=1, gamma=0.5, horizon=3)
    buf = insert(buf, block([[1, 2], [1, 2]], terminals=[[0, 0], [0, 1]]))  # member 0: 2 steps running
    with pytest.raises(ValueError, match="member 0: an episode ran past the buffer's horizon of 3"):
        insert(buf, block([[3, 4], [3, 4]], terminals=[[0, 1], [0, 0]]))  # member 0's episode would be 4 steps
    with pytest.raises(ValueError, match="member 1: an episode ran past"):
        insert(buf, block([[3, 4, 5], [3, 4, 5]], terminals=[[1, 0, 0], [0, 0, 0]]))  # 3 steps, not ended
    insert(buf, block([[3, 4], [3, 4]], terminals=[[1, 0], [0, 0]]))  # 3 steps each: at the horizon, accepted
