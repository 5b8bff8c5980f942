"""`data.catalogue`: `load` by name / path (generator faked), and the CLI (`list`, `info`, `generate`) including
its error contract: exit status 2, one line on stderr starting with "error:", no traceback."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import types
import warnings
from pathlib import Path

import h5py
import numpy as np
import pytest

from offrl_jax.data import catalogue
from offrl_jax.data.dataset import DatasetError
from tests.entry import run_module

REPO = Path(__file__).resolve().parents[1]


def run_cli(*args, env=None):
    return run_module("offrl_jax.data", *args, cwd=REPO, timeout=120, env=env)


def assert_cli_error(result, *fragments):
    assert result.returncode == 2, (result.returncode, result.stderr)
    assert result.stderr.startswith("error:") and "Traceback" not in result.stderr, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    for fragment in fragments:
        assert fragment in result.stderr, result.stderr


def write_d4rl(path, T=20, obs_dim=11, act_dim=3, nan=False, big_action=False):
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(T, obs_dim))
    actions = rng.uniform(-1, 1, (T, act_dim))
    if nan:
        obs[3, 2] = np.nan
    if big_action:
        actions[0, 0] = 3.0
    timeouts = np.zeros(T, bool)
    timeouts[9] = True
    with h5py.File(path, "w") as f:
        for k, v in dict(observations=obs, actions=actions, rewards=np.ones(T), terminals=np.zeros(T, bool),
                         timeouts=timeouts).items():
            f.create_dataset(k, data=v, compression="gzip")
    return path


# ------------------------------------------------------------------------------------------------------ load()
def test_known_names():
    for env in ("hopper", "halfcheetah", "walker2d"):
        for kind in ("random", "medium", "medium-replay", "full-replay", "expert", "medium-expert"):
            assert f"{env}-{kind}" in catalogue.KNOWN
    assert {"door-human", "door-cloned"} <= set(catalogue.KNOWN)


def test_load_unknown_name():
    with pytest.raises(DatasetError, match="known names: .*hopper-medium"):
        catalogue.load("hopper-mediocre")


def test_load_generates_once_then_reads_cache(tmp_path, monkeypatch):
    """A missing generated name calls `offrl_jax.data.generate.generate` (faked here: writes a Minari dataset with
    minari itself into the cache), then later loads read the cache without generating again."""
    import gymnasium as gym
    import minari
    from minari.data_collector import EpisodeBuffer

    monkeypatch.setenv("OFFRL_JAX_CACHE", str(tmp_path / "cache"))
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    calls = []

    def fake_generate(name, transitions=None, out_dir=None, seed=0, shown_as=None):
        calls.append((name, transitions, out_dir, seed, shown_as))
        T = transitions
        rng = np.random.default_rng(seed)
        buffer = [EpisodeBuffer(observations=rng.normal(size=(T + 1, 11)).astype(np.float32),
                                actions=rng.uniform(-1, 1, (T, 3)).astype(np.float32), rewards=list(np.ones(T)),
                                terminations=[False] * T, truncations=[False] * (T - 1) + [True])]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ds = minari.create_dataset_from_buffers(f"gen/{name}-v0", buffer, env=gym.spec("Hopper-v5"))
        out = Path(out_dir) if out_dir is not None else catalogue.cached_path(name)
        out.parent.mkdir(parents=True, exist_ok=True)
        Path(ds.storage.data_path).parent.rename(out)
        return out

    monkeypatch.setitem(sys.modules, "offrl_jax.data.generate", types.SimpleNamespace(generate=fake_generate))
    with pytest.raises(DatasetError, match="not generated yet"):
        catalogue.load("hopper-medium", generate_if_missing=False)
    # a capped load of a dataset that is not cached generates just that many transitions, and not into the cache
    ds = catalogue.load("hopper-medium", max_transitions=30)
    assert (len(ds), ds.env, ds.name) == (30, "hopper", "hopper-medium") and len(calls) == 1
    assert calls[0][1] == 30 and calls[0][2] is not None and not Path(calls[0][2]).exists()  # a deleted temporary
    assert "not cached" in calls[0][4]  # what its [generate] line names instead of the deleted directory
    assert not catalogue.is_cached("hopper-medium")
    # a full load generates into the cache; a capped load then takes the first rows of the cached one
    T = 40
    calls.clear()
    monkeypatch.setitem(sys.modules, "offrl_jax.data.generate", types.SimpleNamespace(
        generate=lambda name, transitions=None, out_dir=None, seed=0: fake_generate(name, T, out_dir, seed)))
    assert len(catalogue.load("hopper-medium")) == 40 and catalogue.is_cached("hopper-medium")
    assert len(catalogue.load("hopper-medium", max_transitions=30)) == 30 and len(calls) == 1
    assert not catalogue.is_cached("hopper-expert")


def test_load_without_generator(tmp_path, monkeypatch):
    monkeypatch.setenv("OFFRL_JAX_CACHE", str(tmp_path))
    monkeypatch.setitem(sys.modules, "offrl_jax.data.generate", None)  # import fails
    with pytest.raises(DatasetError, match="generator is not available"):
        catalogue.load("walker2d-random", max_transitions=10)


def test_load_path(tmp_path):
    ds = catalogue.load(write_d4rl(tmp_path / "hopper-small.hdf5"))
    assert (len(ds), ds.env, len(ds.episode_returns())) == (20, "hopper", 2)


# ------------------------------------------------------------------------------------------------------ CLI
@pytest.fixture(scope="module")
def door_available():
    if not catalogue.door_human_path().is_file():
        pytest.skip(f"shared door demonstrations not found at {catalogue.door_human_path()}")


def test_cli_info_door_human(door_available):
    result = run_cli("info", "door-human")
    assert result.returncode == 0, result.stderr
    info = json.loads(result.stdout)
    assert (info["transitions"], info["episodes"], info["obs_dim"], info["act_dim"]) == (6729, 25, 39, 28)
    assert info["env"] == "door" and info["normalized_score"] == pytest.approx(
        100 * (info["mean_episode_return"] + 84.52) / (2880.5693 + 84.52))
    assert result.stderr.startswith("warning:") and "clipped" in result.stderr and "Traceback" not in result.stderr


def test_cli_info_file(tmp_path):
    path = write_d4rl(tmp_path / "some.hdf5", obs_dim=17, act_dim=6)
    result = run_cli("info", path)
    assert result.returncode == 0, result.stderr
    info = json.loads(result.stdout)
    assert (info["transitions"], info["episodes"], info["mean_episode_return"]) == (20, 2, 10.0)
    assert info["env"] is None and info["normalized_score"] is None  # 17/6: halfcheetah or walker2d


def test_cli_list(tmp_path):
    result = run_cli("list", env={"OFFRL_JAX_CACHE": str(tmp_path)})
    assert result.returncode == 0, result.stderr
    first, *rest = result.stdout.splitlines()
    lines = {line.split()[0]: line for line in rest}
    assert first.startswith("cache: ")
    assert set(lines) == set(catalogue.KNOWN) and "not cached" in lines["hopper-medium"]
    assert lines["door-human"].split()[1] == "shipped"


def test_cli_shared_dir_override(tmp_path):
    assert_cli_error(run_cli("info", "door-human", env={"OFFRL_JAX_SHARED": str(tmp_path)}), "no such file",
                     str(tmp_path))


@pytest.mark.parametrize("case", ["missing", "nan", "actions", "unknown", "not-generated", "generate-unknown"])
def test_cli_errors(tmp_path, case):
    env = {"OFFRL_JAX_CACHE": str(tmp_path / "cache")}
    args, fragments = {
        "missing": (("info", tmp_path / "absent.hdf5"), ("no such file",)),
        "nan": (("info", write_d4rl(tmp_path / "d.hdf5", nan=True)), ("observations contains 1 non-finite",)),
        "actions": (("info", write_d4rl(tmp_path / "hopper.hdf5", big_action=True)), ("outside", "--clip-actions")),
        "unknown": (("info", "hopper-mediocre"), ("known names",)),
        "not-generated": (("info", "hopper-expert"), ("generate hopper-expert",)),
        "generate-unknown": (("generate", "door-human"), ("not a generated dataset",)),
    }[case]
    assert_cli_error(run_cli(*args, env=env), *fragments)


def test_cli_clip_actions_flag(tmp_path):
    result = run_cli("info", write_d4rl(tmp_path / "hopper.hdf5", big_action=True), "--clip-actions")
    assert result.returncode == 0 and json.loads(result.stdout)["env"] == "hopper"
    assert result.stderr.strip() == f"warning: {tmp_path / 'hopper.hdf5'}: clipped 1 action values to [-1, 1] " \
                                    "(max |a| was 3)"


def test_cli_usage_error():
    assert_cli_error(run_cli("bogus"), "invalid choice")


def test_door_human_ships_with_the_package_and_needs_no_shared_folder(tmp_path):
    """From a directory with no ../shared and no $OFFRL_JAX_SHARED: the packaged copy (DAPG, Apache-2.0)."""
    env = {k: v for k, v in os.environ.items() if k != "OFFRL_JAX_SHARED"}
    result = subprocess.run([sys.executable, "-m", "offrl_jax.data", "info", "door-human"], cwd=tmp_path,
                            env=env | {"PYTHONPATH": str(REPO)}, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    info = json.loads(result.stdout)
    assert info["transitions"] == 6729 and info["episodes"] == 25
    assert catalogue.PACKAGED.is_file() and (catalogue.PACKAGED.parent / "README.md").is_file()


def test_an_npz_with_d4rl_keys_reads_as_a_d4rl_file(tmp_path):
    rng = np.random.default_rng(0)
    T = 30
    terminals = np.zeros(T)
    terminals[9] = 1
    path = tmp_path / "mine.npz"
    np.savez(path, observations=rng.normal(size=(T, 11)), actions=rng.uniform(-1, 1, (T, 3)),
             rewards=rng.normal(size=T), terminals=terminals)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # no timeouts key: inferred, with a warning
        ds = catalogue.load(path)
    assert ds.env == "hopper" and len(ds) == T and ds.terminals.sum() == 1


def test_list_shows_the_cache_root(tmp_path):
    result = run_cli("list", env={"OFFRL_JAX_CACHE": str(tmp_path)})
    assert result.returncode == 0 and result.stdout.splitlines()[0].startswith(f"cache: {tmp_path}")
