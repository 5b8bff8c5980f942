"""Bad input to the SAC and ship commands of dataset generation and to rollout: one `error:` line, exit 2, before any
work, and nothing written or replaced."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from offrl_jax.data.generate import sac, ship
from tests.entry import run_module

ROOT = Path(__file__).resolve().parents[1]


def tree(path: Path) -> dict[str, bytes | None]:
    """Every file (its bytes) and directory (None) under `path`."""
    return {str(p.relative_to(path)): p.read_bytes() if p.is_file() else None for p in sorted(path.rglob("*"))}


def command(module: str, *args: str) -> str:
    """The one error line of a command that must refuse its input."""
    result = run_module(module, *args)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2, result.stderr
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    return lines[0]


def refused(main, argv: list[str], capsys) -> str:
    """The one error line of `main(argv)`, called in this process."""
    with pytest.raises(SystemExit) as exit_:
        main([str(a) for a in argv])
    lines = capsys.readouterr().err.strip().splitlines()
    assert exit_.value.code == 2
    assert len(lines) == 1 and lines[0].startswith("error: "), lines
    return lines[0]


# ------------------------------------------------------------------------------------------------------------- SAC

RUN_JSON = {"env": "hopper", "gym_id": "Hopper-v5", "seed": 0, "steps": 100, "eval_every": 50, "eval_episodes": 1,
            "config": {}, "checkpoints": []}


@pytest.mark.parametrize("args, message", [
    (["--env", "hopper", "--steps", "-10", "--out", "{tmp}/out"], "--steps: expected a positive integer"),
    (["--env", "hopper", "--steps", "0", "--out", "{tmp}/out"], "--steps: expected a positive integer"),
    (["--env", "hopper", "--steps", "2.5", "--out", "{tmp}/out"], "--steps: expected a positive integer"),
    (["--env", "hopper", "--stop-score", "nan", "--out", "{tmp}/out"], "--stop-score: expected a finite number"),
    (["--env", "hopper", "--eval-every", "0", "--out", "{tmp}/out"], "--eval-every: expected a positive integer"),
    (["--env", "hopper", "--eval-episodes", "x", "--out", "{tmp}/out"], "--eval-episodes: expected a positive"),
    (["--env", "hopper", "--warmup", "-1", "--out", "{tmp}/out"], "--warmup: expected an integer >= 0"),
    (["--env", "hopper", "--seed", "-1", "--out", "{tmp}/out"], "--seed: expected a seed"),
    (["--out", "{tmp}/out"], "error: --env is required (or --resume DIR)"),
    (["--env", "hopper", "--steps", "5"], "error: --out is required (or --resume DIR)"),
    (["--steps", "5"], "error: --env and --out are required (or --resume DIR)"),
    (["--env", "nope", "--out", "{tmp}/out"], "unknown env 'nope'"),
    (["--env", "hopper", "--steps", "10", "--out", "{tmp}/afile/x"], "not writable"),
    (["--env", "hopper", "--out", "{tmp}/afile"], "is a file, not a directory"),
    (["--env", "hopper", "--out", "{tmp}/run"], "already holds a SAC run (run.json"),
    (["--resume", "{tmp}/none"], "nothing to resume"),
    (["--resume", "{tmp}/afile"], "--resume takes a SAC run directory, not a file"),
    (["--resume", "{tmp}/run/run.json"], "not a file: did you mean "),
    (["--resume", "{tmp}/run", "--seed", "1"], "--seed: a resumed run keeps its own settings"),
    (["--resume", "{tmp}/run"], "replay holds the first 0 transitions, not the 50"),
    (["--resume", "{tmp}/broken"], "not a SAC run that can be resumed"),
])
def test_sac_refuses_bad_input_before_writing_anything(tmp_path, capsys, args, message):
    (tmp_path / "afile").write_text("a file")
    for name, run in (("run", RUN_JSON), ("broken", {"env": "hopper"})):
        (tmp_path / name).mkdir()
        (tmp_path / name / "run.json").write_text(json.dumps(run))
        (tmp_path / name / "state.json").write_text(json.dumps({"step": 50, "rng": {}}))
        (tmp_path / name / "state.msgpack").write_bytes(b"state")
    before = tree(tmp_path)
    assert message in refused(sac.main, [a.format(tmp=tmp_path) for a in args], capsys)
    assert tree(tmp_path) == before


def test_sac_refuses_a_run_directory_another_process_writes(tmp_path, capsys):
    from offrl_jax.system.cli import lock_run_dir

    held = lock_run_dir(tmp_path / "out")  # as a running `sac --out tmp/out` holds it
    try:
        before = tree(tmp_path)
        assert "being written by another process" in refused(
            sac.main, ["--env", "hopper", "--steps", "10", "--out", tmp_path / "out"], capsys)
        assert tree(tmp_path) == before
    finally:
        held.close()


def test_sac_refuses_more_steps_than_memory_holds_before_writing(tmp_path, capsys, monkeypatch):
    def no_memory(*args):
        raise MemoryError

    monkeypatch.setattr(sac, "ReplayBuffer", no_memory)
    assert sac.main(["--env", "hopper", "--steps", "2000000000", "--out", str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err.splitlines() == ["error: 2,000,000,000 steps: the replay of every transition does "
                                                    "not fit in memory"]
    assert not (tmp_path / "out").exists()


def test_sac_refuses_to_resume_a_state_of_another_layout(tmp_path, capsys):
    """A state.msgpack whose fields are not `SACState`'s (here the earlier layout: separate actor_opt, critic_opt and
    target_critic) is refused in one line by the command and by `train`, before anything is written."""
    from flax.serialization import msgpack_serialize

    out = tmp_path / "run"
    (out / "replay").mkdir(parents=True)
    (out / "run.json").write_text(json.dumps(RUN_JSON))
    (out / "state.json").write_text(json.dumps({"step": 50, "rng": {}}))
    np.savez(out / "replay" / "0000000_0000050.npz", rewards=np.zeros(50, np.float32))
    fields = ("actor", "critic", "target_critic", "log_alpha", "actor_opt", "critic_opt", "alpha_opt", "key")
    (out / "state.msgpack").write_bytes(msgpack_serialize({f: {"x": np.zeros(2, np.float32)} for f in fields}))
    before = tree(tmp_path)
    assert "a SAC state of the earlier layout" in refused(sac.main, ["--resume", out], capsys)
    with pytest.raises(ValueError, match="cannot resume: start a new run"):
        sac.train("hopper", 60, out, resume=True, progress=False)
    assert tree(tmp_path) == before


def test_sac_runs_resumes_and_keeps_its_run(tmp_path, capsys):
    out = tmp_path / "run"
    flags = ["--warmup", "20", "--eval-every", "20", "--eval-episodes", "1", "--no-progress"]
    assert sac.main(["--env", "hopper", "--steps", "40", "--out", str(out), *flags]) == 0
    assert sac.main(["--resume", str(out), "--steps", "60", "--no-progress"]) == 0
    run = json.loads((out / "run.json").read_text())
    assert run["steps_done"] == 60 and run["config"]["warmup_steps"] == 20 and run["resumed_at"] == [40]
    assert [c["step"] for c in run["checkpoints"]] == [20, 40, 60]
    capsys.readouterr()
    before = tree(out)
    assert "already holds a SAC run" in refused(sac.main, ["--env", "hopper", "--out", out], capsys)
    assert tree(out) == before


def test_sac_command_refuses_an_output_under_a_file_in_one_line(tmp_path):
    (tmp_path / "afile").write_text("a file")
    assert "not writable" in command("offrl_jax.data.generate.sac", "--env", "hopper", "--steps", "10", "--out",
                                     tmp_path / "afile" / "x")
    assert "--steps" in command("offrl_jax.data.generate.sac", "--env", "hopper", "--steps", "-10", "--out",
                                tmp_path / "out")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"]


# ------------------------------------------------------------------------------------------------------------ ship


@pytest.fixture(scope="module")
def sac_run(tmp_path_factory) -> Path:
    """A SAC run directory as `ship` reads it: run.json, log.jsonl, one hopper actor and one damaged checkpoint."""
    import flax
    import jax
    import numpy as np

    from offrl_jax.data.generate.collect import actor_module

    run = tmp_path_factory.mktemp("ship") / "run"
    (run / "checkpoints").mkdir(parents=True)
    actor = actor_module(3, (32, 32)).init(jax.random.PRNGKey(0), np.zeros((1, 11), np.float32))
    (run / "checkpoints" / "actor_0000010.msgpack").write_bytes(flax.serialization.to_bytes(actor))
    (run / "checkpoints" / "actor_0000020.msgpack").write_bytes(b"not a checkpoint")
    log = [{"step": step, "eval_return": 900.0 - step, "normalized_score": 28.4 - step / 10,
            "checkpoint": f"checkpoints/actor_{step:07d}.msgpack"} for step in (10, 20)]
    (run / "log.jsonl").write_text("".join(json.dumps(e) + "\n" for e in log))
    (run / "run.json").write_text(json.dumps({"env": "hopper", "gym_id": "Hopper-v5", "seed": 0}))
    return run


def variant(run: Path, where: Path, run_json: dict | None = None, log: str | None = None) -> Path:
    """A copy of `run` with another run.json or log.jsonl."""
    import shutil

    copy = shutil.copytree(run, where)
    if run_json is not None:
        (copy / "run.json").write_text(json.dumps(run_json))
    if log is not None:
        (copy / "log.jsonl").write_text(log)
    return copy


@pytest.mark.parametrize("args, message", [
    (["--run", "{tmp}/none", "--level", "medium"], "none/run.json: no such file"),
    (["--run", "{tmp}/nolog", "--level", "medium"], "nolog/log.jsonl: no such file"),
    (["--run", "{tmp}/badrun", "--level", "medium"], "badrun/run.json: not the run.json of a SAC run"),
    (["--run", "{tmp}/badlog", "--level", "expert", "--list"], "log.jsonl, line 3: not an evaluation of a SAC run"),
    (["--run", "{run}", "--level", "medium", "--step", "-1"], "--step: expected a positive integer"),
    (["--run", "{run}", "--level", "medium", "--episodes", "0"], "--episodes: expected a positive integer"),
    (["--run", "{run}", "--level", "expert", "--candidates", "nan"], "--candidates: expected a positive integer"),
    (["--run", "{run}", "--level", "medium", "--step", "30"], "--step 30: "),
    (["--run", "{run}", "--level", "medium", "--step", "20"], "actor_0000020.msgpack: not an actor checkpoint"),
    (["--run", "{run}", "--level", "expert", "--candidates", "2"], "actor_0000020.msgpack: not an actor checkpoint"),
    (["--run", "{tmp}/walker", "--level", "expert", "--step", "10"], "not walker2d's 17 and 6"),
    (["--run", "{tmp}/pen", "--level", "medium"], "no medium target score for pen"),
    (["--run", "{run}", "--level", "medium"], "hopper-medium.msgpack is already shipped; pass --overwrite"),
])
def test_ship_refuses_bad_input_before_evaluating(sac_run, tmp_path, capsys, monkeypatch, args, message):
    variant(sac_run, tmp_path / "nolog").joinpath("log.jsonl").unlink()
    variant(sac_run, tmp_path / "badrun", run_json={"env": "hopper"})
    variant(sac_run, tmp_path / "badlog", log=(sac_run / "log.jsonl").read_text() + "{\"step\": 3\n")
    variant(sac_run, tmp_path / "walker", run_json={"env": "walker2d", "gym_id": "Walker2d-v5", "seed": 0})
    variant(sac_run, tmp_path / "pen", run_json={"env": "pen", "gym_id": "AdroitHandPen-v1", "seed": 0})
    policies = tmp_path / "policies"
    policies.mkdir()
    (policies / "hopper-medium.msgpack").write_bytes(b"shipped")
    (policies / "policies.json").write_text("{}")
    monkeypatch.setattr(ship, "POLICY_DIR", policies)
    before, run_before = tree(tmp_path), tree(sac_run)
    assert message in refused(ship.main, [a.format(tmp=tmp_path, run=sac_run) for a in args], capsys)
    assert tree(tmp_path) == before and tree(sac_run) == run_before


@pytest.mark.parametrize("args, message", [
    (["--run", "{tmp}/none", "--steps", "10"], "none/run.json: no such file (--run takes a SAC run directory)"),
    (["--run", "{tmp}/badrun", "--steps", "10"], "badrun/run.json: not the run.json of a SAC run"),
    (["--run", "{tmp}/notjson", "--steps", "10"], "notjson/run.json: not the run.json of a SAC run"),
    (["--run", "{run}", "--steps", "10", "10"], "--steps 10 10: a step is given twice"),
    (["--run", "{run}", "--steps", "1e1", "20"], "actor_0000020.msgpack: not an actor checkpoint"),  # 1e1 is 10
    (["--run", "{run}", "--steps", "ten"], "--steps: expected a positive integer"),
    (["--run", "{run}", "--steps", "10", "--out", "/proc/scan"], "/proc/scan: not writable"),
])
def test_scan_checkpoints_refuses_bad_input_in_one_line_writing_nothing(sac_run, tmp_path, args, message):
    variant(sac_run, tmp_path / "badrun", run_json={"env": "hopper"})
    variant(sac_run, tmp_path / "notjson").joinpath("run.json").write_text("{")
    before, run_before = tree(tmp_path), tree(sac_run)
    out = [] if "--out" in args else ["--out", str(tmp_path / "scan")]
    result = run_module("experiments.scan_checkpoints", *[a.format(tmp=tmp_path, run=sac_run) for a in args], *out)
    assert result.returncode == 2 and message in result.stderr, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert tree(tmp_path) == before and tree(sac_run) == run_before  # --out is not created


def test_ship_command_names_the_missing_file_in_one_line(sac_run, tmp_path):
    assert "none/run.json: no such file" in command("offrl_jax.data.generate.ship", "--run", tmp_path / "none",
                                                    "--level", "medium")
    assert "--step" in command("offrl_jax.data.generate.ship", "--run", sac_run, "--level", "medium", "--step", "-1")
    assert not (tmp_path / "none").exists()


@pytest.mark.parametrize("module", ["offrl_jax.data.generate.sac", "offrl_jax.data.generate.ship"])
def test_usage_names_the_module(module, capsys):
    with pytest.raises(SystemExit):
        (sac if module.endswith("sac") else ship).main(["--help"])
    assert capsys.readouterr().out.startswith(f"usage: {module} ")


# --------------------------------------------------------------------------------------------------------- rollout


def test_rollout_keeps_an_existing_video_unless_told_to_replace_it(tmp_path):
    video = tmp_path / "old.gif"
    video.write_bytes(b"an earlier video")
    (tmp_path / "afile").write_text("a file")
    (tmp_path / "dir.gif").mkdir()
    before = tree(tmp_path)
    for args, message in [([video], "old.gif exists; pass --overwrite to replace it"),
                          ([video, "--overwrite"], "not a saved run"),  # the video is checked first, then the run
                          ([tmp_path / "afile" / "x.gif"], "afile is a file, not a directory"),
                          ([tmp_path / "dir.gif"], "dir.gif is a directory, not a file")]:
        line = command("offrl_jax.rollout", tmp_path / "none", "--episodes", "1", "--max-frames", "5", "--video",
                       *args)
        assert message in line, line
        assert tree(tmp_path) == before


def test_rollout_replaces_a_video_whole(tmp_path):
    """With --overwrite the new video takes the old one's place at once; no temporary file is left beside it."""
    video = tmp_path / "old.gif"
    video.write_bytes(b"an earlier video")
    script = ("import os, sys, numpy as np; from pathlib import Path; os.environ['MUJOCO_GL'] = 'egl'\n"
              "from offrl_jax.rollout import rollout\n"
              "class Still:\n    env = 'hopper'\n    def __call__(self, obs):\n        return np.zeros(3)\n"
              "rollout(Still(), 1, Path(sys.argv[1]), max_frames=2)\n")
    result = subprocess.run([sys.executable, "-c", script, str(video)], cwd=ROOT, capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 0, result.stderr
    import imageio.v2 as imageio

    assert len(imageio.mimread(video)) == 2
    assert [p.name for p in tmp_path.iterdir()] == ["old.gif"]


def test_an_unstarted_sac_run_is_discarded_and_a_users_file_kept(tmp_path):
    """Ctrl-C before a new SAC run saved its first state leaves nothing to resume: what it wrote goes, so the same
    --out can start again; a file of the user's in --out stays."""
    from offrl_jax.data.generate.sac_run import discard_unstarted

    out = tmp_path / "out"
    (out / "checkpoints").mkdir(parents=True)
    (out / "replay").mkdir()
    (out / "run.json").write_text("{}")
    (out / "log.jsonl").write_text("")
    (out / "notes.txt").write_text("mine")
    discard_unstarted(out)
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]
    (out / "notes.txt").unlink()
    discard_unstarted(out)
    assert not out.exists()
