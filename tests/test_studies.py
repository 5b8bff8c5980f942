"""Every study module builds the variants the paper's figure needs (no training here)."""
import pytest

from experiments import ablation, figure2, lambda_sweep, layernorm, mujoco_medium, qtransformer, replay


def build(module, argv):
    built = module.build(module.make_parser().parse_args(argv))
    return built if isinstance(built, list) else [built]


def labels(study):
    return [v.label for v in study.variants]


def test_main_job_default():
    (study,) = build(mujoco_medium, [])
    assert study.dataset == "hopper-medium" and labels(study) == ["pretrained", "scratch"]
    assert study.reference == "scratch" and study.seeds == (0, 1, 2) and study.updates == 60_000
    assert dict(study.variants[0].overrides)["pretrain"] == "actor+critic"


def test_ablation_layernorm_lambda_qtransformer():
    assert labels(build(ablation, [])[0]) == ["pretrained", "actor-only", "critic-only", "scratch"]
    ln = build(layernorm, [])
    assert [s.env for s in ln] == ["hopper", "halfcheetah"] and len(ln[0].variants) == 4
    lam = build(lambda_sweep, [])[0]
    assert labels(lam) == ["lambda=0", "lambda=0.1", "lambda=0.5", "lambda=1", "scratch"]
    qt = build(qtransformer, [])[0]
    assert dict(qt.variants[1].overrides)["target"] == "max_mc"


def test_figure2_and_replay():
    fig = build(figure2, [])
    assert len(fig) == 6
    edac = [s for s in fig if s.name == "figure2-walker2d-edac"][0]
    pretrained, scratch = (dict(v.overrides) for v in edac.variants)
    assert edac.updates == 16_000 and edac.eval_every == 1_000 and pretrained["num_critics"] == 10
    assert pretrained["pretrain_updates"] == 12_000 and pretrained["actor_pretrain_fraction"] == 0.25
    assert "pretrain_updates" not in scratch  # the EDAC pre-training defaults go to the pre-trained arm only
    reordered = {s.name: s for s in build(figure2, ["--algos", "edac", "td3bc", "--envs", "hopper",
                                                    "--pretrain-updates", "6000"])}
    td3bc = reordered["figure2-hopper-td3bc"]
    assert td3bc.updates == 30_000 and dict(td3bc.variants[0].overrides).get("num_critics") is None
    assert dict(reordered["figure2-hopper-edac"].variants[0].overrides)["pretrain_updates"] == 6000  # flag wins
    assert [s.dataset for s in build(replay, [])] == ["hopper-medium-replay"]
    assert [s.dataset for s in build(replay, ["--levels", "medium-replay", "full-replay"])] == [
        "hopper-medium-replay", "hopper-full-replay"]


def test_preset_paper():
    studies = build(mujoco_medium, ["--preset", "paper"])
    assert len(studies) == 6 and all(s.updates == 1_000_000 for s in studies)


@pytest.mark.parametrize("algo", ["edac", "cql"])
def test_qtransformer_target_is_td3bc_only(algo):
    with pytest.raises(ValueError, match="not a hyper-parameter"):
        build(qtransformer, ["--algo", algo])


def test_alpha_sweep_builds_one_variant_per_value_and_groups_them():
    from offrl_jax.runner import sweep_groups

    (study,) = build(mujoco_medium, ["--alpha", "1", "2.5", "10"])
    assert labels(study) == [f"{p} alpha={a}" for p in ("pretrained", "scratch") for a in ("1", "2.5", "10")]
    groups = sweep_groups(study.variants)
    assert [(len(g), name) for g, name in groups] == [(3, "alpha"), (3, "alpha")]
    lam = build(lambda_sweep, [])[0]  # lambda is not sweepable in one program (it switches code paths)
    assert all(name is None for _, name in sweep_groups(lam.variants))
    with pytest.raises(ValueError, match="sweep one hyper-parameter at a time"):
        build(mujoco_medium, ["--alpha", "1", "2", "--eta", "1", "2"])
