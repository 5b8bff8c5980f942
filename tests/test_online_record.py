"""The online transitions as datasets (`offrl_jax.online.record`): appended per chunk, cut back on a resume, read
back by the D4RL reader as a dataset of the env."""
import numpy as np
import pytest

from offrl_jax.data.readers import read_d4rl_hdf5
from offrl_jax.online.record import dataset_path, record, record_chunk


def rows(members: int, start: int, n: int) -> dict[str, np.ndarray]:
    """n env steps of each member, every value its member * 1000 + env step (hopper's dims)."""
    t = (np.arange(members)[:, None] * 1000 + start + np.arange(n)[None]).astype(np.float32)
    ends = ((start + np.arange(n)) % 4 == 3).astype(np.float32)[None].repeat(members, 0)  # every 4th step ends
    return {"observations": t[..., None].repeat(11, -1), "next_observations": t[..., None].repeat(11, -1) + 1,
            "actions": np.tanh(t[..., None].repeat(3, -1)), "rewards": t, "terminals": ends,
            "timeouts": np.zeros_like(ends)}


def test_chunks_append_and_a_resume_cuts_back_to_its_env_step(tmp_path):
    paths = [dataset_path(tmp_path, "hopper", "pretrained", s) for s in (0, 1)]
    assert paths[1] == tmp_path / "online" / "hopper-pretrained-seed1.hdf5"
    record(paths, 0, rows(2, 0, 6))
    record(paths, 6, rows(2, 6, 6))
    record(paths, 6, rows(2, 6, 2))  # a resume from env step 6: rows 8-11 of the stopped run are gone
    ds = read_d4rl_hdf5(paths[1])
    assert ds.env == "hopper" and len(ds.rewards) == 8
    np.testing.assert_array_equal(ds.rewards, 1000 + np.arange(8))
    np.testing.assert_array_equal(ds.terminals, [0, 0, 0, 1, 0, 0, 0, 1])
    np.testing.assert_array_equal(ds.next_observations[:, 0], 1001 + np.arange(8))
    with pytest.raises(ValueError, match="holds 8 env steps, but the online phase goes on from 10"):
        record(paths, 10, rows(2, 10, 2))


def test_a_file_that_cannot_go_on_gets_one_line_and_nothing_is_written(tmp_path):
    message = record_chunk(tmp_path, "hopper", [("scratch", 3)], 12, rows(1, 6, 6))
    assert message == ("online transitions not recorded: " + str(tmp_path / "online" / "hopper-scratch-seed3.hdf5")
                       + ": missing, and the online phase is at env step 6")
    assert not (tmp_path / "online").exists()
    assert record_chunk(tmp_path, "hopper", [("scratch", 3)], 6, rows(1, 0, 6)) is None
    assert read_d4rl_hdf5(dataset_path(tmp_path, "hopper", "scratch", 3)).rewards.shape == (6,)


def test_a_file_held_by_a_reader_stops_the_recording_with_one_line(tmp_path):
    import h5py

    assert record_chunk(tmp_path, "hopper", [("scratch", 0)], 6, rows(1, 0, 6)) is None
    with h5py.File(dataset_path(tmp_path, "hopper", "scratch", 0), "r"):  # an offline run reading it meanwhile
        message = record_chunk(tmp_path, "hopper", [("scratch", 0)], 12, rows(1, 6, 6))
    assert message.startswith("online transitions not recorded: ") and "\n" not in message
    assert read_d4rl_hdf5(dataset_path(tmp_path, "hopper", "scratch", 0)).rewards.shape == (6,)
