"""The evaluator: reused envs give the same returns as fresh ones, threads never share an env, and stepping the envs
in threads gives the serial returns."""
import threading

import jax.numpy as jnp
import numpy as np

from offrl_jax.envs import evaluate as ev


def _linear_policy():
    """A per-seed linear policy tanh(obs @ W_s) on hopper (obs 11, act 3); states: W of shape (S, 11, 3)."""
    policy = ev.make_policy(lambda w, obs: jnp.tanh(obs @ w), np.zeros(11), np.ones(11))
    weights = jnp.asarray(np.random.default_rng(0).normal(scale=0.3, size=(2, 11, 3)), jnp.float32)
    return policy, weights


def test_reused_envs_match_fresh_envs():
    policy, weights = _linear_policy()
    ev._POOL.__dict__.clear()
    fresh = ev.evaluate(policy, weights, "hopper", episodes=2, seed=3)
    pool = ev.env_pool("hopper", 4)
    ev.evaluate(policy, weights, "hopper", episodes=1, seed=7)  # other seeds and a smaller count in between
    again = ev.evaluate(policy, weights, "hopper", episodes=2, seed=3)
    assert fresh.shape == (2, 2)
    np.testing.assert_array_equal(fresh, again)
    assert [id(e) for e in ev.env_pool("hopper", 4)] == [id(e) for e in pool]  # the same envs, not new ones
    assert fresh[0, 0] != fresh[1, 0]  # different seeds' policies -> different returns: the seeds are not mixed up


def test_threads_get_their_own_envs():
    mine = ev.env_pool("hopper", 1)[0]
    theirs = []
    t = threading.Thread(target=lambda: theirs.append(ev.env_pool("hopper", 1)[0]))
    t.start()
    t.join()
    assert theirs and theirs[0] is not mine


def test_threaded_stepping_gives_the_serial_returns():
    policy, weights = _linear_policy()
    serial = ev.evaluate(policy, weights, "hopper", episodes=3, seed=5, workers=1)
    threaded = ev.evaluate(policy, weights, "hopper", episodes=3, seed=5, workers=4)
    np.testing.assert_array_equal(serial, threaded)
