"""The experiment CLI end to end on a tiny dataset: bad input, kill-and-resume, divergence, determinism."""
import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import pytest

from tests.conftest import synthetic_dataset
from tests.entry import run_module

ROOT = Path(__file__).resolve().parents[1]
TINY = ["--updates", "400", "--eval-every", "100", "--pretrain-updates", "200", "--eval-episodes", "1",
        "--seeds", "2", "--hidden", "32", "32", "--batch-size", "32", "--no-progress"]


@pytest.fixture(scope="module")
def tiny_hdf5(tmp_path_factory) -> Path:
    ds = synthetic_dataset(3000, episode_len=100)
    path = tmp_path_factory.mktemp("data") / "hopper-tiny.hdf5"
    with h5py.File(path, "w") as f:
        for key in ("observations", "actions", "rewards", "next_observations", "terminals", "timeouts"):
            f[key] = getattr(ds, key)
    return path


def cli(*args, check=False, timeout=300, env=None):
    """The main job's command, run as `python -m` (through `tests.entry`); `check` raises on a non-zero exit."""
    result = run_module("experiments.mujoco_medium", *args, timeout=timeout, env=env)
    if check:
        result.check_returncode()
    return result


def curves_without_time(path: Path) -> list[dict]:
    with open(path) as f:
        return [{k: v for k, v in row.items() if k != "seconds"} for row in csv.DictReader(f)]


@pytest.mark.parametrize("args, message", [
    (["--env", "cartpole"], "invalid choice"),
    (["--algo", "dqn"], "invalid choice"),
    (["--updates", "0"], "positive integer"),
    (["--lam", "1.5"], "lam = 1.5 must be in [0, 1]"),
    (["--batch-size", "-4"], "positive integer"),
    (["--algo", "edac", "--num-critics", "1"], "num_critics = 1 must be >= 2"),
    (["--algo", "edac", "--actor-pretrain-fraction", "1.5"], "actor_pretrain_fraction = 1.5 must be in [0, 1]"),
    (["--actor-pretrain-fraction", "0.5"], "'actor_pretrain_fraction' is not a hyper-parameter of td3bc"),
    (["--dataset-path", "/nonexistent/file.hdf5"], "/nonexistent/file.hdf5"),
    (["--resume", "/nonexistent/run"], "nothing to resume"),
    (["--updates", "5000"], "pre-training updates (10000) exceed the total budget (5000)"),
    (["--updates", "20000", "--eval-every", "1001"], "must be multiples of 2"),  # TD3's 2-update call grid
    (["--level", "expert", "--dataset-path", "x.hdf5"], "--level names a generated dataset"),  # else ignored
    (["--pretrain-auto-window", "2000"], "--pretrain-auto-window applies only to --pretrain-updates auto"),
])
def test_bad_input_is_one_line_and_writes_nothing(tmp_path, args, message):
    out = tmp_path / "out"
    result = cli(*args, "--out", out, timeout=120)
    assert result.returncode != 0
    lines = result.stderr.strip().splitlines()
    assert lines[-1].startswith("error:") and message in lines[-1], result.stderr
    assert "Traceback" not in result.stderr
    assert not out.exists()


def test_a_batch_larger_than_the_dataset_is_refused_before_anything_is_written(tmp_path, tiny_hdf5):
    out = tmp_path / "out"
    result = cli("--dataset-path", tiny_hdf5, "--out", out, "--batch-size", "5000", "--updates", "400",
                 "--pretrain-updates", "200", "--eval-every", "100", timeout=120)
    assert result.returncode == 2 and result.stderr.strip().splitlines()[-1] == (
        f"error: --batch-size 5000 is larger than the dataset (3,000 transitions of {tiny_hdf5})")
    assert not out.exists()


@pytest.mark.parametrize("episode_len, batch, algo, left", [
    (1, "256", ["--algo", "rebrac"], "0 of its 3,000 transitions remain"),  # every row a time-out
    (1, "256", ["--timeouts", "drop"], "0 of its 3,000 transitions remain"),
    (2, "2000", ["--algo", "rebrac"], "1,500 of its 3,000 transitions remain"),  # fewer left than a batch
])
def test_a_batch_larger_than_the_rows_left_after_dropping_time_outs_is_refused(tmp_path, episode_len, batch, algo,
                                                                              left):
    ds = synthetic_dataset(3000, episode_len=episode_len)
    path = tmp_path / "hopper-short.hdf5"
    with h5py.File(path, "w") as f:
        for key in ("observations", "actions", "rewards", "next_observations", "terminals", "timeouts"):
            f[key] = getattr(ds, key)
    out = tmp_path / "out"
    result = cli("--dataset-path", path, "--out", out, *algo, "--batch-size", batch, "--updates", "400",
                 "--pretrain-updates", "200", "--eval-every", "100", timeout=120)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and "Traceback" not in result.stderr, result.stderr
    assert lines[-1].startswith(f"error: {path}: {left} once its time-out rows are dropped"), lines[-1]
    assert f"fewer than --batch-size {batch}; keep them with --timeouts bootstrap or stop" in lines[-1]
    assert not out.exists()


def test_existing_output_is_never_overwritten(tmp_path, tiny_hdf5):
    out = tmp_path / "run"
    out.mkdir()
    (out / "keep.txt").write_text("precious")
    result = cli("--dataset-path", tiny_hdf5, "--out", out, *TINY, timeout=120)
    assert result.returncode == 2 and "exists and is not empty" in result.stderr
    assert (out / "keep.txt").read_text() == "precious"
    result = cli("--dataset-path", tiny_hdf5, "--out", out, "--overwrite", *TINY, timeout=120)
    assert result.returncode == 2 and "holds no earlier run" in result.stderr  # not a run: kept
    assert (out / "keep.txt").read_text() == "precious"


@pytest.mark.slow  # one of the suite's longest (1-5 min on 2 busy cores); -m slow runs it
def test_overwrite_replaces_an_earlier_run_only_once_the_new_one_can_start(tmp_path, tiny_hdf5):
    from offrl_jax.run.study import Study, Variant

    out = tmp_path / "run"
    out.mkdir()
    (out / "config.json").write_text("{}")  # a config.json that is not a saved study: not a run, never deleted
    result = cli("--dataset-path", tiny_hdf5, "--out", out, "--overwrite", *TINY, timeout=120)
    assert result.returncode == 2 and "holds no earlier run" in result.stderr and (out / "config.json").exists()
    earlier = Study(name="earlier", dataset=str(tiny_hdf5), env="hopper",
                    variants=(Variant.of("scratch", "td3bc", pretrain="none"),))
    (out / "config.json").write_text(earlier.to_json())
    (out / "summary.json").write_text("earlier")
    result = cli("--dataset-path", tmp_path / "missing.hdf5", "--out", out, "--overwrite", *TINY, timeout=120)
    assert result.returncode == 2 and "missing.hdf5" in result.stderr
    assert (out / "summary.json").read_text() == "earlier"  # the data failed to load: nothing deleted
    # the new run starts and diverges before its first checkpoint: the earlier run is given back as it was
    result = cli("--dataset-path", tiny_hdf5, "--out", out, "--overwrite", *TINY, "--critic-lr", "1e30",
                 timeout=300)
    assert result.returncode != 0 and "the earlier run in" in result.stderr, result.stderr
    assert (out / "summary.json").read_text() == "earlier" and not (out.parent / ".run.replaced").exists()
    # a new run that trains replaces it
    result = cli("--dataset-path", tiny_hdf5, "--out", out, "--overwrite", *TINY, timeout=300)
    assert result.returncode == 0, result.stderr
    assert (out / "summary.json").read_text() != "earlier" and not (out.parent / ".run.replaced").exists()


FAR = ["--updates", "20000", "--eval-every", "10000", "--pretrain-updates", "10000"]  # a first checkpoint far off
SHORT = [*TINY, "--updates", "200", "--pretrain-updates", "100", "--parallel", "1"]  # a finished run, soon


def start_overwrite(tiny_hdf5, out: Path, **popen) -> subprocess.Popen:
    """An --overwrite of the run in `out`, returned once it has moved that run aside and begun the new one (in one
    process: the parent ignores Ctrl-C while it starts worker processes)."""
    proc = subprocess.Popen([sys.executable, "-m", "experiments.mujoco_medium", "--dataset-path", str(tiny_hdf5),
                             "--out", str(out), "--overwrite", *TINY, *FAR, "--parallel", "1"], cwd=ROOT, **popen)
    deadline = time.time() + 300
    while not ((out / "config.json").exists() and (out.parent / f".{out.name}.replaced").exists()):
        assert time.time() < deadline and proc.poll() is None
        time.sleep(0.02)
    assert not any(out.rglob("*.msgpack"))
    return proc


def test_a_killed_overwrite_leaves_the_earlier_run_where_the_next_command_finds_it(tmp_path, tiny_hdf5):
    """SIGKILL before the new run's first checkpoint: `report` names where the earlier run is, the next run command
    on the directory gives it back (a --resume then has nothing of the new run to continue), and a second
    --overwrite never deletes it unseen."""
    out, aside = tmp_path / "run", tmp_path / ".run.replaced"
    cli("--dataset-path", tiny_hdf5, "--out", out, *SHORT, check=True)
    earlier = (out / "summary.json").read_text()
    proc = start_overwrite(tiny_hdf5, out, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    proc.kill()
    proc.wait()
    result = run_module("experiments.report", str(out))
    assert result.returncode == 2 and f"the run it was replacing is in {aside}" in result.stderr, result.stderr
    result = cli("--resume", out, "--dry-run")  # a dry run only reads: both directories stay as they are
    assert f"note: {aside} holds the earlier run" in result.stderr and aside.is_dir()
    result = cli("--resume", out, "--no-progress")
    assert result.returncode == 2 and "the earlier run in" in result.stderr and "is given back" in result.stderr
    assert result.stderr.strip().splitlines()[-1].startswith(f"error: {out}: the --overwrite that was replacing")
    assert (out / "summary.json").read_text() == earlier and not aside.exists()
    # the same state again, then an --overwrite whose data fails to load: the earlier run is back, not deleted
    out.rename(aside)
    out.mkdir()
    (out / "config.json").write_text((aside / "config.json").read_text())
    result = cli("--dataset-path", tmp_path / "missing.hdf5", "--out", out, "--overwrite", *TINY)
    assert result.returncode == 2 and "is given back" in result.stderr, result.stderr
    assert (out / "summary.json").read_text() == earlier and not aside.exists()


def test_an_interrupted_overwrite_says_the_earlier_run_is_kept_not_resume(tmp_path, tiny_hdf5):
    out = tmp_path / "run"
    cli("--dataset-path", tiny_hdf5, "--out", out, *SHORT, check=True)
    earlier = (out / "summary.json").read_text()
    proc = start_overwrite(tiny_hdf5, out, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                           preexec_fn=terminal_sigint)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert err.strip().splitlines()[-1] == (f"interrupted before the new run's first checkpoint; the earlier run in "
                                            f"{out} is kept (the new one left nothing to resume)"), err
    assert "resume with" not in err and (out / "summary.json").read_text() == earlier


def test_kill_and_resume_equals_uninterrupted_run(tmp_path, tiny_hdf5):
    full, killed = tmp_path / "full", tmp_path / "killed"
    cli("--dataset-path", tiny_hdf5, "--out", full, *TINY, check=True, timeout=600)

    proc = subprocess.Popen([sys.executable, "-m", "experiments.mujoco_medium", "--dataset-path", str(tiny_hdf5),
                             "--out", str(killed), *TINY], cwd=ROOT, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    checkpoint = killed / "checkpoints" / "pretrained.msgpack"
    deadline = time.time() + 300
    while not checkpoint.exists() and time.time() < deadline and proc.poll() is None:
        time.sleep(0.05)
    os.kill(proc.pid, signal.SIGKILL)  # in the middle of the pre-training phase (first checkpoint: update 100)
    proc.wait()
    assert checkpoint.exists()
    assert not (killed / "summary.json").exists()

    result = cli("--resume", killed, "--no-progress", timeout=600)
    assert result.returncode == 0, result.stderr
    assert curves_without_time(killed / "curves.csv") == curves_without_time(full / "curves.csv")
    assert (killed / "summary.json").exists() and (killed / "curves.png").exists()


def terminal_sigint() -> None:
    """In the child: SIGINT as a terminal's foreground command has it, even when the tests themselves run as a
    background job (which a shell starts with SIGINT ignored, and children inherit that)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.mark.parametrize("background", [False, True])
def test_sigterm_is_a_stop_with_the_resume_command(tmp_path, tiny_hdf5, background):
    """`kill PID` (a scheduler's stop): the same one line as Ctrl-C, with the resume command, and exit 143; also for
    a background job of a shell (`cmd &`: SIGINT ignored from the start) training its variants in worker processes."""
    stopped = tmp_path / "stopped"
    ignore_sigint = (lambda: signal.signal(signal.SIGINT, signal.SIG_IGN)) if background else terminal_sigint
    proc = subprocess.Popen([sys.executable, "-m", "experiments.mujoco_medium", "--dataset-path", str(tiny_hdf5),
                             "--out", str(stopped), "--parallel", "2" if background else "1", *TINY], cwd=ROOT,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, preexec_fn=ignore_sigint)
    checkpoint = stopped / "checkpoints" / "pretrained.msgpack"
    deadline = time.time() + 300
    while not checkpoint.exists() and time.time() < deadline and proc.poll() is None:
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 143, err
    parallel = "" if background else " --parallel 1"  # a resume keeps the run's --parallel
    assert f"interrupted; resume with --resume {stopped} --no-progress{parallel}\n" in err and "Traceback" not in err
    assert ("\n" + err).count("\ninterrupted; resume") == 1, err  # on a line of its own, not on the progress bar's


@pytest.mark.slow  # one of the suite's longest (1-5 min on 2 busy cores); -m slow runs it
def test_ctrl_c_stops_the_worker_processes_and_the_run_resumes(tmp_path, tiny_hdf5):
    """Ctrl-C as a terminal sends it (SIGINT to the whole process group; the two variants train in worker
    processes): the parent tells the workers to stop, exits 130 with the resume command and no traceback, and the
    resumed run equals an uninterrupted one."""
    full, stopped = tmp_path / "full", tmp_path / "stopped"
    cli("--dataset-path", tiny_hdf5, "--out", full, *TINY, check=True, timeout=600)
    proc = subprocess.Popen([sys.executable, "-m", "experiments.mujoco_medium", "--dataset-path", str(tiny_hdf5),
                             "--out", str(stopped), "--no-progress", *TINY], cwd=ROOT, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True, start_new_session=True,
                            preexec_fn=terminal_sigint)
    checkpoint = stopped / "checkpoints" / "pretrained.msgpack"
    deadline = time.time() + 300
    while not checkpoint.exists() and time.time() < deadline and proc.poll() is None:
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert f"interrupted; resume with --resume {stopped} --no-progress\n" in err and "Traceback" not in err
    assert not (stopped / "summary.json").exists()
    result = cli("--resume", stopped, "--no-progress", timeout=600)
    assert result.returncode == 0, result.stderr
    assert curves_without_time(stopped / "curves.csv") == curves_without_time(full / "curves.csv")


def test_divergence_stops_cleanly_and_keeps_checkpoint(tmp_path, tiny_hdf5):
    out = tmp_path / "nan"
    # BC pre-training is fine; the exploding critic learning rate blows up the offline-RL phase
    result = cli("--dataset-path", tiny_hdf5, "--out", out, "--pretrain", "actor", "--critic-lr", "1e12", *TINY,
                 timeout=600)
    assert result.returncode == 3, result.stderr
    last = result.stderr.strip().splitlines()[-1]
    assert last.startswith("error:") and "td3bc" in last and "diverged in phase offline_rl" in last
    assert "Traceback" not in result.stderr
    assert "seed(s) 0, 1" in result.stderr
    assert (out / "checkpoints" / "actor-only.msgpack").exists()
    assert (out / "curves.csv").exists()


@pytest.mark.slow  # the worker processes are tested in tests/test_workers.py and by the Ctrl-C test below
def test_parallel_variants_equal_one_after_another(tmp_path, tiny_hdf5):
    runs = {n: tmp_path / f"parallel{n}" for n in (1, 2)}
    for n, out in runs.items():
        cli("--dataset-path", tiny_hdf5, "--out", out, "--parallel", n, *TINY, check=True, timeout=600)
    assert curves_without_time(runs[1] / "curves.csv") == curves_without_time(runs[2] / "curves.csv")
    assert [r["variant"] for r in curves_without_time(runs[2] / "curves.csv")][0] == "pretrained"  # study order


def test_vmapped_alpha_sweep_equals_separate_runs(tmp_path, tiny_dataset):
    import dataclasses

    from offrl_jax.run.runner import run_study
    from offrl_jax.run.study import Study, Variant

    variants = tuple(Variant.of(f"alpha={a:g}", "td3bc", pretrain="none", alpha=a, hidden=(32, 32))
                     for a in (1.0, 10.0))
    study = Study(name="sweep", dataset="synthetic", env="hopper", variants=variants, seeds=(0, 1), updates=200,
                  eval_every=100, eval_episodes=1, batch_size=32)
    together = run_study(study, tmp_path / "together", tiny_dataset, progress=False)
    apart = run_study(dataclasses.replace(study, vmap_sweeps=False), tmp_path / "apart", tiny_dataset, progress=False)
    rows = [curves_without_time(tmp_path / d / "curves.csv") for d in ("together", "apart")]
    assert [(r["variant"], r["seed"], r["update"]) for r in rows[0]] == [(r["variant"], r["seed"], r["update"])
                                                                         for r in rows[1]]
    for a, b in zip(*rows):
        for key in ("score", "critic_loss", "actor_loss", "q_mean"):
            assert abs(float(a[key]) - float(b[key])) <= 1e-3 * (1 + abs(float(b[key]))), (key, a, b)
    assert [s["final_score_mean"] for s in together] == pytest.approx([s["final_score_mean"] for s in apart], abs=0.5)


@pytest.mark.slow  # one of the suite's longest (1-5 min on 2 busy cores); -m slow runs it
def test_config_replays_a_saved_run_and_resume_refuses_other_settings(tmp_path, tiny_hdf5):
    """--config FILE re-runs a run exactly; --resume refuses changed settings (writing nothing) but extends
    --updates from the last checkpoint, equal to a run made that long from the start."""
    first, again, longer = tmp_path / "first", tmp_path / "again", tmp_path / "longer"
    cli("--dataset-path", tiny_hdf5, "--out", first, *TINY, check=True, timeout=600)
    result = cli("--config", first / "config.json", "--out", again, "--no-progress", timeout=600)
    assert result.returncode == 0, result.stderr
    assert curves_without_time(again / "curves.csv") == curves_without_time(first / "curves.csv")
    before = {p.name: p.read_bytes() for p in first.iterdir() if p.is_file()}
    for args, flag in ((["--hidden", "64"], "--hidden"), (["--out", tmp_path / "x"], "--out"),
                       (["--alpha", "3"], "--alpha"), (["--updates", "200"], "less than")):
        result = cli("--resume", first, *map(str, args), timeout=120)
        assert result.returncode == 2 and flag in result.stderr.strip().splitlines()[-1], result.stderr
        assert "Traceback" not in result.stderr
    assert {p.name: p.read_bytes() for p in first.iterdir() if p.is_file()} == before  # nothing written
    # a single value changed with --config: that run differs from the first only there
    result = cli("--config", first, "--out", tmp_path / "alpha3", "--alpha", "3", "--no-progress", timeout=600)
    assert result.returncode == 0, result.stderr
    import json
    resolved = json.loads((tmp_path / "alpha3" / "config.json").read_text())["resolved"]
    assert {v["alpha"] for v in resolved.values()} == {3.0}
    result = cli("--config", first, "--out", tmp_path / "bad", "--pretrain", "none", timeout=120)
    assert result.returncode == 2 and "--pretrain" in result.stderr and not (tmp_path / "bad").exists()
    # extend a finished run by 200 updates: the same as a 600-update run
    result = cli("--resume", first, "--updates", "600", "--no-progress", timeout=600)
    assert result.returncode == 0, result.stderr
    cli("--dataset-path", tiny_hdf5, "--out", longer, *TINY[:1], "600", *TINY[2:], check=True, timeout=600)
    assert curves_without_time(first / "curves.csv") == curves_without_time(longer / "curves.csv")
    assert len(json.loads((first / "config.json").read_text())["runs"]) == 2  # the start and the extension


def test_a_config_replay_is_exact_or_refused(tmp_path, tiny_hdf5):
    """--config never trains variants under labels their values contradict (one value for a swept field), nor on
    data other than the saved run's unless a data flag says so; both refusals come before anything is written."""
    from offrl_jax.data import catalogue
    from offrl_jax.run.study import Study, Variant

    sweep = tuple(Variant.of(f"scratch actor_beta={b:g}", "rebrac", actor_beta=b, pretrain="none")
                  for b in (0.001, 0.01))
    study = Study(name="sweep", dataset=str(tiny_hdf5), env="hopper", variants=sweep, updates=400, eval_every=100)
    saved = tmp_path / "sweep.json"
    saved.write_text(study.record_json())
    result = cli("--config", saved, "--out", tmp_path / "new", "--actor-beta", "0.5", timeout=120)
    assert result.returncode == 2 and not (tmp_path / "new").exists(), result.stderr
    assert result.stderr.strip().splitlines()[-1].startswith(
        "error: --actor-beta: the saved run's variants differ in actor_beta (scratch actor_beta=0.001: 0.001, "
        "scratch actor_beta=0.01: 0.01)"), result.stderr
    # the data file changed since the run: its SHA-256 is not the one config.json recorded
    study = Study(name="one", dataset=str(tiny_hdf5), env="hopper",
                  variants=(Variant.of("scratch", "td3bc", pretrain="none"),), updates=400, eval_every=100,
                  batch_size=32)
    saved.write_text(study.record_json(catalogue.load(str(tiny_hdf5)), data_sha256="ab" * 32))
    result = cli("--config", saved, "--out", tmp_path / "new", timeout=120)
    assert result.returncode == 2 and not (tmp_path / "new").exists(), result.stderr
    assert "not the data the saved run trained on (SHA-256" in result.stderr.strip().splitlines()[-1], result.stderr
    assert f"say so with --dataset-path {tiny_hdf5}" in result.stderr
    assert "recorded ababababab" in result.stderr and "generated again, on another machine" in result.stderr


def test_a_resume_keeps_the_runs_parallel(tmp_path, tiny_hdf5):
    """Variants side by side (one core each) or one after another (sharing the cores) round differently, so a
    resume with another --parallel is refused like any other changed setting, before anything is written."""
    import json

    from offrl_jax.data import catalogue
    from offrl_jax.run.study import Study, Variant

    run = tmp_path / "run"
    run.mkdir()
    study = Study(name="two", dataset=str(tiny_hdf5), env="hopper", updates=400, eval_every=100, batch_size=32,
                  variants=(Variant.of("a", "td3bc", pretrain="none"), Variant.of("b", "td3bc", pretrain="none",
                                                                                    hidden=(32, 32))))
    record = json.loads(study.record_json(catalogue.load(str(tiny_hdf5))))
    for command, saved, given in (("", "2", ["--parallel", "1"]), (" --parallel 1", "1", [])):
        record["runs"][-1]["command"] = f"python -m experiments.mujoco_medium --out {run}{command}"
        (run / "config.json").write_text(json.dumps(record))
        before = (run / "config.json").read_text()
        result = cli("--resume", run, *given, timeout=120)
        assert result.returncode == 2 and (run / "config.json").read_text() == before, result.stderr
        now = given[1] if given else "2"
        assert result.stderr.strip().splitlines()[-1].endswith(
            f"it ran with --parallel {saved}, and --parallel {now} would train the rest differently (rounding); "
            f"resume with --parallel {saved}"), result.stderr


def test_a_config_replay_keeps_the_saved_runs_parallel_unless_given(tmp_path, tiny_hdf5):
    import json

    from experiments.mujoco_medium import make_parser
    from offrl_jax.app.command import Command
    from offrl_jax.app.studies import HPARAM_DESTS, given
    from offrl_jax.run.study import Study, Variant

    study = Study(name="one", dataset=str(tiny_hdf5), env="hopper", updates=400, eval_every=100, batch_size=32,
                  variants=(Variant.of("scratch", "td3bc", pretrain="none"),))
    record = json.loads(study.record_json())
    record["runs"][-1]["command"] = "python -m experiments.mujoco_medium --parallel 1"
    (tmp_path / "config.json").write_text(json.dumps(record))
    for argv, parallel in (([], 1), (["--parallel", "2"], 2)):
        argv = ["--config", str(tmp_path / "config.json"), "--out", str(tmp_path / "new"), *argv]
        command = Command(make_parser().parse_args(argv), make_parser(), argv)
        command.read(None, given, HPARAM_DESTS)
        assert command.args.parallel == parallel


def test_a_config_replay_changes_only_what_its_flags_say(tmp_path, tiny_hdf5):
    from experiments.mujoco_medium import make_parser
    from offrl_jax.app.command import Command
    from offrl_jax.app.studies import HPARAM_DESTS, given
    from offrl_jax.run.study import Study, Variant

    auto = Variant.of("pretrained", "td3bc", pretrain_auto=True, pretrain_auto_window=100, pretrain_updates=200)
    study = Study(name="one", dataset=str(tiny_hdf5), env="hopper", updates=400, eval_every=100, batch_size=32,
                  seeds=(5, 6), variants=(auto,))
    (tmp_path / "config.json").write_text(study.record_json())

    def replayed(*argv):
        argv = ["--config", str(tmp_path / "config.json"), "--out", str(tmp_path / "new"), *argv]
        command = Command(make_parser().parse_args(argv), make_parser(), argv)
        command.read(None, given, HPARAM_DESTS)
        return command.built

    assert replayed("--seed-offset", "7").seeds == (7, 8)  # the saved count, not the flag's default 5
    assert replayed("--seeds", "3").seeds == (5, 6, 7)  # from the saved first seed, not 0
    fixed = replayed("--pretrain-updates", "100")
    assert fixed.config("pretrained").pretrain_updates == 100 and not fixed.config("pretrained").pretrain_auto


def test_the_parallel_a_config_replay_ran_with_is_the_replayed_runs(tmp_path):
    import json

    from offrl_jax.app.command import recorded_parallel

    def run(name, command):
        (tmp_path / name).mkdir()
        (tmp_path / name / "config.json").write_text(json.dumps({"runs": [{"command": command}]}))
        return tmp_path / name / "config.json"

    first = run("first", "python -m experiments.mujoco_medium --parallel 1 --out first")
    replay = run("replay", f"python -m experiments.mujoco_medium --config {first.parent} --out replay")
    assert recorded_parallel(replay, "experiments.mujoco_medium", 2) == 1  # it took the replayed run's
    moved = run("moved", "python -m experiments.mujoco_medium --config elsewhere --out moved")
    assert recorded_parallel(moved, "experiments.mujoco_medium", 2) is None  # not known: nothing is refused
    plain = run("plain", "python -m experiments.mujoco_medium --out plain")
    assert recorded_parallel(plain, "experiments.mujoco_medium", 2) == 2


def test_debug_variable_shows_the_traceback(tmp_path):
    result = cli("--lam", "1.5", "--out", tmp_path / "x", timeout=120)
    assert result.returncode == 2 and "Traceback" not in result.stderr
    result = cli("--lam", "1.5", "--out", tmp_path / "x", timeout=120, env={"OFFRL_JAX_DEBUG": "1"})
    assert result.returncode != 0 and "Traceback" in result.stderr and "lam = 1.5" in result.stderr


def test_a_run_directory_has_one_writer(tmp_path, tiny_hdf5):
    """While one process holds a run directory, a second one started on it (even with --overwrite, or --resume)
    gets one line and exit 2, and writes nothing."""
    from offrl_jax.system.cli import lock_run_dir

    out = tmp_path / "run"
    held = lock_run_dir(out)
    try:
        for extra in ([], ["--overwrite"]):
            result = cli("--dataset-path", tiny_hdf5, "--out", out, *extra, *TINY, timeout=120)
            assert result.returncode == 2 and "another process" in result.stderr.strip().splitlines()[-1]
        assert not out.exists()
    finally:
        held.close()
    cli("--dataset-path", tiny_hdf5, "--out", out, *TINY, check=True, timeout=600)  # free again


def test_written_files_follow_the_umask(tmp_path, monkeypatch):
    import stat

    from offrl_jax.system import checkpoint
    for mask, mode in ((0o022, 0o644), (0o077, 0o600)):
        monkeypatch.setattr(checkpoint, "_UMASK", mask)
        checkpoint.atomic_write_text(tmp_path / "x.json", "{}")
        assert stat.S_IMODE((tmp_path / "x.json").stat().st_mode) == mode


def test_a_failed_run_leaves_no_empty_directories(tmp_path):
    result = subprocess.run([sys.executable, "-m", "experiments.mujoco_medium", "--dataset-path",
                             str(tmp_path / "missing.hdf5")], cwd=tmp_path, capture_output=True, text=True,
                            timeout=120, env=os.environ | {"PYTHONPATH": str(ROOT)})
    assert result.returncode == 2 and "missing.hdf5" in result.stderr
    assert not (tmp_path / "runs").exists()


def test_warnings_print_as_one_line(capsys):
    import warnings

    from offrl_jax.system.cli import one_line_warnings

    saved = warnings.showwarning
    try:
        one_line_warnings()
        with warnings.catch_warnings():
            warnings.simplefilter("always")
            warnings.showwarning = warnings.showwarning  # catch_warnings restores it; keep ours inside
            one_line_warnings()
            warnings.warn("cached 'x' was generated capped\n   at 2,000 transitions", stacklevel=1)
    finally:
        warnings.showwarning = saved
    assert capsys.readouterr().err == "warning: cached 'x' was generated capped at 2,000 transitions\n"
