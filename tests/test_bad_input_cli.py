"""Every bad-input case of the reliability contract through a CLI: `error: <file>: <problem>`, exit 2, one line.

(missing file, NaN, out-of-bounds actions and unknown names are in test_datasets_cli.py; invalid hyper-parameters
and unknown env/algorithm names through the experiment CLI in test_experiments.py; bad numbers, paths and choices
of every entry point in the one table of test_every_entry_point.py.)
"""
import shutil
from pathlib import Path

import numpy as np
import pytest

from tests.entry import run_module
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


def non_binary_terminals(tmp_path):
    arrays = d4rl_arrays()
    arrays["terminals"] = arrays["terminals"].astype(np.float32)
    arrays["terminals"][3] = 2.0  # once silently read as a terminal
    return write_h5(tmp_path / "hopper-x.hdf5", arrays), "terminals must be 0 or 1"


def nan_timeouts(tmp_path):
    arrays = d4rl_arrays()
    arrays["timeouts"] = arrays["timeouts"].astype(np.float32)
    arrays["timeouts"][3] = np.nan
    return write_h5(tmp_path / "hopper-x.hdf5", arrays), "timeouts must be 0 or 1"


def two_dimensional_timeouts(tmp_path):
    arrays = d4rl_arrays()
    arrays["timeouts"] = np.stack([arrays["timeouts"]] * 2, axis=1)
    return write_npz_d4rl(tmp_path / "hopper-x.npz", arrays), "timeouts has shape (40, 2)"


def write_npz_d4rl(path, arrays):
    np.savez(path, **arrays)
    return path


def zero_length_episode(tmp_path):
    return write_npz(tmp_path / "door.npz", lengths=(10, 0, 20)), "length 0"


def garbage_npz(tmp_path):
    path = tmp_path / "door.npz"
    path.write_bytes(bytes(range(256)) * 4)  # numpy would try this as a pickle and say so
    return path, "not a .npz file"


def minari_without_metadata(tmp_path):
    data = tmp_path / "minari-ds" / "data"
    data.mkdir(parents=True)
    write_h5(data / "main_data.hdf5", {})
    return tmp_path / "minari-ds", "metadata"


@pytest.mark.parametrize("make", [missing_key, different_lengths, empty, corrupt, non_binary_terminals, nan_timeouts,
                                  two_dimensional_timeouts, zero_length_episode, garbage_npz,
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


# ------------------------------------------------------------------------------------ every secondary entry point
def _one_line_error(module: str, *args: str, cwd=None):
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    result = run_module(module, *args, cwd=cwd or root)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr and lines and lines[-1].startswith("error:"), result.stderr
    return lines[-1]


def test_a_config_integer_is_read_as_counts_are():
    """A config's integer field takes "1e6" as --updates does (its range is the config's to check)."""
    import argparse

    from offrl_jax.system.cli import integer
    assert (integer("1e6"), integer("-3"), integer("0")) == (1_000_000, -3, 0)
    for text in ("2.5", "1e40", "nan", ""):
        with pytest.raises(argparse.ArgumentTypeError):
            integer(text)


@pytest.mark.parametrize("module, args", [
    ("experiments.mujoco_medium", ["--dataset-path", "/tmp/a\nb.hdf5"]),
    ("offrl_jax.data", ["info", "/tmp/a\nb.hdf5"]),
    ("experiments.report", ["/tmp/a\nb"]),
])
def test_a_newline_in_a_path_stays_on_the_one_error_line(module, args):

    result = run_module(module, *args)
    assert result.returncode == 2 and result.stderr.count("\n") == 1, result.stderr
    assert result.stderr.startswith("error: ") and "a\\nb" in result.stderr, result.stderr


@pytest.mark.parametrize("module, args", [
    ("experiments.theory", ["--mdps", "1", "--states", "3"]),
    ("experiments.adroit_random_scores", ["--episodes", "2", "--envs", "door"]),
    ("experiments.mujoco_medium", []),
    ("benchmarks.throughput", ["--quick"]),
    ("experiments.report", ["--merge"]),
])
def test_entry_point_refuses_an_unwritable_output_before_working(tmp_path, module, args):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a directory")
    out = blocker / "out"  # under a file: cannot be made
    if module == "experiments.report":
        line = _one_line_error(module, *args, str(out), str(tmp_path))
    elif module == "benchmarks.throughput":
        line = _one_line_error(module, *args, "--out", str(out / "x.jsonl"))
    else:
        line = _one_line_error(module, *args, "--out", str(out))
    assert "a-file" in line and blocker.read_text() == "not a directory"


def test_report_refuses_a_summary_that_is_not_one(tmp_path):
    for text in ('{"a": 1}', "[1, 2]", "null", "not json", "[]"):
        (tmp_path / "summary.json").write_text(text)
        assert str(tmp_path / "summary.json") in _one_line_error("experiments.report", str(tmp_path))


RUN = Path(__file__).resolve().parents[1] / "results" / "mujoco_medium" / "default-20261202"


def extended_and_stopped(run: Path) -> None:
    """What `--resume RUN --updates 100000` of a finished 70k run leaves when it is stopped: config.json says the
    new budget, one variant has evaluations past the old one, summary.json is the 70k run's."""
    (run / "config.json").write_text((run / "config.json").read_text().replace('"updates": 70000', '"updates": 100000'))
    lines = (run / "curves.csv").read_text().splitlines(True)
    more = [line.replace(",70000,", ",75000,") for line in lines
            if line.startswith("pretrained,") and ",70000," in line]
    (run / "curves.csv").write_text("".join(lines + more))


@pytest.mark.parametrize("damage, message", [
    (None, None),
    # a summary without its config is reported as it is, if it has the interval statistics; this run's is older
    (lambda run: (run / "config.json").unlink(), "written before the interval statistics"),
    (lambda run: (run / "curves.csv").write_text("".join((run / "curves.csv").read_text().splitlines(True)[:-1])),
     "has no row for seed"),  # the last line cut
    (lambda run: (run / "curves.csv").write_text("".join((run / "curves.csv").read_text().splitlines(True)[:-6])),
     "end at update"),  # cut at an evaluation boundary: before the budget
    (lambda run: (run / "config.json").write_text((run / "config.json").read_text().replace('"scratch"', '"other"')),
     "are not the study's"),  # a config of another study
    (lambda run: (run / "config.json").write_text('{"name": 1}'), "not a saved study"),
    (lambda run: (run / "curves.csv").write_text((run / "curves.csv").read_text().replace("\nscratch,", "\nx,")),
     "another run"),
    (lambda run: (run / "curves.csv").write_text((run / "curves.csv").read_text()
                                                 + "".join((run / "curves.csv").read_text().splitlines(True)[1:])),
     "has two rows at update"),  # the file appended to itself
    (lambda run: (run / "curves.csv").write_text((run / "curves.csv").read_text().replace(",td3bc,1,", ",td3bc,7,")),
     "has seeds 0, 2, 7 where its run has 0, 1, 2"),  # a seed relabelled
    (lambda run: (run / "curves.csv").write_text((run / "curves.csv").read_text().replace(",td3bc,", ",iql,")),
     "its pretrained rows are iql's, where the run trains td3bc"),  # another algorithm's curves
    (lambda run: (run / "summary.json").write_text((run / "summary.json").read_text().replace('"td3bc"', '"iql"')),
     "its pretrained is iql, the study's is td3bc"),
    (extended_and_stopped, "is a partial run: pretrained stopped at update 75,000, scratch stopped at update 70,000, "
                           "of the 100,000 updates in its config.json"),
])
def test_report_reads_a_run_as_a_whole(tmp_path, capsys, damage, message):
    """report RUN checks the summary against the run's config.json and curves.csv: a damaged or mixed run is one
    line, not a table."""
    from experiments.report import main

    run = tmp_path / "run"
    shutil.copytree(RUN, run)
    if damage is not None:
        damage(run)
    code = main([str(run)])
    out, err = capsys.readouterr()
    if message is None:
        assert code == 0 and "| pretrained" in out, err
    else:
        assert code == 2 and message in err and len(err.strip().splitlines()) == 1 and not out, err


def test_datasets_generate_refuses_an_existing_dataset_without_overwrite(tmp_path):
    out = tmp_path / "ds"
    out.mkdir()
    (out / "keep").write_text("x")
    line = _one_line_error("offrl_jax.data", "generate", "hopper-medium", "--out", str(out))
    assert "--overwrite" in line and (out / "keep").read_text() == "x"
    (tmp_path / "file").write_text("x")
    assert "is a file" in _one_line_error("offrl_jax.data", "generate", "hopper-medium", "--out",
                                          str(tmp_path / "file"), "--overwrite")


@pytest.mark.parametrize("module, args, message", [
    ("experiments.figure2", ["--envs", "hopper", "hopper"], "argument --envs: hopper given more than once"),
    ("experiments.replay", ["--levels", "medium-replay", "medium-replay"], "medium-replay given more than once"),
])
def test_a_choice_given_twice_is_refused(module, args, message):
    assert message in _one_line_error(module, *args)


def test_theory_refuses_an_error_whose_noise_floor_hides_the_target():
    assert "nothing to converge to" in _one_line_error("experiments.theory", "--mdps", "1", "--states", "5",
                                                       "--eps", "5", "--betas", "0")


def test_report_refuses_a_run_being_written_or_half_replaced(tmp_path, capsys):
    """A run that a process holds (a run, --resume, --overwrite) and one whose earlier run an interrupted --overwrite
    left aside are refused with one line naming why; neither is read as a finished run."""
    from experiments.report import main
    from offrl_jax.system.cli import lock_run_dir

    run = tmp_path / "run"
    shutil.copytree(RUN, run)
    lock = lock_run_dir(run)
    try:
        assert main([str(run)]) == 2
        out, err = capsys.readouterr()
        assert not out and "is being written by another process" in err and len(err.strip().splitlines()) == 1
    finally:
        lock.close()
    assert main([str(run)]) == 0
    capsys.readouterr()
    aside = tmp_path / ".run.replaced"
    run.rename(aside)
    run.mkdir()  # the new run had begun: its config.json, no curves yet
    shutil.copy(aside / "config.json", run / "config.json")
    assert main([str(run)]) == 2
    out, err = capsys.readouterr()
    assert not out and f"the run it was replacing is in {aside}" in err, err


def test_report_says_a_run_is_partial_and_reports_it_at_the_budget_its_summary_was_made_for(capsys):
    """A run stopped on purpose and summarised where it stopped (one arm, 14k of 16k updates): its heading says so,
    and its numbers are labelled with the 14k they were measured at, not config.json's 16k."""
    from experiments.report import main

    run = RUN.parents[1] / "figure2" / "hopper-edac-critic9k"
    assert main([str(run), "--no-reference"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"### {run} (partial: pretrained stopped at update 14,000, scratch has no evaluation, of "
                          "16,000; reported at the summary's budget)\n"), out
    assert "2 seeds, 14,000 updates per variant" in out and "16,000" not in out.split("\n", 1)[1]
