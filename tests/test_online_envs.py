"""One env per member on the host, the collector of blocks, exploration, and the pieces composed: hopper, random
and fixed actions, a few hundred steps."""
import gymnasium as gym
import jax.numpy as jnp
import numpy as np
import pytest

from offrl_jax.data.returns import returns_to_go
from offrl_jax.online.buffer import device_rows, insert, member_rows, new_buffer
from offrl_jax.online.envs import (
    MemberEnvs,
    NonFiniteObservation,
    collect,
    exploration_keys,
    exploration_policy,
    reset_seed,
)
from offrl_jax.online.returns import episode_returns

A = np.testing.assert_allclose


def random_policy(members, act_dim=3, seed=0):
    """Uniform actions, a pure function of (seed, env step), the same for every member."""
    def policy(obs, step):
        rng = np.random.default_rng([seed, step])
        return np.repeat(rng.uniform(-1, 1, (1, act_dim)), members, axis=0)
    return policy


def blocks(envs, policy, k, n):
    parts = [collect(envs, policy, k) for _ in range(n)]
    return {f: np.concatenate([p[0][f] for p in parts], axis=1) for f in parts[0][0]}, [e for p in parts for e in p[1]]


def test_hopper_random_policy_blocks_are_consistent_transitions():
    envs = MemberEnvs("hopper", seeds=(0, 1))
    rows, episodes = blocks(envs, random_policy(2), k=100, n=3)
    assert rows["observations"].shape == (2, 300, 11) and rows["actions"].shape == (2, 300, 3)
    assert rows["rewards"].shape == rows["terminals"].shape == rows["timeouts"].shape == (2, 300)
    assert all(v.dtype == np.float32 for v in rows.values())
    ends = np.maximum(rows["terminals"], rows["timeouts"]) > 0
    assert rows["terminals"].sum() > 0 and rows["timeouts"].sum() == 0  # a random hopper falls long before 1000 steps
    for m in range(2):
        goes_on = ~ends[m, :-1]  # block boundaries included: the next block starts where this one stopped
        A(rows["next_observations"][m, :-1][goes_on], rows["observations"][m, 1:][goes_on])
        assert not np.allclose(rows["next_observations"][m, :-1][~goes_on], rows["observations"][m, 1:][~goes_on])
        # every ended episode: its return is the sum of its rewards, its end where the flags say
        mine = [e for e in episodes if e.member == m]
        assert [e.end_step - 1 for e in mine] == np.flatnonzero(ends[m]).tolist()
        start = 0
        for e in mine:
            A(e.return_, rows["rewards"][m, start:e.end_step].sum(), rtol=1e-5)
            assert e.length == e.end_step - start and e.terminal
            start = e.end_step
    assert envs.step_count == 300
    assert not np.allclose(rows["observations"][0, 0], rows["observations"][1, 0])  # seeds 0, 1: other starts
    envs.close()


def test_what_a_member_collects_is_a_function_of_its_seed_and_actions():
    a = MemberEnvs("hopper", seeds=(3, 5))
    b = MemberEnvs("hopper", seeds=(5,))
    rows_a, _ = blocks(a, random_policy(2), k=50, n=2)
    rows_b, _ = blocks(b, random_policy(1), k=100, n=1)  # other block sizes, same steps
    for f in rows_a:
        A(rows_a[f][1], rows_b[f][0])
    assert reset_seed(5, 0) != reset_seed(5, 1) and reset_seed(5, 0) != reset_seed(6, 0)


def test_time_limit_gives_time_outs_with_the_real_next_observation():
    envs = MemberEnvs("hopper", seeds=(0,), make=lambda: gym.make("Hopper-v5", max_episode_steps=5))
    assert envs.horizon == 5
    rows, episodes = collect(envs, lambda obs, step: np.zeros((1, 3)), 12)
    A(rows["timeouts"][0], [0, 0, 0, 0, 1] * 2 + [0, 0])
    assert not rows["terminals"].any()
    assert [(e.length, e.terminal, e.end_step) for e in episodes] == [(5, False, 5), (5, False, 10)]
    # s_5 is recorded as the time-out's next observation; the next row starts from the reset
    assert not np.allclose(rows["next_observations"][0, 4], rows["observations"][0, 5])
    A(rows["observations"][0, 0], rows["observations"][0, 5], atol=0.02)  # both reset states: near the start pose


class NaNAtStep(gym.Wrapper):
    def __init__(self, env, at):
        super().__init__(env)
        self.at, self.steps = at, 0

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.steps += 1
        return (obs * np.nan if self.steps == self.at else obs), reward, terminated, truncated, info


def test_a_non_finite_observation_names_member_and_step():
    made = iter([gym.make("Hopper-v5", max_episode_steps=50),
                 NaNAtStep(gym.make("Hopper-v5", max_episode_steps=50), at=3)])
    envs = MemberEnvs("hopper", seeds=(0, 1), make=lambda: next(made))
    with pytest.raises(NonFiniteObservation, match=r"member 1 \(seed 1\).* at env step 2"):
        collect(envs, lambda obs, step: np.zeros((2, 3)), 10)


def test_a_diverged_member_is_not_stepped_and_the_others_go_on():
    healthy, mixed = MemberEnvs("hopper", seeds=(0, 1)), MemberEnvs("hopper", seeds=(0, 1))
    start = mixed.observations.copy()
    actions = lambda obs, step: np.full((2, 3), 0.3, np.float32)  # noqa: E731
    nan_for_1 = lambda obs, step: np.array([[0.3] * 3, [np.nan] * 3], np.float32)  # noqa: E731
    block, _ = collect(mixed, nan_for_1, 5)
    expected, _ = collect(healthy, actions, 5)
    for field in block:  # member 0 steps as if member 1 were healthy
        np.testing.assert_array_equal(block[field][0], expected[field][0])
    assert np.isnan(block["next_observations"][1]).all() and np.isnan(block["rewards"][1]).all()
    assert (block["observations"][1] == start[1]).all() and not block["terminals"][1].any()
    assert block["timeouts"][1].all()  # nothing of it is under way: its buffer waits for no episode's end
    np.testing.assert_array_equal(mixed.observations[1], start[1])  # its env stayed where it was


def test_bad_actions_and_block_sizes_are_refused():
    envs = MemberEnvs("hopper", seeds=(0, 1))
    with pytest.raises(ValueError, match=r"actions of shape \(2, 3\)"):
        envs.step(np.zeros((1, 3)))
    with pytest.raises(ValueError, match="at least one step"):
        collect(envs, random_policy(2), 0)


def test_exploration_noise_is_a_pure_function_of_seed_and_step():
    # act = 0.5 everywhere: with noise 0 the actions are 0.5; with noise, clipped to [-1, 1] and keyed by (seed, step)
    act = lambda state, obs: jnp.full((3,), 0.5) + 0.0 * state  # noqa: E731
    states, obs = jnp.zeros((2, 3)), np.zeros((2, 11), np.float32)
    mean, std = np.zeros(11, np.float32), np.ones(11, np.float32)
    keys = exploration_keys((7, 7))
    A(exploration_policy(act, mean, std, 0.0)(states, keys, obs, 4), np.full((2, 3), 0.5))
    assert np.abs(np.asarray(exploration_policy(act, mean, std, 10.0)(states, keys, obs, 4))).max() <= 1.0
    noisy = exploration_policy(act, mean, std, 0.1)
    a4 = np.asarray(noisy(states, keys, obs, 4))
    assert 0 < np.abs(a4 - 0.5).max() < 0.5
    A(a4[0], a4[1])  # the same seed, the same step: the same noise
    assert not np.allclose(a4, noisy(states, keys, obs, 5))
    assert not np.allclose(noisy(states, exploration_keys((7, 8)), obs, 4)[1], a4[1])


def test_collected_blocks_fill_the_buffer_with_the_episodes_returns():
    # hopper, random actions: collect, put in device form, insert; every ended episode's rows hold its MC returns
    envs = MemberEnvs("hopper", seeds=(0, 1))
    buf = new_buffer(2, capacity=2_000, obs_dim=11, act_dim=3, gamma=0.99, horizon=envs.horizon)
    mean, std = np.full(11, 0.5, np.float32), np.full(11, 2.0, np.float32)
    raw = []
    for _ in range(4):
        block, _ = collect(envs, random_policy(2), 50)
        raw.append(block)
        buf = insert(buf, device_rows(block, mean, std))
    rewards = np.concatenate([b["rewards"] for b in raw], axis=1)
    terminals = np.concatenate([b["terminals"] for b in raw], axis=1)
    for m in range(2):
        rows = member_rows(buf, m)
        A(rows["observations"], (np.concatenate([b["observations"][m] for b in raw]) - 0.5) / 2.0, rtol=1e-5)
        ends = np.flatnonzero(terminals[m])
        assert int(buf.pending[m]) == 199 - ends[-1]
        A(rows["returns"][:ends[0] + 1], episode_returns(rewards[m, :ends[0] + 1], True, 0.99), rtol=1e-5)
        # every ended episode's, as the offline returns of the whole stream give them
        offline = returns_to_go(rewards[m], terminals[m], np.zeros(200), 0.99)
        A(rows["returns"][:ends[-1] + 1], offline[:ends[-1] + 1], rtol=1e-5)
        assert not rows["returns"][ends[-1] + 1:].any()  # the pending rows: not yet known


@pytest.mark.parametrize("env, save_at", [("hopper", 30), ("door", 30), ("door", 100)])
def test_saved_envs_step_on_exactly_as_the_envs_they_were_saved_from(env, save_at):
    """Mid-episode (time limit 50, so episodes end on both sides of the save): the restored envs collect the same
    block, episodes and all, as the envs that went on; door with its D4RL reward wrapper, as fine-tuning makes it,
    saved in its first episode and after two resets (each places the door anew: a model field, not the state)."""
    from offrl_jax.envs.adroit import with_original_reward
    from offrl_jax.envs.registry import get_env_spec, make_env

    make_env(env).close()  # registers the Adroit envs
    spec = get_env_spec(env)
    make = lambda: with_original_reward(gym.make(spec.gym_id, max_episode_steps=50))  # noqa: E731
    envs = MemberEnvs(env, seeds=(0, 1), make=make)
    blocks(envs, random_policy(2, spec.act_dim), save_at, 1)
    saved = envs.state()
    went_on = blocks(envs, random_policy(2, spec.act_dim), 40, 2)
    restored = MemberEnvs(env, seeds=(0, 1), make=make)
    restored.restore(saved)
    assert restored.step_count == save_at
    again = blocks(restored, random_policy(2, spec.act_dim), 40, 2)
    for f in went_on[0]:
        np.testing.assert_array_equal(again[0][f], went_on[0][f])
    assert again[1] == went_on[1] and len(went_on[1]) >= 2


def test_envs_that_are_not_mujoco_cannot_be_saved():
    class Still(gym.Env):
        observation_space = gym.spaces.Box(-1.0, 1.0, (11,))
        action_space = gym.spaces.Box(-1.0, 1.0, (3,))

        def reset(self, seed=None, options=None):
            return np.zeros(11, np.float32), {}

        def step(self, action):
            return np.zeros(11, np.float32), 0.0, False, False, {}

    if "OfflineRLStill-v0" not in gym.registry:
        gym.register("OfflineRLStill-v0", entry_point=Still, max_episode_steps=5)
    envs = MemberEnvs("hopper", seeds=(0,), make=lambda: gym.make("OfflineRLStill-v0"))
    assert envs.state() is None
