"""--dry-run shows what a study will run: each value it prints is the value a run of the same command records in its
config.json (`resolved`, and where it came from: `sources`), and it writes, loads and trains nothing."""
import ast
import json
import re
from pathlib import Path

import h5py
import numpy as np
import pytest

from tests.conftest import synthetic_dataset
from tests.entry import run_module

ROOT = Path(__file__).resolve().parents[1]
FIELD = re.compile(r"^    (\w+) = (.+)  \(([\w-]+)\)$")
TINY = ["--seeds", "1", "--eval-episodes", "1", "--batch-size", "32", "--no-progress", "--parallel", "1"]
MUJOCO = [*TINY, "--updates", "200", "--eval-every", "100", "--pretrain-updates", "100", "--hidden", "16", "16"]
# study: the flags of a tiny run of it ({hopper} and {door} are tiny datasets)
STUDIES = {
    "experiments.mujoco_medium": [*MUJOCO, "--dataset-path", "{hopper}", "--alpha", "3"],
    "experiments.ablation": [*MUJOCO, "--dataset-path", "{hopper}", "--preset", "authors"],
    "experiments.lambda_sweep": [*MUJOCO, "--dataset-path", "{hopper}", "--env", "hopper", "--lambdas", "0", "0.5"],
    "experiments.layernorm": [*MUJOCO, "--dataset-path", "{hopper}", "--env", "hopper"],
    "experiments.qtransformer": [*MUJOCO, "--dataset-path", "{hopper}"],
    "experiments.replay": [*MUJOCO, "--dataset-path", "{hopper}"],
    "experiments.figure2": [*MUJOCO, "--dataset-path", "{hopper}", "--envs", "hopper", "--algos", "td3bc", "edac",
                            "--edac-updates", "200", "--edac-eval-every", "100", "--num-critics", "2"],
    "experiments.finetune": [*MUJOCO, "--dataset-path", "{hopper}", "--env", "hopper", "--arms", "pretrained",
                             "scratch", "--online-steps", "200", "--online-block", "100", "--online-eval-every", "100",
                             "--replay", "append"],
    "experiments.adroit_door": [*TINY, "--dataset-path", "{door}", "--variants", "BC", "pre-trained TD3+BC+CQL",
                                "--scale", "0.001", "--alpha", "1"],
}


@pytest.fixture(scope="module")
def datasets(tmp_path_factory) -> dict[str, str]:
    where = tmp_path_factory.mktemp("data")
    paths = {}
    for env, obs_dim, act_dim in (("hopper", 11, 3), ("door", 39, 28)):
        ds = synthetic_dataset(2000, env=env, obs_dim=obs_dim, act_dim=act_dim, episode_len=100)
        paths[env] = str(where / f"{env}-tiny.hdf5")
        with h5py.File(paths[env], "w") as f:
            for key in ("observations", "actions", "rewards", "next_observations", "terminals", "timeouts"):
                f[key] = np.clip(getattr(ds, key), -1, 1) if key == "actions" else getattr(ds, key)
    return paths


def printed(stdout: str) -> dict[str, dict[str, dict[str, tuple]]]:
    """{study: {variant: {field: (value, source)}}} from a dry run's output."""
    found: dict = {}
    for line in stdout.splitlines():
        if line.startswith("study "):
            study = found.setdefault(line.split()[1], {})
        elif line.startswith("  variant "):
            variant = study.setdefault(line[len("  variant "):].rsplit(": ", 1)[0], {})
        elif match := FIELD.match(line):
            variant[match[1]] = (json.loads(match[2]), match[3])
    return found


def recorded(out: Path) -> dict[str, dict[str, dict[str, tuple]]]:
    """The same from a run's config.json files (one per study)."""
    found = {}
    for path in [out / "config.json", *out.glob("*/config.json")]:
        raw = json.loads(path.read_text())
        if "resolved" in raw:
            found[raw["name"]] = {label: {k: (v, raw["sources"][label][k]) for k, v in config.items()}
                                  for label, config in raw["resolved"].items()}
    return found


@pytest.mark.parametrize("module", [pytest.param(m, marks=pytest.mark.slow) if m == "experiments.adroit_door" else m
                                    for m in STUDIES])  # adroit_door: 30 evaluations on door at any --scale (~2 min)
def test_dry_run_prints_what_the_run_records_and_writes_nothing(module, datasets, tmp_path):
    argv = [a.format(**datasets) for a in STUDIES[module]]
    # in a folder of its own (a plain `python -m` there, the work tree on its path), where runs/ would appear
    dry = run_module(module, *argv, "--out", tmp_path / "dry", "--dry-run", cwd=tmp_path, env={"PYTHONPATH": str(ROOT)})
    assert dry.returncode == 0, dry.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no --out, no runs/, no dataset cache here
    shown = printed(dry.stdout)
    assert shown and all(shown.values()) and all(v for s in shown.values() for v in s.values())
    assert "budget: 200 updates per variant" in dry.stdout or module == "experiments.adroit_door"
    assert "phases: " in dry.stdout
    run = run_module(module, *argv, "--out", tmp_path / "run", timeout=600)
    assert run.returncode == 0, run.stderr
    assert shown == recorded(tmp_path / "run")


@pytest.mark.parametrize("path, fragment", [("missing.hdf5", "missing.hdf5: no such file, directory or Minari"),
                                             ("nothing", "nothing")])
def test_dry_run_refuses_data_that_is_not_there(tmp_path, path, fragment):
    dry = run_module("experiments.mujoco_medium", "--dry-run", "--dataset-path", tmp_path / path)
    assert dry.returncode == 2 and fragment in dry.stderr and len(dry.stderr.strip().splitlines()) == 1, dry.stderr
    assert dry.stdout == ""


def test_dry_run_sources_name_each_layer():
    dry = run_module("experiments.mujoco_medium", "--dry-run", "--lam", "0.5")
    assert dry.returncode == 0, dry.stderr
    (study,) = printed(dry.stdout).values()
    pretrained = study["pretrained"]
    assert pretrained["alpha"] == (2.5, "preset")  # the study's default preset, over hopper's 10
    assert pretrained["lam"] == (0.5, "flag") and pretrained["pretrain"] == ("actor+critic", "study")
    assert pretrained["gamma"] == (0.99, "default")
    edac = printed(run_module("experiments.mujoco_medium", "--dry-run", "--algo", "edac", "--env",
                              "halfcheetah").stdout)["halfcheetah-medium-edac"]["scratch"]
    assert edac["num_critics"] == (10, "per-env") and edac["lam"] == (0.1, "per-env")


def test_finetune_on_door_takes_corls_door_values_and_pretrain_only_keeps_the_whole_budget():
    dry = run_module("experiments.finetune", "--dry-run", "--env", "door", "--algo", "rebrac",
                     "--pretrain-updates", "3000", "--updates", "8000")
    assert dry.returncode == 0, dry.stderr
    arms = printed(dry.stdout)["door-human-rebrac"]  # --env door without --level: door-human
    pretrained = arms["pretrained"]
    assert pretrained["actor_beta"] == pretrained["critic_beta"] == (0.1, "per-env")
    assert arms["pretrained"]["pretrain_updates"] == (3000, "flag")
    assert arms["pretrain-only"]["pretrain_updates"] == (8000, "study")  # the flag sets the other arms'
    cloned = printed(run_module("experiments.finetune", "--dry-run", "--env", "door", "--level", "cloned", "--algo",
                                "iql", "--arms", "scratch").stdout)["door-cloned-iql"]["scratch"]
    assert cloned["expectile"] == (0.8, "per-env")


def test_dry_run_of_a_resume_shows_the_saved_run(tmp_path, datasets):
    out = tmp_path / "run"
    argv = [a.format(**datasets) for a in STUDIES["experiments.mujoco_medium"]]
    assert run_module("experiments.mujoco_medium", *argv, "--out", out).returncode == 0
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    dry = run_module("experiments.mujoco_medium", "--resume", out, "--updates", "400", "--dry-run")
    assert dry.returncode == 0, dry.stderr
    assert "budget: 400 updates per variant" in dry.stdout and printed(dry.stdout) == recorded(out)
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before


OPTION = re.compile(r" (?=--[a-z][a-z0-9-]*(?: [A-Z{\[]|, --))")  # where --help starts an option's entry


def stated_defaults(help_text: str) -> dict[str, tuple[str | None, list[tuple[str | None, str | None, object]]]]:
    """{field: (the env its default is stated for, or None for every env, [(algo, label, value)])} of each option
    whose help ends with its default for the study's own algorithm ("with --algo X" ones are left out)."""
    found = {}
    for entry in OPTION.split(" ".join(help_text.split())):
        flag, _, text = entry.partition(" ")
        if "Default: " not in text or not flag.startswith("--"):
            continue
        stated = re.sub(r" \(preset [\w, ]+\)$", "", text.rsplit("Default: ", 1)[1])
        if stated.startswith("with --algo"):
            continue
        env = None
        if match := re.fullmatch(r"(.*) on (\w+) \(.*\)", stated):
            stated, env = match[1], match[2]
        parts = re.findall(r"(.+?) for ([a-z0-9_]+)(?: ([^,\s]+))?(?:, |$)", stated)
        values = [(algo, label or None, part) for part, algo, label in parts] or [(None, None, stated)]
        try:
            found[flag[2:].rstrip(",").replace("-", "_")] = (
                env, [(a, label, ast.literal_eval(v)) for a, label, v in values])
        except (ValueError, SyntaxError):  # not a value (a run flag's prose default)
            continue
    return found


def plain(value):
    return [plain(x) for x in value] if isinstance(value, (list, tuple)) else value


@pytest.mark.parametrize("module", [m for m in STUDIES if m != "experiments.adroit_door"])
def test_help_states_the_default_the_study_runs(module):
    """For every hyper-parameter flag, --help's default (for the study's default env and preset) is the value its
    dry run shows for every variant that has the field; a per-env field names its default env."""
    shown = run_module(module, "--help")
    dry = run_module(module, "--dry-run")
    assert shown.returncode == 0 and dry.returncode == 0, shown.stderr + dry.stderr
    runs = [(name.rsplit("-", 1)[-1], name, variants) for name, variants in printed(dry.stdout).items()]
    env_of = {name: next(e for e in ("halfcheetah", "walker2d", "hopper") if e in name) for _, name, _ in runs}
    stated = stated_defaults(shown.stdout)
    assert {"alpha", "gamma", "num_critics", "tau"} <= set(stated), sorted(stated)
    checked = 0
    for field, (env, values) in stated.items():
        for algo, name, variants in runs:
            if env is not None and env_of[name] != env:
                continue
            for label, config in variants.items():
                if field not in config:
                    continue
                want = [v for a, lab, v in values if a in (None, algo) and lab in (None, label)]
                assert want, f"{module} --{field}: no default stated for {algo} {label}"
                assert plain(want[0]) == plain(config[field][0]), (module, field, env, algo, label)
                checked += 1
    assert checked > 0
    if module == "experiments.mujoco_medium":
        assert stated["alpha"] == (None, [(None, None, 2.5)]) and "Default: published" in " ".join(shown.stdout.split())
    if module == "experiments.ablation":  # the paper's per-env alphas, hopper's first
        assert stated["alpha"] == ("hopper", [(None, None, 10.0)])
        assert "Default: none" in " ".join(shown.stdout.split())


def _committed_configs() -> list[Path]:
    """Every results/**/config.json in the repository that is one study's (a multi-study run's top file lists them)."""
    return sorted(p for p in (ROOT / "results").rglob("config.json") if "studies" not in json.loads(p.read_text()))


@pytest.mark.parametrize("path", _committed_configs(), ids=lambda p: str(p.relative_to(ROOT / "results")))
def test_every_committed_run_resolves_to_the_values_it_recorded(path):
    """Replayed through the code --config, --resume and --dry-run use, a committed run's variants resolve to the
    values and sources its config.json recorded (a field added after the run has no recorded source)."""
    from offrl_jax.run.resume import resolved_differences
    from offrl_jax.run.study import Study

    study = Study.from_json(path.read_text())
    assert resolved_differences(study, path) == []
    saved = json.loads(path.read_text()).get("sources") or {}
    now = study.sources()
    assert set(saved) <= set(now)
    for label, fields in saved.items():
        assert {k: now[label][k] for k in fields} == fields
