"""An output the user already has is never deleted or mixed into: `--overwrite` replaces only what the command itself
wrote, a refused command changes nothing (every file's SHA-256 is the same after it), and a bad output or input
path gets a one-line error that says what is wrong with it.
"""
import hashlib
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.test_bad_input_cli import _one_line_error

ROOT = Path(__file__).resolve().parents[1]


def snapshot(root: Path) -> dict[str, str]:
    """Every path under `root`: the SHA-256 of a file, "dir" for a directory."""
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "dir"
            for p in sorted(root.rglob("*"))}


def refused(root: Path, module: str, *args) -> str:
    """The one error line of a command that must exit 2 and leave everything under `root` as it was."""
    before = snapshot(root)
    assert before, "nothing to guard"
    line = _one_line_error(module, *map(str, args))
    assert snapshot(root) == before, f"a refused command changed {root}"
    return line


def training_run(path: Path) -> Path:
    """A directory like a training run's (not a dataset, not theory's or adroit_random_scores's output)."""
    (path / "checkpoints").mkdir(parents=True)
    (path / "checkpoints" / "edac.msgpack").write_bytes(b"\x00weights" * 100)
    (path / "config.json").write_text('{"name": "mine"}\n')
    (path / "summary.json").write_text('{"score": 97.5}\n')
    return path


def run_ok(module: str, *args) -> subprocess.CompletedProcess:
    result = subprocess.run([sys.executable, "-m", module, *map(str, args)], cwd=ROOT, capture_output=True,
                            text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    return result


# ------------------------------------------------------------------------------------------ datasets generate


def _unrelated(path: Path) -> Path:
    path.mkdir()
    (path / "notes.txt").write_text("mine\n")
    (path / "data").mkdir()
    (path / "data" / "photo.jpg").write_bytes(b"\xff\xd8" * 50)
    return path


def _dataset_look_alike(path: Path) -> Path:
    (path / "data").mkdir(parents=True)  # a data/ folder but no metadata.json, no offrl_jax.json
    (path / "data" / "main_data.hdf5").write_bytes(b"not really")
    return path


@pytest.mark.parametrize("make, held", [(training_run, "checkpoints, config.json, summary.json"),
                                        (_unrelated, "notes.txt"),
                                        (_dataset_look_alike, "no data/metadata.json")])
def test_generate_overwrite_refuses_a_directory_that_is_not_a_dataset(tmp_path, make, held):
    out = make(tmp_path / "target")
    line = refused(tmp_path, "offrl_jax.data", "generate", "hopper-random", "--transitions", "100", "--out", out,
                   "--overwrite")
    assert line.startswith(f"error: {out} ") and held in line and "not a generated dataset" in line, line


def test_generate_overwrite_replaces_a_generated_dataset(tmp_path):
    out = tmp_path / "ds"
    run_ok("offrl_jax.data", "generate", "hopper-random", "--transitions", "100", "--out", out)
    assert json.loads((out / "offrl_jax.json").read_text())["seed"] == 0
    run_ok("offrl_jax.data", "generate", "hopper-random", "--transitions", "100", "--out", out, "--seed", "1",
           "--overwrite")
    assert json.loads((out / "offrl_jax.json").read_text())["seed"] == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds"]  # no scratch folder left beside it
    # the dataset with one file of the user's added is no longer only a dataset: left alone
    (out / "my-notes.txt").write_text("mine\n")
    line = refused(tmp_path, "offrl_jax.data", "generate", "hopper-random", "--transitions", "100", "--out", out,
                   "--overwrite")
    assert "my-notes.txt" in line, line


def test_generate_api_refuses_to_replace_what_is_not_a_dataset(tmp_path):
    from offrl_jax.data.generate import generate

    out = training_run(tmp_path / "run")
    before = snapshot(tmp_path)
    with pytest.raises(FileExistsError, match="not a generated dataset"):
        generate("hopper-random", transitions=100, out_dir=out, overwrite=True, progress=False)
    assert snapshot(tmp_path) == before


# ------------------------------------------------------------------------ theory and adroit_random_scores --out

COMMANDS = [("experiments.theory", ["--mdps", "1", "--states", "3"]),
            ("experiments.adroit_random_scores", ["--episodes", "2", "--envs", "pen"])]


@pytest.mark.parametrize("module, args", COMMANDS)
def test_overwrite_refuses_a_directory_with_files_the_command_does_not_write(tmp_path, module, args):
    out = training_run(tmp_path / "run")
    line = refused(tmp_path, module, *args, "--out", out, "--overwrite")
    assert line.startswith(f"error: {out} holds checkpoints, config.json") and "choose another --out" in line, line


@pytest.mark.parametrize("module, args", COMMANDS)
@pytest.mark.parametrize("overwrite", [[], ["--overwrite"]])
def test_an_out_that_is_a_file_is_called_a_file(tmp_path, module, args, overwrite):
    out = tmp_path / "results.txt"
    out.write_text("my results\n")
    line = refused(tmp_path, module, *args, "--out", out, *overwrite)
    assert line == f"error: {out} is a file, not a directory", line


def test_theory_overwrite_refuses_a_directory_named_like_its_output(tmp_path):
    out = tmp_path / "out"
    (out / "summary.json").mkdir(parents=True)  # a directory, not the file theory writes
    (out / "summary.json" / "keep.txt").write_text("mine\n")
    line = refused(tmp_path, "experiments.theory", "--mdps", "1", "--states", "3", "--out", out, "--overwrite")
    assert "summary.json" in line, line


def test_theory_overwrite_replaces_its_own_files(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "summary.json").write_text("old\n")
    (out / "rows.json").write_text("old\n")
    run_ok("experiments.theory", "--mdps", "1", "--states", "3", "--out", out, "--overwrite")
    assert isinstance(json.loads((out / "summary.json").read_text()), list)
    assert sorted(p.name for p in out.iterdir()) == ["rows.json", "summary.json", "theory.png"]


# ----------------------------------------------------------------------------------------- benchmarks.throughput


def test_throughput_markdown_says_what_is_wrong_with_the_path(tmp_path):
    a_file = tmp_path / "a-file"
    a_file.write_text("not json\n")
    line = refused(tmp_path, "benchmarks.throughput", "--markdown", tmp_path)
    assert line == f"error: {tmp_path} is a directory; --markdown reads a results .jsonl file", line
    line = refused(tmp_path, "benchmarks.throughput", "--markdown", a_file / "x.jsonl")
    assert line == f"error: {a_file / 'x.jsonl'}: cannot be read (Not a directory)", line
    line = refused(tmp_path, "benchmarks.throughput", "--markdown", tmp_path / "missing.jsonl")
    assert line.startswith(f"error: {tmp_path / 'missing.jsonl'}: no such file"), line
    line = refused(tmp_path, "benchmarks.throughput", "--markdown", a_file)  # readable, but not results
    assert line.startswith(f"error: {a_file}: not a results file of this benchmark"), line


@pytest.mark.parametrize("args, message", [
    (["--quick", "--algo", "nope"], "invalid choice: 'nope'"),
    (["--algo", "nope"], "invalid choice: 'nope'"),
    (["--quick", "--phase", "nope"], "invalid choice: 'nope'"),
    (["--quick", "--algo"], "expected at least one argument"),
    (["--algo"], "expected at least one argument"),
    (["--quick", "--seeds", "3"], "--quick runs one fixed case"),
    (["--quick", "--algo", "bc", "--reps", "5"], "takes no --algo, --reps"),
    (["--algo", "td3bc", "--phase", "bc"], "no case matches --algo td3bc --phase bc"),
])
def test_throughput_refuses_flags_it_would_ignore_or_cannot_use(tmp_path, args, message):
    (tmp_path / "keep.txt").write_text("mine\n")
    line = refused(tmp_path, "benchmarks.throughput", *args, "--out", tmp_path / "bench.jsonl")
    assert message in line, line


def test_a_failed_run_leaves_no_folders_it_made_for_its_out(tmp_path):
    out = tmp_path / "a" / "b" / "run"
    result = subprocess.run([sys.executable, "-m", "experiments.mujoco_medium", "--out", str(out), "--dataset-path",
                             str(tmp_path / "missing.hdf5")], capture_output=True, text=True, timeout=300,
                            cwd=Path(__file__).resolve().parents[1])
    assert result.returncode == 2 and list(tmp_path.iterdir()) == []


# ------------------------------------------------------------------------------------------- training runs


@pytest.mark.parametrize("extra", ["README.md", "notes.txt", "mydir/", "checkpoints/mine.txt",
                                   "tensorboard/events.mine", "online/notes.txt"])
def test_overwrite_of_a_run_refuses_files_no_run_writes(tmp_path, extra):
    """A saved run with a file the user put there (a README, notes, a folder) is not a run --overwrite may delete."""
    out = tmp_path / "run"
    shutil.copytree(ROOT / "results" / "mujoco_medium" / "default-20261202b", out)
    if extra != "README.md":
        (out / "README.md").unlink()
        (out / extra).parent.mkdir(exist_ok=True)
        (out / extra).mkdir() if extra.endswith("/") else (out / extra).write_text("mine\n")
    line = refused(tmp_path, "experiments.mujoco_medium", "--out", out, "--overwrite", "--updates", "20000")
    assert f"holds {extra.rstrip('/')}, which a run does not write" in line, line


def test_what_a_fine_tuning_run_writes_is_a_runs_own(tmp_path):
    from offrl_jax.app.outputs import not_from_a_run

    for name in ("config.json", "curves.csv", "online.png", "checkpoints/pretrained.handover.msgpack",
                 "online/hopper-pretrained-seed0.hdf5", "README.md"):
        (tmp_path / name).parent.mkdir(exist_ok=True)
        (tmp_path / name).write_text("x")
    assert not_from_a_run(tmp_path, None) == ["README.md"]


def test_what_a_killed_overwrite_left_aside_is_given_back_or_removed_and_left_alone_while_it_runs(tmp_path, capsys):
    """`.<name>.replaced` beside a run: left as it is while a process holds the run (the --overwrite is alive),
    given back when the new run has no checkpoint, removed (and said) when it has one."""
    from offrl_jax.app.outputs import give_back_replaced, replaced_dir
    from offrl_jax.system.cli import lock_run_dir

    out = tmp_path / "run"
    aside = replaced_dir(out)

    def leave(new_checkpoint: bool) -> None:
        aside.mkdir()
        (aside / "summary.json").write_text("earlier")
        (out / "checkpoints").mkdir(parents=True)
        (out / "config.json").write_text("{}")
        if new_checkpoint:
            (out / "checkpoints" / "pretrained.msgpack").write_bytes(b"new")

    leave(new_checkpoint=False)
    lock = lock_run_dir(out)
    assert give_back_replaced(out) is False and aside.is_dir() and (out / "config.json").exists()
    lock.close()
    assert give_back_replaced(out) is True and not aside.exists()
    assert (out / "summary.json").read_text() == "earlier" and not (out / "config.json").exists()
    assert "is given back" in capsys.readouterr().err
    shutil.rmtree(out)
    leave(new_checkpoint=True)
    assert give_back_replaced(out) is False and not aside.exists()
    assert (out / "checkpoints" / "pretrained.msgpack").read_bytes() == b"new"
    assert f"removed {aside}" in capsys.readouterr().err


def test_a_lock_on_the_lock_file_its_holder_just_deleted_is_no_lock(tmp_path, monkeypatch):
    """A holder deletes the lock file as it lets go: a process that opened that file just before, then locked it,
    would hold a lock on a file no longer there, and a third process would lock a new one: two writers."""
    import fcntl
    import os

    from offrl_jax.system import cli

    run = tmp_path / "run"
    first = cli.lock_run_dir(run)
    flock = fcntl.flock

    def first_lets_go_between_open_and_flock(handle, op):
        if not first.closed:
            Path(first.name).unlink()
            first.close()
        flock(handle, op)

    monkeypatch.setattr(fcntl, "flock", first_lets_go_between_open_and_flock)
    second = cli.lock_run_dir(run)
    try:
        assert os.fstat(second.fileno()).st_ino == os.stat(cli.lock_file(run)).st_ino  # the file at its place
        with pytest.raises(OSError, match="being written by another process"):
            cli.lock_run_dir(run)  # a third process is refused
    finally:
        second.close()
