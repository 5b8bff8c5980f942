"""What a run records about itself: the resolved config of every variant and where the run came from."""
import json

import numpy as np
import pytest

from offrl_jax.algos import ALGOS, FAMILIES
from offrl_jax.run.provenance import command_line, fingerprint, run_record
from offrl_jax.run.runner import run_study
from offrl_jax.run.study import Study, Variant


def test_config_json_holds_the_resolved_config_and_round_trips(tiny_dataset):
    study = Study(name="t", dataset="hopper-medium", env="hopper", seeds=(0,), updates=20_000, eval_every=1_000,
                  variants=(Variant.of("default", "td3bc", "hopper"), Variant.of("a2.5", "td3bc", "hopper", alpha=2.5)))
    text = study.record_json(tiny_dataset)
    raw = json.loads(text)
    assert Study.from_json(text) == study  # what the run wrote about itself does not change the study
    resolved = raw["resolved"]
    assert resolved["default"]["alpha"] == 10.0  # hopper's per-env default, which the overrides do not show
    assert resolved["a2.5"]["alpha"] == 2.5
    for field in ("actor_lr", "critic_lr", "gamma", "tau", "hidden", "policy_noise", "layer_norm_eps", "timeouts"):
        assert field in resolved["default"], field
    (record,) = raw["runs"]
    assert record["command"].startswith("python")
    assert set(record["versions"]) >= {"python", "jax", "jaxlib", "flax", "optax", "gymnasium", "mujoco", "numpy"}
    assert record["backend"]["platform"] == "cpu" and record["backend"]["device_kind"]
    assert record["dataset"] == {"source": "hopper-medium", "name": tiny_dataset.name,
                                 "transitions": len(tiny_dataset), "sha256": fingerprint(tiny_dataset)}
    assert record["git"] is None or set(record["git"]) == {"commit", "dirty"}
    # a resume adds its own record and keeps the first
    again = json.loads(study.record_json(tiny_dataset, text))
    assert len(again["runs"]) == 2 and again["runs"][0] == record


@pytest.mark.parametrize("algo", list(ALGOS))
def test_with_no_env_and_no_preset_a_config_is_its_dataclass_defaults_and_its_algorithm_values(algo):
    from offrl_jax.algos import resolve

    entry = ALGOS[algo]
    resolved = resolve(algo, "")
    assert resolved.config == FAMILIES[entry.family].config(**entry.values)
    assert resolved.sources == {name: "algo" if name in entry.values else "default" for name in resolved.sources}


def test_resolve_applies_its_layers_in_order_and_says_where_each_value_came_from():
    from offrl_jax.algos import resolve
    from offrl_jax.algos.sacn import SACNConfig
    from offrl_jax.algos.td3bc import TD3BCConfig

    plain = resolve("rebrac")  # no env: the dataclass
    assert set(plain.sources.values()) == {"default"}
    anywhere = resolve("td3bc")
    assert (anywhere.config.alpha, anywhere.sources["alpha"]) == (2.5, "default") and TD3BCConfig().alpha == 2.5
    door = resolve("td3bc", "door")  # Adroit's alpha is named under each of its envs
    assert (door.config.alpha, door.sources["alpha"]) == (0.1, "per-env")
    hopper = resolve("td3bc", "hopper")
    assert (hopper.config.alpha, hopper.sources["alpha"]) == (10.0, "per-env")
    assert (hopper.config.gamma, hopper.sources["gamma"]) == (0.99, "default")
    preset = resolve("td3bc", "hopper", preset="published")
    assert (preset.config.alpha, preset.sources["alpha"]) == (2.5, "preset")  # over the per-env 10
    study = resolve("td3bc", "hopper", preset="published", overrides={"alpha": 4.0, "lam": 0.5, "tau": None},
                    flags=("lam",))
    assert (study.config.alpha, study.sources["alpha"]) == (4.0, "study")  # over the preset
    assert (study.config.lam, study.sources["lam"]) == (0.5, "flag")
    assert study.sources["tau"] == "default"  # a None override is no value
    algo = resolve("td3bc_cql", "pen")  # the algorithm's own value, then pen's per-env one over it
    assert (algo.config.cql_weight, algo.sources["cql_weight"]) == (1.0, "per-env")
    assert resolve("td3bc_cql", "hopper").sources["cql_weight"] == "algo"
    edac = resolve("sacn", "pen", "pen-cloned")  # SAC-N reads EDAC's ensemble sizes, not its eta
    assert (edac.config.num_critics, edac.sources["num_critics"]) == (20, "per-env")
    assert (edac.config.eta, edac.sources["eta"]) == (0.0, "algo")
    assert resolve("edac", "hopper").config == SACNConfig(num_critics=50, eta=1.0)
    unrecorded = resolve("td3bc", "hopper", overrides={"alpha": 3.0}, flags=None)  # a run saved before
    assert unrecorded.sources["alpha"] == "variant"


def test_config_json_records_where_each_value_came_from_and_an_older_one_still_reads(tiny_dataset):
    study = Study(name="t", dataset="hopper-medium", env="hopper", seeds=(0,), updates=20_000, eval_every=1_000,
                  variants=(Variant.make("a", "td3bc", "hopper", "hopper-medium", "authors",
                                         {"alpha": 4.0, "pretrain": "none"}, ("alpha",)),))
    raw = json.loads(study.record_json(tiny_dataset))
    sources = raw["sources"]["a"]
    assert set(sources) == set(raw["resolved"]["a"])  # every field
    assert (sources["alpha"], sources["pretrain"], sources["init"], sources["lam"]) == \
        ("flag", "study", "preset", "default")
    assert raw["resolved"]["a"]["init"] == "torch"
    assert Study.from_json(json.dumps(raw)) == study
    assert raw["variants"] == [{"label": "a", "algo": "td3bc", "preset": "authors", "env": "hopper",
                                "dataset": "hopper-medium"}]  # its config is `resolved`
    # a config.json written before variants carried their config (overrides, preset, flags): resolved as then
    older = dict(raw, variants=[{"label": "a", "algo": "td3bc", "overrides": [["alpha", 4.0], ["pretrain", "none"]],
                                 "preset": "authors", "flags": ["alpha"]}])
    assert Study.from_json(json.dumps(older)) == study
    # ... and before variants recorded their preset and flags, and before `sources`
    old = dict(raw, variants=[{"label": "a", "algo": "td3bc", "overrides": [["alpha", 4.0], ["pretrain", "none"]]}])
    del old["sources"]
    before = Study.from_json(json.dumps(old))
    assert before.config("a").alpha == 4.0 and before.config("a").init != "torch"  # no preset then
    assert before.sources()["a"]["alpha"] == "variant" and before.sources()["a"]["lam"] == "default"


def test_fingerprint_tells_datasets_apart(tiny_dataset):
    same = fingerprint(tiny_dataset)
    assert fingerprint(tiny_dataset.select(slice(0, len(tiny_dataset)))) == same
    assert fingerprint(tiny_dataset.select(slice(0, len(tiny_dataset) - 1))) != same
    changed = tiny_dataset.select(slice(0, len(tiny_dataset)))
    changed.rewards[0] += 1.0
    assert fingerprint(changed) != same


def test_summary_carries_the_resolved_config(tmp_path, tiny_dataset):
    study = Study(name="t", dataset="hopper-medium", env="hopper", seeds=(0,), updates=200, eval_every=100,
                  variants=(Variant.of("scratch", "td3bc", "hopper", pretrain="none", hidden=(16, 16)),),
                  eval_episodes=1)
    summary = run_study(study, tmp_path, tiny_dataset, progress=False)
    saved = json.loads((tmp_path / "config.json").read_text())
    in_summary = json.loads(json.dumps(summary[0]["config"]))
    assert in_summary == saved["resolved"]["scratch"]
    assert in_summary["alpha"] == 10.0 and in_summary["hidden"] == [16, 16]
    assert json.loads((tmp_path / "summary.json").read_text())[0]["config"]["pretrain"] == "none"


def test_command_line_is_the_typed_command():
    assert command_line(["x.py", "--alpha", "2.5 10"]).endswith("'2.5 10'")
    assert np.all(run_record()["versions"]["numpy"])
