"""docs/howto.md's first recipe as written: your own numpy arrays in an .npz with D4RL's keys, checked by
`datasets info` and read back unchanged.  (The third recipe, load/evaluate/roll out, is tests/test_policy.py.)"""
import json

import numpy as np

from offrl_jax.data.readers import load_dataset_path

from .conftest import synthetic_dataset
from .test_datasets_cli import run_cli


def test_own_numpy_arrays_as_an_npz_with_d4rl_keys(tmp_path):
    ds = synthetic_dataset(600, episode_len=100)
    obs, act, rew, term, trunc = ds.observations, ds.actions, ds.rewards, ds.terminals, ds.timeouts
    path = tmp_path / "my-hopper.npz"
    np.savez(path, observations=obs, actions=act, rewards=rew, terminals=term, timeouts=trunc)  # as in the doc

    result = run_cli("info", path)
    assert result.returncode == 0, result.stderr
    info = json.loads(result.stdout)
    assert (info["env"], info["transitions"], info["obs_dim"], info["act_dim"]) == ("hopper", 600, 11, 3)
    assert info["episodes"] == len(ds.episode_returns())

    back = load_dataset_path(path)
    for name in ("observations", "actions", "rewards", "terminals", "timeouts"):
        np.testing.assert_array_equal(getattr(back, name), getattr(ds, name))
    inside = ~(ds.terminals.astype(bool) | ds.timeouts.astype(bool))  # no next_observations: the next row's
    inside[-1] = False
    np.testing.assert_array_equal(back.next_observations[inside], ds.next_observations[inside])
