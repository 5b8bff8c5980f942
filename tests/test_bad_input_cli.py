"""Every bad-input case of the reliability contract through a CLI: `error: <file>: <problem>`, exit 2, one line.

(missing file, NaN, out-of-bounds actions and unknown names are in test_datasets_cli.py; invalid hyper-parameters
and unknown env/algorithm names through the experiment CLI in test_experiments.py.)
"""
import pytest

from tests.test_datasets_cli import assert_cli_error, run_cli
from tests.test_readers import d4rl_arrays, write_h5, write_npz


def missing_key(tmp_path):
    arrays = d4rl_arrays()
    del arrays["rewards"]
    return write_h5(tmp_path / "hopper-x.hdf5", arrays), "rewards"


def different_lengths(tmp_path):
    arrays = d4rl_arrays()
    arrays["rewards"] = arrays["rewards"][:-3]
    return write_h5(tmp_path / "hopper-x.hdf5", arrays), "rewards"


def empty(tmp_path):
    return write_h5(tmp_path / "hopper-x.hdf5", d4rl_arrays(T=0)), "empty"


def corrupt(tmp_path):
    path = write_h5(tmp_path / "hopper-x.hdf5", d4rl_arrays(T=2000))
    path.write_bytes(path.read_bytes()[:5000])
    return path, "not a readable HDF5 file"


def zero_length_episode(tmp_path):
    return write_npz(tmp_path / "door.npz", lengths=(10, 0, 20)), "length 0"


def minari_without_metadata(tmp_path):
    data = tmp_path / "minari-ds" / "data"
    data.mkdir(parents=True)
    write_h5(data / "main_data.hdf5", {})
    return tmp_path / "minari-ds", "metadata"


@pytest.mark.parametrize("make", [missing_key, different_lengths, empty, corrupt, zero_length_episode,
                                  minari_without_metadata])
def test_cli_rejects_with_one_line(tmp_path, make):
    path, fragment = make(tmp_path)
    assert_cli_error(run_cli("info", path), str(path), fragment)


def test_experiment_cli_rejects_dims_that_do_not_match_the_chosen_env(tmp_path):
    from tests.test_experiments import cli

    path = write_h5(tmp_path / "data.hdf5", d4rl_arrays(obs_dim=17, act_dim=6))  # walker2d-shaped data
    result = cli("--env", "hopper", "--dataset-path", path, "--out", tmp_path / "out", timeout=120)
    assert result.returncode == 2 and "Traceback" not in result.stderr
    last = result.stderr.strip().splitlines()[-1]
    assert last.startswith(f"error: {path}") and "hopper" in last, result.stderr
    assert not (tmp_path / "out").exists()
