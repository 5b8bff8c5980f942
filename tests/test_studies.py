"""Every study module builds the variants the paper's figure needs (no training here)."""
import pytest

from experiments import ablation, figure2, lambda_sweep, layernorm, mujoco_medium, qtransformer, replay
from experiments.mujoco_medium import parser


def build(module, prog, argv, **parser_kw):
    p = parser(prog, **parser_kw)
    if module is lambda_sweep:
        p.add_argument("--lambdas", type=float, nargs="+", default=[0.0, 0.1, 0.5, 1.0])
    if module is figure2:
        p.add_argument("--envs", nargs="+", default=["hopper", "halfcheetah", "walker2d"])
        p.add_argument("--algos", nargs="+", default=["td3bc", "edac"])
        p.add_argument("--edac-updates", type=int, default=30_000)
    if module is replay:
        p.add_argument("--levels", nargs="+", default=["medium-replay", "full-replay"])
    built = module.build(p.parse_args(argv))
    return built if isinstance(built, list) else [built]


def labels(study):
    return [v.label for v in study.variants]


def test_main_job_default():
    (study,) = build(mujoco_medium, "m", [])
    assert study.dataset == "hopper-medium" and labels(study) == ["pretrained", "scratch"]
    assert study.reference == "scratch" and study.seeds == (0, 1, 2)
    assert dict(study.variants[0].overrides)["pretrain"] == "actor+critic"


def test_ablation_layernorm_lambda_qtransformer():
    assert labels(build(ablation, "a", [])[0]) == ["pretrained", "actor-only", "critic-only", "scratch"]
    ln = build(layernorm, "l", [], env=None)
    assert [s.env for s in ln] == ["hopper", "halfcheetah"] and len(ln[0].variants) == 4
    lam = build(lambda_sweep, "s", [], env="halfcheetah")[0]
    assert labels(lam) == ["lambda=0", "lambda=0.1", "lambda=0.5", "lambda=1", "scratch"]
    qt = build(qtransformer, "q", [])[0]
    assert dict(qt.variants[1].overrides)["target"] == "max_mc"


def test_figure2_and_replay():
    fig = build(figure2, "f", [])
    assert len(fig) == 6
    edac = [s for s in fig if s.name == "figure2-walker2d-edac"][0]
    assert edac.updates == 30_000 and dict(edac.variants[0].overrides)["num_critics"] == 10
    assert [s.dataset for s in build(replay, "r", [])] == ["hopper-medium-replay", "hopper-full-replay"]


def test_preset_paper():
    studies = build(mujoco_medium, "m", ["--preset", "paper"])
    assert len(studies) == 6 and all(s.updates == 1_000_000 for s in studies)


@pytest.mark.parametrize("algo", ["edac", "cql"])
def test_qtransformer_target_is_td3bc_only(algo):
    with pytest.raises(ValueError, match="not a hyper-parameter"):
        build(qtransformer, "q", ["--algo", algo])
