"""Every study module builds the variants the paper's figure needs (no training here)."""
import json

import pytest

from experiments import ablation, adroit_door, figure2, lambda_sweep, layernorm, mujoco_medium, qtransformer, replay
from offrl_jax.system.cli import UsageError


def build(module, argv):
    built = module.build(module.make_parser().parse_args(argv))
    return built if isinstance(built, list) else [built]


def labels(study):
    return [v.label for v in study.variants]


def test_main_job_default():
    (study,) = build(mujoco_medium, [])
    assert study.dataset == "hopper-medium" and labels(study) == ["pretrained", "scratch"]
    assert study.reference == "scratch" and study.seeds == (0, 1, 2, 3, 4) and study.updates == 40_000
    assert study.eval_every == 2_500 and study.eval_episodes == 5
    assert study.variants[0].given()["pretrain"] == "actor+critic"


def test_ablation_layernorm_lambda_qtransformer():
    assert labels(build(ablation, [])[0]) == ["pretrained", "actor-only", "critic-only", "scratch"]
    ln = build(layernorm, [])
    assert [s.env for s in ln] == ["hopper", "halfcheetah"] and len(ln[0].variants) == 4
    lam = build(lambda_sweep, [])[0]
    assert labels(lam) == ["lambda=0", "lambda=0.1", "lambda=0.5", "lambda=1", "scratch"]
    qt = build(qtransformer, [])[0]
    assert qt.variants[1].given()["target"] == "max_mc"


def test_figure2_and_replay():
    fig = build(figure2, [])
    assert len(fig) == 6
    edac = [s for s in fig if s.name == "figure2-walker2d-edac"][0]
    pretrained, scratch = (v.given() for v in edac.variants)
    assert edac.updates == 16_000 and edac.eval_every == 1_000 and pretrained["num_critics"] == 10
    assert pretrained["pretrain_updates"] == 12_000 and pretrained["actor_pretrain_fraction"] == 0.25
    assert "pretrain_updates" not in scratch  # the EDAC pre-training defaults go to the pre-trained arm only
    reordered = {s.name: s for s in build(figure2, ["--algos", "edac", "td3bc", "--envs", "hopper",
                                                    "--pretrain-updates", "6000"])}
    td3bc = reordered["figure2-hopper-td3bc"]
    assert td3bc.updates == 30_000 and td3bc.variants[0].given().get("num_critics") is None
    assert reordered["figure2-hopper-edac"].variants[0].given()["pretrain_updates"] == 6000  # flag wins
    assert [s.dataset for s in build(replay, [])] == ["hopper-medium-replay"]
    assert [s.dataset for s in build(replay, ["--levels", "medium-replay", "full-replay"])] == [
        "hopper-medium-replay", "hopper-full-replay"]


def test_figure2_beyond_the_paper_rebrac_and_iql():
    studies = {s.name: s for s in build(figure2, ["--algos", "rebrac", "iql", "--envs", "walker2d"])}
    rebrac, iql = studies["figure2-walker2d-rebrac"], studies["figure2-walker2d-iql"]
    assert rebrac.batch_size == 1024 and iql.batch_size == 256  # ReBRAC's published batch unless given
    assert [v.label for v in rebrac.variants] == ["pretrained", "scratch"] and rebrac.reference == "scratch"
    assert rebrac.config("pretrained").actor_beta == 0.05 and iql.config("scratch").pretrain == "none"
    given = build(figure2, ["--algos", "rebrac", "--envs", "hopper", "--batch-size", "512"])
    assert given[0].batch_size == 512


def test_figure2_runs_awac_with_its_twin_critics_whatever_edacs_ensemble():
    (awac,) = build(figure2, ["--algos", "awac", "--envs", "hopper", "--num-critics", "5"])
    assert awac.name == "figure2-hopper-awac" and awac.batch_size == 256
    assert [v.label for v in awac.variants] == ["pretrained", "scratch"]
    assert awac.config("pretrained").num_critics == 2 and awac.config("scratch").awac_lambda == 0.3333


def test_study_paper():
    studies = build(mujoco_medium, ["--study", "paper"])
    assert len(studies) == 6 and all(s.updates == 1_000_000 for s in studies)
    assert {(s.env, s.variants[0].algo) for s in studies} == {(e, a) for e in ("hopper", "halfcheetah", "walker2d")
                                                              for a in ("td3bc", "edac")}


@pytest.mark.parametrize("module, argv", [
    (qtransformer, ["--algo", "edac"]),  # the max(MC, Q) target is TD3+BC's
    (ablation, ["--pretrain", "actor"]),
    (lambda_sweep, ["--lam", "0.5"]),  # --lambdas
    (layernorm, ["--no-actor-ln"]),
    (replay, ["--level", "medium"]),  # --levels
    (figure2, ["--env", "walker2d"]),  # --envs
    (adroit_door, ["--updates", "5000"]),  # --scale
])
def test_a_study_does_not_accept_a_flag_it_would_ignore(module, argv, capsys):
    with pytest.raises(SystemExit) as e:
        module.main(argv)
    assert e.value.code == 2 and capsys.readouterr().err.startswith("error: unrecognized arguments")


@pytest.mark.parametrize("module, argv, refusal", [
    (figure2, ["--study", "paper"], "unrecognized arguments: --study paper"),  # the main job's only
    (mujoco_medium, ["--preset", "paper"], "invalid choice: 'paper'"),  # a whole study is no table of values
])
def test_a_whole_study_is_the_main_jobs_study_not_a_preset(module, argv, refusal, capsys):
    with pytest.raises(SystemExit) as e:
        module.main(argv)
    err = capsys.readouterr().err
    assert e.value.code == 2 and refusal in err and len(err.strip().splitlines()) == 1


def test_the_main_job_declares_its_default_preset():
    def alphas(argv):  # (alpha, where it came from) of every variant
        study = build(mujoco_medium, argv)[0]
        return {(study.config(v.label).alpha, study.sources()[v.label]["alpha"]) for v in study.variants}

    (default,) = build(mujoco_medium, [])
    assert all(v.preset == "published" for v in default.variants) and alphas([]) == {(2.5, "preset")}
    assert alphas(["--preset", "authors"]) == {(10.0, "per-env")}  # the paper's hopper value
    assert alphas(["--alpha", "7"]) == {(7.0, "flag")}
    assert alphas(["--env", "walker2d", "--preset", "authors"]) == {(5.0, "per-env")}
    assert "alpha" not in build(mujoco_medium, ["--algo", "edac"])[0].sources()["scratch"]  # TD3+BC's only
    args = mujoco_medium.make_parser().parse_args([])
    assert args.preset is None and mujoco_medium.given(args) == {}  # not a parsed flag: --config replays nothing
    with pytest.raises(SystemExit):  # one table of values at a time
        build(mujoco_medium, ["--preset", "authors", "published"])


def test_study_paper_refuses_the_flags_it_sets():
    with pytest.raises(UsageError, match="--study paper sets --env, --updates itself"):
        build(mujoco_medium, ["--study", "paper", "--env", "walker2d", "--updates", "1000"])
    # a flag typed with its default value is typed too (the command line says which were typed)
    from tests.entry import run_module
    result = run_module("experiments.mujoco_medium", "--study", "paper", "--updates", "40000")
    assert result.returncode == 2 and "--study paper sets --updates itself; leave it out" in result.stderr


def test_figure2_num_critics_is_edac_only():
    studies = {s.name: s for s in build(figure2, ["--envs", "hopper", "--num-critics", "4"])}
    assert all("num_critics" not in v.given() for v in studies["figure2-hopper-td3bc"].variants)
    assert all(v.given()["num_critics"] == 4 for v in studies["figure2-hopper-edac"].variants)
    cql = {s.name: s for s in build(figure2, ["--envs", "hopper", "--algos", "calql", "--num-critics", "4"])}
    assert all("num_critics" not in v.given() for v in cql["figure2-hopper-calql"].variants)


def test_alpha_sweep_builds_one_variant_per_value_and_groups_them():
    from offrl_jax.run.study import sweep_groups

    (study,) = build(mujoco_medium, ["--alpha", "1", "2.5", "10"])
    assert labels(study) == [f"{p} alpha={a}" for p in ("pretrained", "scratch") for a in ("1", "2.5", "10")]
    groups = sweep_groups(study.variants)
    assert [(len(g), name) for g, name in groups] == [(3, "alpha"), (3, "alpha")]
    lam = build(lambda_sweep, [])[0]  # lambda is not sweepable in one program (it switches code paths)
    assert all(name is None for _, name in sweep_groups(lam.variants))
    with pytest.raises(ValueError, match="sweep one hyper-parameter at a time"):
        build(mujoco_medium, ["--alpha", "1", "2", "--eta", "1", "2"])


def test_a_multi_study_run_saves_every_study_for_resume(tmp_path):
    from offrl_jax.app.outputs import saved_studies, studies_json

    studies = build(figure2, ["--envs", "hopper", "walker2d", "--algos", "td3bc", "--alpha", "1", "2.5"])
    (tmp_path / "config.json").write_text(studies_json(studies))  # what a new run writes before its first study
    assert len(studies) == 2 and saved_studies(tmp_path) == studies  # the ones not begun yet included
    (study,) = build(mujoco_medium, ["--hidden", "64", "64"])
    (tmp_path / "config.json").write_text(study.to_json())
    assert saved_studies(tmp_path) == study
    (tmp_path / "config.json").write_text('{"name": "x"}')
    with pytest.raises(UsageError, match="not a saved study"):
        saved_studies(tmp_path)


def test_runs_started_in_the_same_second_get_their_own_directories(tmp_path, monkeypatch):
    import argparse

    from offrl_jax.app.outputs import output_dir

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("time.strftime", lambda fmt: "20260101-000000")
    args = argparse.Namespace(resume=None, out=None, overwrite=False)
    first, second = output_dir(args, "study")[0], output_dir(args, "study")[0]
    assert (first.name, second.name) == ("20260101-000000", "20260101-000000-2") and first.is_dir()


def test_an_old_multi_study_config_resumes_the_studies_begun_and_names_the_others(tmp_path, capsys):
    import json

    from offrl_jax.app.outputs import saved_studies

    hopper, walker = build(figure2, ["--envs", "hopper", "walker2d", "--algos", "td3bc"])
    (tmp_path / "config.json").write_text(json.dumps({"studies": [hopper.name, walker.name]}))  # the old format
    with pytest.raises(UsageError, match="none of its studies had begun"):
        saved_studies(tmp_path)
    (tmp_path / hopper.name).mkdir()
    (tmp_path / hopper.name / "config.json").write_text(hopper.to_json())
    assert saved_studies(tmp_path) == [hopper]
    assert walker.name in capsys.readouterr().err


def test_a_failing_parallel_variant_stops_the_others_at_once(tmp_path, monkeypatch, tiny_dataset):
    """Group 0 runs until told to stop (or 60 s); group 1 fails at once: the run must not wait for group 0."""
    import time

    from offrl_jax.run import runner
    from offrl_jax.run.runner import Stopped, run_study
    from offrl_jax.run.study import Study, Variant

    def fake_group(study, group, swept, ds, data_sha256, out_dir, resume, bar, recorder, data=None):
        if group[0].label == "slow":
            deadline = time.monotonic() + 60
            while not recorder.stop.is_set() and time.monotonic() < deadline:
                time.sleep(0.01)
            raise Stopped("slow stopped")
        raise RuntimeError("fast failed")

    monkeypatch.setattr(runner, "run_group", fake_group)
    study = Study(name="t", dataset="hopper-medium", env="hopper", updates=1000, eval_every=100,
                  variants=(Variant.of("slow", "td3bc", pretrain="none"), Variant.of("fast", "cql")))
    tic = time.monotonic()
    with pytest.raises(RuntimeError, match="fast failed"):
        run_study(study, tmp_path, tiny_dataset, progress=False, parallel=2, processes=False)
    assert time.monotonic() - tic < 30


@pytest.mark.parametrize("module", ["theory", "adroit_random_scores"])
def test_commands_writing_into_out_refuse_an_earlier_one(module, tmp_path, capsys):
    import importlib

    command = importlib.import_module(f"experiments.{module}")
    earlier = tmp_path / command.OUTPUTS[0]  # one of the command's own files, from an earlier run
    earlier.write_text("earlier")
    with pytest.raises(SystemExit) as e:
        command.main(["--out", str(tmp_path)])
    assert e.value.code == 2 and "exists and is not empty; pass --overwrite" in capsys.readouterr().err
    assert earlier.read_text() == "earlier"


def test_random_scores_report_the_installed_reward_too():
    import numpy as np

    from experiments.adroit_random_scores import random_returns

    door, door_installed = random_returns("door", 2, seed=0)
    assert door.shape == door_installed.shape == (2,) and not np.allclose(door, door_installed)
    pen, pen_installed = random_returns("pen", 2, seed=0)  # pen's reward was not changed
    np.testing.assert_array_equal(pen, pen_installed)


def test_every_sweepable_field_sweeps_from_the_command_line():
    from offrl_jax.run.study import sweep_groups

    for flag, name in (("--tau", "tau"), ("--policy-noise", "policy_noise"), ("--noise-clip", "noise_clip")):
        (study,) = build(mujoco_medium, [flag, "0.1", "0.2", "--pretrain", "none"])
        assert labels(study) == [f"scratch {name}=0.1", f"scratch {name}=0.2"]
        assert [n for _, n in sweep_groups(study.variants)] == [name]
    (study,) = build(mujoco_medium, ["--algo", "edac", "--tau", "0.01", "0.02", "--pretrain", "none"])
    assert [n for _, n in sweep_groups(study.variants)] == ["tau"]


@pytest.mark.parametrize("field, value", [("resolved", []), ("resolved", None), ("runs", {}), ("runs", "x")])
def test_a_config_json_whose_records_have_the_wrong_shape_is_not_a_saved_study(field, value):
    from offrl_jax.run.study import Study, Variant

    study = Study(name="t", dataset="hopper-medium", env="hopper", variants=(Variant.of("a", "td3bc"),))
    raw = json.loads(study.to_json()) | {field: value}
    with pytest.raises(ValueError, match=f"'{field}' must"):
        Study.from_json(json.dumps(raw))


@pytest.mark.parametrize("name", ["../../elsewhere", "/abs", "."])
def test_an_old_multi_study_config_refuses_a_name_outside_its_run(tmp_path, name):
    import json

    from offrl_jax.app.outputs import saved_studies

    (tmp_path / "config.json").write_text(json.dumps({"studies": [name]}))  # the old format: names only
    with pytest.raises(UsageError, match="a study's name"):
        saved_studies(tmp_path)


@pytest.mark.parametrize("path, name", [("my-hopper.npz", "my-hopper-td3bc"),
                                        ("mujoco/hopper/medium-v0", "mujoco-hopper-medium-v0-td3bc")])
def test_a_study_on_a_users_dataset_is_named_after_it(path, name):
    """Not "hopper-medium-td3bc": the generated dataset of that name is not what trained."""
    (study,) = build(mujoco_medium, ["--dataset-path", path])
    assert study.name == name and study.dataset == path
