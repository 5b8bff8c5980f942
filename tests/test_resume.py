"""A resume continues the run its files belong to, or refuses with one line and changes nothing
(`offrl_jax.run.resume`)."""
from __future__ import annotations

import dataclasses
import hashlib
import shutil
from pathlib import Path

import numpy as np
import pytest
from flax import serialization

from offrl_jax.run.resume import ResumeMismatch, shape_mismatch
from offrl_jax.run.runner import run_study
from offrl_jax.run.study import Study, Variant

from .conftest import synthetic_dataset


def tiny_study(**changes) -> Study:
    hidden = changes.pop("hidden", (32, 32))
    study = Study(name="t", dataset="synthetic", env="hopper", seeds=(0, 1), updates=200, eval_every=100,
                  eval_episodes=1, batch_size=32,
                  variants=(Variant.of("scratch", "td3bc", pretrain="none", hidden=hidden),))
    return dataclasses.replace(study, **changes)


def digest(run: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(run.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def half_run(tmp_path_factory):
    """A run stopped after its first chunk (its budget cut to 100 updates), to be resumed to 200."""
    run = tmp_path_factory.mktemp("resume") / "half"
    run_study(tiny_study(updates=100), run, synthetic_dataset(), progress=False)
    return run


def resumed_copy(half_run: Path, tmp_path: Path) -> Path:
    run = tmp_path / "run"
    shutil.copytree(half_run, run)
    return run


def test_an_edited_config_is_refused_naming_what_differs_and_nothing_changes(half_run, tmp_path):
    run = resumed_copy(half_run, tmp_path)
    before = digest(run)
    with pytest.raises(ResumeMismatch, match=r"made by another run \(variants; scratch: hidden \[32, 32\] -> "
                                             r"\[16, 16\]\); nothing was changed"):
        run_study(tiny_study(hidden=(16, 16)), run, synthetic_dataset(), resume=True, progress=False)
    assert digest(run) == before


@pytest.mark.parametrize("change, named", [
    ({"seeds": (0, 2)}, r"made by another run \(seeds"), ({"batch_size": 16}, r"made by another run \(batch size"),
    # other data: both fingerprints, why data may differ, and what to do
    ("data", r"trained on data with SHA-256 [0-9a-f]{12}\.\.\., and the data here has [0-9a-f]{12}\.\.\. \(a "
             r"dataset generated again, on another machine .*put back the data it trained on, or train again on "
             r"this data with --config .*config.json --dataset-path synthetic; nothing was changed"),
    ({"eval_episodes": 3}, r"made by another run \(evaluation"),
    ({"eval_every": 50}, r"made by another run \(evaluation")])
def test_a_checkpoint_of_another_run_is_refused_and_nothing_changes(half_run, tmp_path, change, named):
    run = resumed_copy(half_run, tmp_path)
    before = digest(run)
    study, data = tiny_study(), synthetic_dataset()
    if change == "data":
        data = synthetic_dataset(seed=1)
    else:
        study = dataclasses.replace(study, **change)
    with pytest.raises(ResumeMismatch, match=named):
        run_study(study, run, data, resume=True, progress=False)
    assert digest(run) == before


def test_fine_tuning_a_run_on_other_data_names_both_fingerprints_and_the_way_on(half_run):
    from offrl_jax.run.provenance import fingerprint
    from offrl_jax.run.resume import start_from

    study = dataclasses.replace(tiny_study(updates=100), start_from=str(half_run))
    group = study.groups()[0][0]
    with pytest.raises(ValueError, match=r"trained on data with SHA-256 .* not bit-identical\); --from goes on with "
                                         r"the data the run trained on: put it back, or train that run again on this "
                                         r"data \(--config .*config.json --dataset-path synthetic\)"):
        start_from(study, group, fingerprint(synthetic_dataset(seed=1)), None, 100)


def test_an_old_checkpoint_without_fingerprint_is_checked_by_its_shapes(half_run, tmp_path):
    run = resumed_copy(half_run, tmp_path)
    path = run / "checkpoints" / "scratch.msgpack"
    payload = serialization.msgpack_restore(path.read_bytes())
    payload.pop("identity")
    path.write_bytes(serialization.msgpack_serialize(payload))
    before = digest(run)
    with pytest.raises(ResumeMismatch, match=r"does not fit the networks .*shape \(2, 32"):
        run_study(tiny_study(hidden=(48, 48)), run, synthetic_dataset(), resume=True, progress=False)
    assert digest(run) == before
    run_study(tiny_study(), run, synthetic_dataset(), resume=True, progress=False)  # its own study: resumes


def test_a_checkpoint_with_rows_of_other_variants_is_refused(half_run, tmp_path):
    run = resumed_copy(half_run, tmp_path)
    path = run / "checkpoints" / "scratch.msgpack"
    payload = serialization.msgpack_restore(path.read_bytes())
    payload["history"] = payload["history"].replace('"scratch"', '"someone-else"')
    payload.pop("identity")
    path.write_bytes(serialization.msgpack_serialize(payload))
    with pytest.raises(ResumeMismatch, match="rows of other variants"):
        run_study(tiny_study(), run, synthetic_dataset(), resume=True, progress=False)


def test_a_checkpoint_whose_counter_disagrees_with_its_rows_is_refused(half_run, tmp_path):
    run = resumed_copy(half_run, tmp_path)
    path = run / "checkpoints" / "scratch.msgpack"
    payload = serialization.msgpack_restore(path.read_bytes())
    payload["update"] = -100
    path.write_bytes(serialization.msgpack_serialize(payload))
    before = digest(run)
    with pytest.raises(ResumeMismatch, match=r"update counter \(-100\) does not match its last evaluation \(100\)"):
        run_study(tiny_study(), run, synthetic_dataset(), resume=True, progress=False)
    assert digest(run) == before


def test_an_unreadable_checkpoint_is_one_line(half_run, tmp_path):
    run = resumed_copy(half_run, tmp_path)
    (run / "checkpoints" / "scratch.msgpack").write_bytes(b"\x00not msgpack")
    with pytest.raises(ResumeMismatch, match="not a readable checkpoint"):
        run_study(tiny_study(), run, synthetic_dataset(), resume=True, progress=False)


@pytest.mark.parametrize("given", ["config.json", "stray.txt"])
def test_resume_of_a_file_asks_for_the_run_directory(half_run, tmp_path, given):
    from tests.entry import run_module

    run = resumed_copy(half_run, tmp_path)
    path = run / given if given == "config.json" else tmp_path / given
    path.touch()
    before = digest(tmp_path)
    result = run_module("experiments.mujoco_medium", "--resume", path, "--no-progress")
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and "Traceback" not in result.stderr and len(lines) == 1, result.stderr
    mean = f": did you mean {run}?" if given == "config.json" else ""
    assert lines[0] == f"error: --resume takes a run directory, not a file{mean}"
    assert digest(tmp_path) == before


def without_seconds(curves: Path) -> list[list[str]]:
    return [line.split(",")[:5] + line.split(",")[6:] for line in curves.read_text().splitlines()]


@pytest.fixture(scope="module")
def whole_run(tmp_path_factory):
    run = tmp_path_factory.mktemp("resume") / "whole"
    run_study(tiny_study(), run, synthetic_dataset(), progress=False)
    return run


def test_its_own_checkpoint_resumes_to_the_uninterrupted_run(half_run, whole_run, tmp_path):
    run = resumed_copy(half_run, tmp_path)
    run_study(tiny_study(), run, synthetic_dataset(), resume=True, progress=False)
    assert without_seconds(run / "curves.csv") == without_seconds(whole_run / "curves.csv")


def test_a_missing_checkpoint_with_evaluations_is_refused(half_run, tmp_path):
    """Resuming would start that variant again and drop its evaluations: refused, nothing changed."""
    run = resumed_copy(half_run, tmp_path)
    (run / "checkpoints" / "scratch.msgpack").unlink()
    before = (run / "curves.csv").read_text()
    with pytest.raises(ResumeMismatch, match="scratch.msgpack is missing although curves.csv has evaluations of "
                                             "scratch up to update 100, which resuming would drop"):
        run_study(tiny_study(), run, synthetic_dataset(), resume=True, progress=False)
    assert (run / "curves.csv").read_text() == before


def test_an_edited_resolved_config_is_refused(half_run, tmp_path):
    """config.json's `resolved` values are what the run trained with: one edited by hand is refused on resume."""
    import json

    run = resumed_copy(half_run, tmp_path)
    raw = json.loads((run / "config.json").read_text())
    label = next(iter(raw["resolved"]))
    raw["resolved"][label]["gamma"] = 0.95
    (run / "config.json").write_text(json.dumps(raw))
    with pytest.raises(ResumeMismatch, match=f"resolved configs are not what its variants give \\({label}.gamma "
                                             "0.95 -> 0.99"):
        run_study(tiny_study(), run, synthetic_dataset(), resume=True, progress=False)
    # and as --config FILE: a replay would not read it, so it is refused too, writing nothing
    from tests.entry import run_module
    result = run_module("experiments.mujoco_medium", "--config", run / "config.json", "--out", tmp_path / "again")
    assert result.returncode == 2 and f"{label}.gamma 0.95 -> 0.99" in result.stderr, result.stderr
    assert not (tmp_path / "again").exists()


def test_a_config_field_added_since_is_no_difference_at_its_default():
    from offrl_jax.run.resume import identity_differences

    saved = {"variants": [["v", "td3bc", []]], "resolved": [{"alpha": 2.5}], "seeds": [0], "batch_size": 256,
             "env": "hopper", "data": "abc"}
    now = dict(saved, resolved=[{"alpha": 2.5, "new_switch": False}])
    assert identity_differences(saved, now, [{"alpha": 2.5, "new_switch": False}]) == []
    changed = dict(saved, resolved=[{"alpha": 2.5, "new_switch": True}])
    assert identity_differences(saved, changed, [{"alpha": 2.5, "new_switch": False}]) == \
        ["v: new_switch '(absent)' -> True"]


@pytest.mark.slow  # two CLI runs of two studies each (~2 minutes); the check itself is the one tested above
def test_a_multi_study_resume_checks_every_study_before_writing(tmp_path):
    """--resume --updates N on a run of several studies: a foreign checkpoint in the second study is refused before
    the first study (or the top-level config.json) is touched."""
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    out = tmp_path / "fig"
    tiny = ["--envs", "hopper", "walker2d", "--algos", "td3bc", "--pretrain", "none", "--updates", "100",
            "--eval-every", "100", "--seeds", "1", "--eval-episodes", "1", "--max-transitions", "2000",
            "--batch-size", "32", "--hidden", "16", "16", "--parallel", "1", "--no-progress"]
    done = subprocess.run([sys.executable, "-m", "experiments.figure2", *tiny, "--out", str(out)], cwd=root,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    studies = sorted(p.parent for p in out.glob("*/config.json"))
    foreign = next(p for p in studies[1].glob("checkpoints/*.msgpack") if ".best." not in p.name)
    foreign.write_bytes((studies[0] / "checkpoints" / foreign.name).read_bytes())  # the other env's checkpoint
    before = digest(out)
    result = subprocess.run([sys.executable, "-m", "experiments.figure2", "--resume", str(out), "--updates", "200"],
                            cwd=root, capture_output=True, text=True, timeout=600)
    assert result.returncode == 2 and "made by another run" in result.stderr, result.stderr
    assert "Traceback" not in result.stderr and digest(out) == before


def test_an_edac_run_resumes(tmp_path):
    """EDAC's state has empty slots (no target for the actor and the temperature): they check as equal."""
    edac = dataclasses.replace(tiny_study(), variants=(Variant.of("edac", "edac", pretrain="none", hidden=(16, 16),
                                                                  num_critics=2),))
    run_study(dataclasses.replace(edac, updates=100), tmp_path, synthetic_dataset(), progress=False)
    run_study(edac, tmp_path, synthetic_dataset(), resume=True, progress=False)
    assert "200" in (tmp_path / "curves.csv").read_text().splitlines()[-1].split(",")


def test_shape_mismatch_names_the_first_difference():
    expected = {"a": {"w": np.zeros((2, 3))}, "b": np.zeros(4), "none": None}
    assert shape_mismatch(expected, {"a": {"w": np.ones((2, 3))}, "b": np.ones(4), "none": None}) is None
    assert "/none" in shape_mismatch(expected, {"a": {"w": np.ones((2, 3))}, "b": np.ones(4), "none": np.ones(1)})
    assert shape_mismatch(expected, {"a": {"w": np.ones((2, 5))}, "b": np.ones(4), "none": None}) == \
        "/a/w: shape (2, 5), expected (2, 3)"
    assert "expected entries ['b', 'none'] not found" in shape_mismatch(expected, {"a": {"w": np.ones((2, 3))}})
    assert "unexpected entries ['c']" in shape_mismatch(expected, {"a": {"w": np.ones((2, 3))}, "b": np.ones(4),
                                                                   "none": None, "c": 1})


@pytest.mark.parametrize("where", ["checkpoints/scratch.msgpack", "checkpoints"])
def test_a_checkpoint_path_that_is_not_a_file_is_refused_before_anything(half_run, tmp_path, where):
    run = resumed_copy(half_run, tmp_path)
    target = run / where
    if target.is_dir():
        shutil.rmtree(target)
    else:
        target.unlink()
    if where.endswith(".msgpack"):
        target.mkdir()
    else:
        target.write_text("not a directory")
    before = {p: p.read_bytes() for p in run.rglob("*") if p.is_file()}
    with pytest.raises(ResumeMismatch, match="not a (checkpoint file|directory); nothing was changed"):
        run_study(tiny_study(), run, synthetic_dataset(), resume=True, progress=False)
    assert {p: p.read_bytes() for p in run.rglob("*") if p.is_file()} == before


def test_a_run_stopped_after_its_first_evaluation_has_a_checkpoint_to_resume_from(tmp_path, monkeypatch):
    """The first evaluation (here the hand-over at 100, off the 200-update checkpoint grid) writes a checkpoint
    along with its rows, so a stop right after it leaves a run that resumes instead of one refused for rows
    without a checkpoint."""
    from offrl_jax.run import progress
    from offrl_jax.run.resume import check_resume

    study = tiny_study(updates=400, eval_every=100, checkpoint_every=400,
                       variants=(Variant.of("pretrained", "td3bc", pretrain_updates=100, hidden=(32, 32)),))
    set_rows = progress.Recorder.set

    def stop_after_first(self, rows_by_label):
        set_rows(self, rows_by_label)
        raise KeyboardInterrupt

    monkeypatch.setattr(progress.Recorder, "set", stop_after_first)
    ds = synthetic_dataset()
    with pytest.raises(KeyboardInterrupt):
        run_study(study, tmp_path / "run", ds, progress=False)
    assert (tmp_path / "run" / "checkpoints" / "pretrained.msgpack").is_file()
    from offrl_jax.run.provenance import fingerprint
    check_resume(study, tmp_path / "run", ds, fingerprint(ds))  # raises if it would be refused


def test_checkpoint_every_evaluation_keeps_one_at_every_evaluation_off_grid_hand_over_included(tmp_path):
    """--checkpoint-every 0 is every evaluation: with the hand-over at 100, off the 150-update evaluation grid,
    the evaluations at 100, 150 and 300 each leave a kept checkpoint (150 was skipped, 50 updates after 100)."""
    from offrl_jax.run.resume import kept_updates

    study = tiny_study(updates=300, eval_every=150, checkpoint_every=0, keep_checkpoints=5,
                       variants=(Variant.of("pretrained", "td3bc", pretrain_updates=100, hidden=(32, 32)),))
    run_study(study, tmp_path / "run", synthetic_dataset(), progress=False)
    assert kept_updates(tmp_path / "run", study.variants) == [100, 150, 300]


def test_a_resume_keeps_the_rows_of_variants_not_yet_resumed_in_curves_csv(tmp_path, monkeypatch):
    """Variants in separate groups resume one after another; until a group resumes, its rows stay in curves.csv
    (they used to vanish from the file, kept only in its checkpoint, while the groups before it ran)."""
    from offrl_jax.run import progress
    from offrl_jax.run.results import read_curves

    variants = (Variant.of("a", "td3bc", pretrain="none", hidden=(32, 32)),
                Variant.of("b", "td3bc", pretrain="none", hidden=(16, 16)))
    run, ds = tmp_path / "run", synthetic_dataset()
    run_study(tiny_study(updates=100, variants=variants), run, ds, progress=False)
    study = tiny_study(variants=variants)
    assert len(study.groups()) == 2
    seen, set_rows = [], progress.Recorder.set

    def look_then_stop(self, rows_by_label):
        set_rows(self, rows_by_label)
        rows = read_curves(run / "curves.csv")
        seen.append(sorted({(r["variant"], r["update"]) for r in rows}))
        raise KeyboardInterrupt

    monkeypatch.setattr(progress.Recorder, "set", look_then_stop)
    with pytest.raises(KeyboardInterrupt):
        run_study(study, run, ds, resume=True, progress=False)
    assert seen == [[("a", 100), ("b", 100)]]  # group a restored (its rows from its checkpoint), b's rows kept


@pytest.mark.parametrize("keep", [0, 5])
def test_a_stop_as_the_last_checkpoint_is_written_leaves_the_best_before_it(tmp_path, monkeypatch, keep):
    """The best checkpoint is written before the last one: a stop in between leaves the last checkpoint behind it
    (a resume reaches it again), never ahead of it (it was lost: a resume rebuilds the best score from the
    checkpoint's rows, so it never wrote that .best).  A kept copy comes after the last checkpoint, and a directory
    with a best checkpoint alone has none to resume (an --overwrite then gives the earlier run back)."""
    from offrl_jax.app.outputs import has_checkpoint
    from offrl_jax.run import group
    from offrl_jax.run.resume import kept_updates

    study = tiny_study(updates=200, eval_every=100, checkpoint_every=0, keep_checkpoints=keep,
                       variants=(Variant.of("pretrained", "td3bc", pretrain_updates=100, hidden=(32, 32)),))
    save = group.save_checkpoint

    def stop_at_the_last(path, *args, **kwargs):
        if Path(path).name == "pretrained.msgpack":
            raise KeyboardInterrupt
        save(path, *args, **kwargs)

    monkeypatch.setattr(group, "save_checkpoint", stop_at_the_last)
    with pytest.raises(KeyboardInterrupt):
        run_study(study, tmp_path / "run", synthetic_dataset(), progress=False)
    ckpts = tmp_path / "run" / "checkpoints"
    assert sorted(p.name for p in ckpts.iterdir()) == ["pretrained.best.msgpack"]
    assert kept_updates(tmp_path / "run", study.variants) == [] and not has_checkpoint(tmp_path / "run")
