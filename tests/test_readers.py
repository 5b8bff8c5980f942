"""Readers: D4RL HDF5 (plain, gzip, with/without next_observations), Minari directories written by `minari` itself,
the shared Adroit door demonstrations, and one test per kind of bad input (one-line `DatasetError` naming the file)."""
from __future__ import annotations

import json
import shutil
import warnings

import h5py
import numpy as np
import pytest

from offrl_jax.data.catalogue import door_human_path
from offrl_jax.data.dataset import DatasetError
from offrl_jax.data.readers import infer_env, load_dataset_path, read_d4rl_hdf5, read_door_npz, read_minari, validate


def d4rl_arrays(T=40, obs_dim=11, act_dim=3, seed=0):
    """Two episodes ending in a terminal (row 14) and a time-out (row 29), a third cut by the dataset end."""
    rng = np.random.default_rng(seed)
    terminals = np.zeros(T, bool)
    timeouts = np.zeros(T, bool)
    if T > 29:
        terminals[14], timeouts[29] = True, True
    return dict(observations=rng.normal(size=(T, obs_dim)), actions=rng.uniform(-1, 1, (T, act_dim)),
                rewards=rng.normal(size=T), terminals=terminals, timeouts=timeouts)


def write_h5(path, arrays, compression=None):
    with h5py.File(path, "w") as f:
        for k, v in arrays.items():
            f.create_dataset(k, data=v, compression=compression)
    return path


def assert_one_line(err: pytest.ExceptionInfo, path, *fragments):
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith(str(path)), msg
    for fragment in fragments:
        assert fragment in msg, msg


# ------------------------------------------------------------------------------------------------------ D4RL
@pytest.mark.parametrize("compression", [None, "gzip"])
def test_d4rl_with_next_observations(tmp_path, compression):
    arrays = d4rl_arrays()
    arrays["next_observations"] = arrays["observations"] + 1.0
    path = write_h5(tmp_path / "hopper-test.hdf5", arrays, compression)
    if compression:
        with h5py.File(path) as f:
            assert f["observations"].compression == "gzip"
    ds = read_d4rl_hdf5(path)
    assert ds.env == "hopper" and len(ds) == 40 and ds.observations.dtype == np.float32
    np.testing.assert_allclose(ds.next_observations, arrays["next_observations"], rtol=1e-6)
    assert ds.terminals.dtype == np.float32 and set(np.unique(ds.terminals)) == {0.0, 1.0}
    assert ds.terminals[14] == 1 and ds.timeouts[29] == 1 and ds.timeouts.sum() == 1
    assert len(ds.episode_returns()) == 3


def test_d4rl_without_next_observations_or_timeouts(tmp_path):
    arrays = d4rl_arrays()
    path = write_h5(tmp_path / "data.h5", arrays, "gzip")
    ds = read_d4rl_hdf5(path)
    obs = arrays["observations"].astype(np.float32)
    inner = np.setdiff1d(np.arange(39), [14, 29])
    np.testing.assert_array_equal(ds.next_observations[inner], obs[inner + 1])
    for end in (14, 29, 39):  # no recorded successor: the row's own observation
        np.testing.assert_array_equal(ds.next_observations[end], obs[end])
    assert list(np.flatnonzero(ds.timeouts)) == [29, 39]  # the file's last step, cut inside its episode: a time-out
    del arrays["timeouts"]
    with pytest.warns(UserWarning, match="inferred 0 time-outs at hopper's 1000-step limit"):
        ds = read_d4rl_hdf5(write_h5(tmp_path / "no_timeouts.hdf5", arrays))
    assert list(np.flatnonzero(ds.timeouts)) == [39] and ds.terminals.sum() == 1
    arrays["next_observations"] = arrays["observations"] + 1.0  # a recorded successor: the last row is a real step
    with pytest.warns(UserWarning, match="inferred 0 time-outs"):
        assert read_d4rl_hdf5(write_h5(tmp_path / "with_next.hdf5", arrays)).timeouts.sum() == 0


def test_d4rl_without_timeouts_gets_them_at_the_time_limit(tmp_path):
    """Old D4RL files have no `timeouts`: a time-out after every 1000 rows without a terminal, so halfcheetah-like
    data (no terminals at all) is not read as one endless episode."""
    arrays = d4rl_arrays(T=2600, seed=1)
    arrays["terminals"][:] = False
    arrays["terminals"][1500] = True  # resets the step count: the next time-out is 1000 rows later
    del arrays["timeouts"]
    with pytest.warns(UserWarning, match="inferred 2 time-outs"):
        ds = read_d4rl_hdf5(write_h5(tmp_path / "hopper-old.hdf5", arrays))
    assert list(np.flatnonzero(ds.timeouts)) == [999, 2500, 2599]  # and the cut at the file's end
    ambiguous = d4rl_arrays(T=30, obs_dim=17, act_dim=6)  # halfcheetah or walker2d, and no name hint
    del ambiguous["timeouts"]
    with pytest.warns(UserWarning, match="env is unknown"):
        ds = read_d4rl_hdf5(write_h5(tmp_path / "data.hdf5", ambiguous))
    assert list(np.flatnonzero(ds.timeouts)) == [29]


def test_env_inference():
    assert infer_env(11, 3) == "hopper"
    assert infer_env(17, 6) is None  # halfcheetah and walker2d share these dims
    assert infer_env(17, 6, ("walker2d-medium-v2",)) == "walker2d"
    assert infer_env(17, 6, ("Walker2d-v5",)) == "walker2d"
    assert infer_env(17, 6, ("hopper-medium",)) is None  # a hint whose dims disagree is ignored
    assert infer_env(39, 28) == "door" and infer_env(39, 30) == "relocate"


# ------------------------------------------------------------------------------------------------------ Minari
@pytest.fixture(scope="module")
def minari_root(tmp_path_factory):
    """A Minari dataset of Hopper-v5 (random actions, 25-step limit: terminals and truncations), written by minari."""
    import gymnasium as gym
    import minari

    root = tmp_path_factory.mktemp("minari")
    with pytest.MonkeyPatch.context() as mp, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mp.setenv("MINARI_DATASETS_PATH", str(root))
        env = minari.DataCollector(gym.make("Hopper-v5", max_episode_steps=25))
        env.action_space.seed(0)
        for ep in range(6):
            env.reset(seed=ep)
            done = False
            while not done:
                _, _, term, trunc, _ = env.step(env.action_space.sample())
                done = term or trunc
        env.create_dataset(dataset_id="test/hopper/random-v0", algorithm_name="random")
        env.close()
    return root


def test_minari_matches_minari_load_dataset(minari_root, monkeypatch):
    import minari

    monkeypatch.setenv("MINARI_DATASETS_PATH", str(minari_root))
    ds = read_minari("test/hopper/random-v0")  # by id
    same = read_minari(minari_root / "test/hopper/random-v0")  # by directory
    np.testing.assert_array_equal(ds.observations, same.observations)
    episodes = list(minari.load_dataset("test/hopper/random-v0").iterate_episodes())
    assert ds.env == "hopper" and len(ds) == sum(len(ep.actions) for ep in episodes)
    assert len(ds.episode_returns()) == len(episodes) == 6
    cat = lambda f: np.concatenate([f(ep) for ep in episodes])  # noqa: E731
    np.testing.assert_allclose(ds.observations, cat(lambda ep: ep.observations[:-1]), rtol=1e-6)
    np.testing.assert_allclose(ds.next_observations, cat(lambda ep: ep.observations[1:]), rtol=1e-6)
    np.testing.assert_allclose(ds.actions, cat(lambda ep: ep.actions), rtol=1e-6)
    np.testing.assert_allclose(ds.rewards, cat(lambda ep: ep.rewards), rtol=1e-6)
    np.testing.assert_array_equal(ds.terminals, cat(lambda ep: ep.terminations))
    np.testing.assert_array_equal(ds.timeouts, cat(lambda ep: ep.truncations))
    assert ds.episode_ends.sum() == 6 and ds.terminals.sum() >= 1 and ds.timeouts.sum() >= 1
    np.testing.assert_allclose(ds.episode_returns(), [ep.rewards.sum() for ep in episodes], rtol=1e-5)


def _copy_minari(minari_root, tmp_path):
    return shutil.copytree(minari_root / "test/hopper/random-v0", tmp_path / "copy")


def test_minari_episode_of_length_zero(minari_root, tmp_path):
    path = _copy_minari(minari_root, tmp_path)
    with h5py.File(path / "data/main_data.hdf5", "a") as f:
        g = f.create_group("episode_6")
        g["observations"] = np.zeros((1, 11), np.float32)
        g["actions"] = np.zeros((0, 3), np.float32)
        for k in ("rewards", "terminations", "truncations"):
            g[k] = np.zeros(0)
    with pytest.raises(DatasetError) as err:
        read_minari(path)
    assert_one_line(err, path, "episode_6", "length 0")


@pytest.mark.parametrize("key", ["observations", "actions", "rewards", "terminations"])
def test_minari_episode_with_a_single_value_for_an_array(minari_root, tmp_path, key):
    path = _copy_minari(minari_root, tmp_path)
    with h5py.File(path / "data/main_data.hdf5", "a") as f:
        del f["episode_0"][key]
        f["episode_0"][key] = np.float32(0.0)
    with pytest.raises(DatasetError) as err:
        read_minari(path)
    assert_one_line(err, path, f"episode_0/{key}", "single value")


@pytest.mark.parametrize("key, flags, shown", [("terminations", [0.5], "0 or 1"), ("truncations", [np.nan], "0 or 1"),
                                               ("truncations", [2], "0 or 1"), ("terminations", "mid", "step 0 of")])
def test_minari_episode_flags_are_0_or_1_and_only_at_the_end(minari_root, tmp_path, key, flags, shown):
    """Cast to bool, 0.5, NaN or 2 would read as True: a 3-step episode would silently become three."""
    path = _copy_minari(minari_root, tmp_path)
    with h5py.File(path / "data/main_data.hdf5", "a") as f:
        x = np.asarray(f["episode_0"][key][()], np.float64)
        if flags == "mid":
            x[0] = 1  # an end flag before the episode's last step
        else:
            x[-1] = flags[0]
        del f["episode_0"][key]
        f["episode_0"][key] = x
    with pytest.raises(DatasetError) as err:
        read_minari(path)
    assert_one_line(err, path, f"episode_0/{key}", shown)


def test_minari_episode_group_with_another_name(minari_root, tmp_path):
    path = _copy_minari(minari_root, tmp_path)
    with h5py.File(path / "data/main_data.hdf5", "a") as f:
        f.create_group("episode_x")
    with pytest.raises(DatasetError) as err:
        read_minari(path)
    assert_one_line(err, path, "'episode_x'", "episode_0, episode_1")


def test_minari_without_metadata(minari_root, tmp_path):
    path = _copy_minari(minari_root, tmp_path)
    (path / "data/metadata.json").unlink()
    with pytest.raises(DatasetError) as err:
        load_dataset_path(path)
    assert_one_line(err, path, "metadata.json")


def test_minari_truncated_hdf5(minari_root, tmp_path):
    path = _copy_minari(minari_root, tmp_path)
    data = path / "data/main_data.hdf5"
    data.write_bytes(data.read_bytes()[:2000])
    with pytest.raises(DatasetError) as err:
        read_minari(path)
    assert_one_line(err, path, "not a readable HDF5 file")


def test_minari_dict_observation_space(tmp_path, monkeypatch):
    import gymnasium as gym
    import minari
    from minari.data_collector import EpisodeBuffer

    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path))
    T = 5
    buffer = [EpisodeBuffer(observations={"a": np.zeros((T + 1, 2), np.float32)}, actions=np.zeros((T, 1), np.float32),
                            rewards=list(np.ones(T)), terminations=[False] * T, truncations=[False] * (T - 1) + [True])]
    obs_space = gym.spaces.Dict({"a": gym.spaces.Box(-1, 1, (2,), np.float32)})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        minari.create_dataset_from_buffers("test/dict/obs-v0", buffer, action_space=gym.spaces.Box(-1, 1, (1,)),
                                           observation_space=obs_space)
    with pytest.raises(DatasetError) as err:
        read_minari("test/dict/obs-v0")
    assert_one_line(err, tmp_path / "test/dict/obs-v0", "Dict", "Box")


def test_minari_unknown_id(tmp_path, monkeypatch):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path))
    with pytest.raises(DatasetError) as err:
        load_dataset_path("nope/hopper/medium-v0")
    assert_one_line(err, "nope/hopper/medium-v0", "no such file")


# ------------------------------------------------------------------------------------------------------ door npz
@pytest.fixture(scope="module")
def door_path():
    path = door_human_path()
    if not path.is_file():
        pytest.skip(f"shared door demonstrations not found at {path}")
    return path


def test_door_npz(door_path):
    with pytest.warns(UserWarning, match=r"clipped \d+ action values"):
        ds = read_door_npz(door_path)
    raw = np.load(door_path)
    assert (len(ds), len(ds.episode_returns()), ds.env) == (6729, 25, "door")
    assert ds.timeouts.sum() == 25 and ds.terminals.sum() == 0 and np.abs(ds.actions).max() <= 1.0
    ends = np.cumsum(raw["episode_lengths"]) - 1
    np.testing.assert_array_equal(np.flatnonzero(ds.timeouts), ends)
    obs = raw["observations"].astype(np.float32)
    np.testing.assert_array_equal(ds.next_observations[ends], obs[ends])
    inner = np.setdiff1d(np.arange(6728), ends)
    np.testing.assert_array_equal(ds.next_observations[inner], obs[inner + 1])
    np.testing.assert_allclose(ds.episode_returns(), np.add.reduceat(raw["rewards"], ends - raw["episode_lengths"] + 1))
    with pytest.warns(UserWarning, match="clipped"):
        assert len(load_dataset_path(door_path)) == 6729  # .npz demos clip by default


def test_door_npz_out_of_range_actions_strict(door_path):
    with pytest.raises(DatasetError) as err:
        read_door_npz(door_path, clip_actions=False)
    assert_one_line(err, door_path, "outside", "[-1, 1]", "clip_actions")


def write_npz(path, T=30, lengths=(10, 20), **overrides):
    rng = np.random.default_rng(0)
    arrays = dict(observations=rng.normal(size=(T, 39)), actions=rng.uniform(-1, 1, (T, 28)),
                  rewards=rng.normal(size=T), episode_lengths=np.array(lengths))
    arrays.update(overrides)
    np.savez(path, **{k: v for k, v in arrays.items() if v is not None})
    return path


@pytest.mark.parametrize("lengths, shown", [((10.5, 19.5), "10.5 at index 0"), ((1e30, 30), "1e+30 at index 0"),
                                            ((10, np.nan), "nan at index 1")])
def test_npz_episode_lengths_that_are_not_whole_numbers_are_one_line(tmp_path, lengths, shown):
    """Not truncated to whole steps, nor cast with a numpy warning on a line of its own."""
    path = write_npz(tmp_path / "demos.npz", lengths=lengths)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(DatasetError) as err:
            read_door_npz(path)
    assert_one_line(err, path, "whole numbers of steps", shown)


def test_npz_episode_of_length_zero(tmp_path):
    path = write_npz(tmp_path / "demos.npz", lengths=(10, 0, 20))
    with pytest.raises(DatasetError) as err:
        read_door_npz(path)
    assert_one_line(err, path, "length 0", "index 1")


def test_npz_lengths_do_not_sum(tmp_path):
    path = write_npz(tmp_path / "demos.npz", lengths=(10, 10))
    with pytest.raises(DatasetError) as err:
        read_door_npz(path)
    assert_one_line(err, path, "sum to 20", "30 transitions")


def test_npz_missing_key(tmp_path):
    path = write_npz(tmp_path / "demos.npz", episode_lengths=None)
    with pytest.raises(DatasetError) as err:
        read_door_npz(path)
    assert_one_line(err, path, "missing key 'episode_lengths'")


@pytest.mark.parametrize("dropped, named", [(("terminals",), "'terminals'"),
                                            (("terminals", "timeouts"), "'episode_lengths' (Adroit's demonstrations) "
                                                                        "or 'terminals' (D4RL's keys)")])
def test_an_npz_with_d4rl_keys_but_no_terminals_names_terminals_as_the_hdf5_twin(tmp_path, dropped, named):
    arrays = {k: v for k, v in d4rl_arrays().items() if k not in dropped}
    np.savez(tmp_path / "d.npz", **arrays)
    with pytest.raises(DatasetError) as err:
        read_door_npz(tmp_path / "d.npz")
    assert_one_line(err, tmp_path / "d.npz", f"missing key {named}")
    if dropped == ("terminals",):
        with pytest.raises(DatasetError) as err:
            read_d4rl_hdf5(write_h5(tmp_path / "d.hdf5", arrays))
        assert_one_line(err, tmp_path / "d.hdf5", "missing key 'terminals'")


# ------------------------------------------------------------------------------------------------------ bad input
def test_missing_file(tmp_path):
    for name in ("absent.hdf5", "absent.npz"):
        with pytest.raises(DatasetError) as err:
            load_dataset_path(tmp_path / name)
        assert_one_line(err, tmp_path / name, "no such file")


def test_missing_key(tmp_path):
    arrays = d4rl_arrays()
    del arrays["rewards"]
    path = write_h5(tmp_path / "d.hdf5", arrays)
    with pytest.raises(DatasetError) as err:
        read_d4rl_hdf5(path)
    assert_one_line(err, path, "missing key 'rewards'")


def test_different_lengths(tmp_path):
    arrays = d4rl_arrays()
    arrays["actions"] = arrays["actions"][:-3]
    path = write_h5(tmp_path / "d.hdf5", arrays)
    with pytest.raises(DatasetError) as err:
        read_d4rl_hdf5(path)
    assert_one_line(err, path, "different lengths", "observations=40", "actions=37")


@pytest.mark.parametrize("field", ["observations", "actions", "rewards", "next_observations"])
def test_non_finite_values(tmp_path, field):
    arrays = d4rl_arrays()
    arrays["next_observations"] = arrays["observations"].copy()
    arrays[field] = arrays[field].copy()
    arrays[field].reshape(-1)[[1, 5, 7]] = [np.nan, np.inf, -np.inf]
    path = write_h5(tmp_path / "d.hdf5", arrays)
    with pytest.raises(DatasetError) as err:
        read_d4rl_hdf5(path)
    assert_one_line(err, path, f"{field} contains 3 non-finite")


def test_empty_dataset(tmp_path):
    path = write_h5(tmp_path / "d.hdf5", d4rl_arrays(T=0))
    with pytest.raises(DatasetError) as err:
        read_d4rl_hdf5(path)
    assert_one_line(err, path, "empty")


def test_dims_do_not_match_env(tmp_path):
    path = write_h5(tmp_path / "d.hdf5", d4rl_arrays(obs_dim=12))
    with pytest.raises(DatasetError) as err:
        read_d4rl_hdf5(path, env="hopper")
    assert_one_line(err, path, "obs_dim=12", "'hopper'", "obs_dim=11")
    assert read_d4rl_hdf5(path).env is None  # not inferred when no env has these dims


def test_actions_out_of_bounds(tmp_path):
    arrays = d4rl_arrays()
    arrays["actions"][[0, 3], [0, 1]] = [1.5, -2.0]
    path = write_h5(tmp_path / "d.hdf5", arrays)
    with pytest.raises(DatasetError) as err:
        read_d4rl_hdf5(path, env="hopper")
    assert_one_line(err, path, "2 action values", "[-1, 1]")
    with pytest.warns(UserWarning, match="clipped 2 action values"):
        ds = read_d4rl_hdf5(path, env="hopper", clip_actions=True)
    assert ds.actions.max() <= 1 and ds.actions.min() >= -1 and ds.actions[0, 0] == 1.0


def test_truncated_hdf5(tmp_path):
    path = write_h5(tmp_path / "d.hdf5", d4rl_arrays(T=2000))
    path.write_bytes(path.read_bytes()[:5000])
    with pytest.raises(DatasetError) as err:
        read_d4rl_hdf5(path)
    assert_one_line(err, path, "not a readable HDF5 file")
    garbage = tmp_path / "g.h5"
    garbage.write_text(json.dumps({"not": "hdf5"}))
    with pytest.raises(DatasetError) as err:
        load_dataset_path(garbage)
    assert_one_line(err, garbage, "not a readable HDF5 file")


def test_validate_returns_float32(tmp_path):
    ds = read_d4rl_hdf5(write_h5(tmp_path / "d.hdf5", d4rl_arrays()))
    again = validate(ds, "x")
    assert all(getattr(again, f).dtype == np.float32 for f in ("observations", "actions", "rewards", "terminals"))


@pytest.mark.parametrize("meta, fragment", [
    ([1, 2], "not a JSON object"),
    (None, "not a JSON object"),
    ({"observation_space": 5}, "observation_space is not an object"),
    ({"observation_space": "{not json"}, "observation_space is not valid JSON"),
])
def test_minari_metadata_that_is_not_an_object(minari_root, tmp_path, meta, fragment):
    path = _copy_minari(minari_root, tmp_path)
    (path / "data/metadata.json").write_text(json.dumps(meta))
    with pytest.raises(DatasetError) as err:
        read_minari(path)
    assert_one_line(err, path, fragment)


def test_minari_episode_that_is_not_a_group(minari_root, tmp_path):
    path = _copy_minari(minari_root, tmp_path)
    with h5py.File(path / "data/main_data.hdf5", "a") as f:
        f["episode_99"] = np.zeros(3)
    with pytest.raises(DatasetError) as err:
        read_minari(path)
    assert_one_line(err, path, "episode_99", "not an episode group")


@pytest.mark.parametrize("field", ["rewards", "terminals", "timeouts"])
def test_string_typed_arrays_name_the_file(tmp_path, field):
    arrays = d4rl_arrays()
    arrays[field] = np.array([b"1"] * len(arrays[field]))
    path = write_h5(tmp_path / "hopper-strings.hdf5", arrays)
    with pytest.raises(DatasetError) as err:
        read_d4rl_hdf5(path)
    assert_one_line(err, path, field, "not numbers")


def test_zero_byte_npz_names_the_file(tmp_path):
    path = tmp_path / "door.npz"
    path.write_bytes(b"")
    with pytest.raises(DatasetError) as err:
        read_door_npz(path)
    assert_one_line(err, path, "not a .npz file")


def test_an_npz_with_d4rl_keys_clips_its_actions_when_asked(tmp_path):
    arrays = d4rl_arrays()
    arrays["actions"][3, 1] = 1.5
    path = tmp_path / "oob.npz"
    np.savez(path, **arrays)
    with pytest.raises(DatasetError, match="clip_actions"):
        load_dataset_path(path)  # refused by default, as a D4RL file is
    with pytest.warns(UserWarning, match="clipped"):
        ds = load_dataset_path(path, clip_actions=True)
    assert ds.actions.max() <= 1.0


def test_a_value_beyond_float32_is_non_finite_in_one_line(tmp_path):
    """float64 rewards of 1e39 become inf in float32: refused as non-finite, without numpy's overflow warning."""
    arrays = d4rl_arrays()
    arrays["rewards"] = arrays["rewards"].astype(np.float64)
    arrays["rewards"][2] = 1e39
    path = write_h5(tmp_path / "d.hdf5", arrays)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(DatasetError) as err:
            read_d4rl_hdf5(path)
    assert_one_line(err, path, "rewards contains 1 non-finite", "beyond float32's range")


@pytest.mark.parametrize("arrays, shown", [
    (dict(observations=np.zeros((0, 39)), actions=np.zeros((0, 28)), rewards=np.zeros(0),
          episode_lengths=np.zeros(0, int)), "empty"),
    (dict(observations=np.float32(0), actions=np.float32(0), rewards=np.float32(0), episode_lengths=[1]),
     "observations has shape ()"),
])
def test_npz_demonstrations_empty_or_scalar_are_one_line(tmp_path, arrays, shown):
    path = tmp_path / "demos.npz"
    np.savez(path, **arrays)
    with pytest.raises(DatasetError) as err:
        load_dataset_path(path)
    assert_one_line(err, path, shown)


def test_an_npz_with_d4rl_keys_is_checked_against_the_env_it_is_given(tmp_path):
    """Named door, an .npz of other dims is refused; with no env its dims name one, when they can."""
    path = tmp_path / "odd.npz"
    np.savez(path, **d4rl_arrays(T=30, obs_dim=5, act_dim=2))
    with pytest.raises(DatasetError) as err:
        load_dataset_path(path, env="door")
    assert_one_line(err, path, "do not match env 'door'")
    assert load_dataset_path(path).env is None
    np.savez(path, **d4rl_arrays(T=30))
    assert load_dataset_path(path).env == "hopper"
