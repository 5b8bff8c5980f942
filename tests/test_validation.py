"""The Python API's config constructors reject invalid hyper-parameters with one line naming the field."""
import dataclasses
import json
import math

import pytest

from offrl_jax.algos import ALGOS, make_config
from offrl_jax.policy import load_policy
from offrl_jax.run.study import Study, Variant


@pytest.mark.parametrize("algo, overrides, message", [
    ("td3bc", {"gamma": 0.0}, "gamma = 0.0 must be in (0, 1)"),
    ("td3bc", {"gamma": 1.0}, "gamma = 1.0 must be in (0, 1)"),
    ("td3bc", {"gamma": 1.01}, "gamma = 1.01 must be in (0, 1)"),
    ("edac", {"tau": 0.0}, "tau = 0.0 must be in (0, 1]"),
    ("edac", {"tau": 1.5}, "tau = 1.5 must be in (0, 1]"),
    ("td3bc", {"lam": -0.1}, "lam = -0.1 must be in [0, 1]"),
    ("td3bc", {"lam": 1.1}, "lam = 1.1 must be in [0, 1]"),
    ("edac", {"num_critics": 1}, "num_critics = 1 must be >= 2"),
    ("td3bc", {"pretrain_updates": -5}, "pretrain_updates = -5 must be >= 0"),
    ("td3bc", {"actor_lr": 0.0}, "actor_lr = 0.0 must be positive"),
    ("td3bc", {"pretrain": "both"}, "pretrain = 'both' must be one of"),
    ("td3bc", {"no_such_field": 1}, "'no_such_field' is not a hyper-parameter of td3bc"),
    ("dqn", {}, "unknown algorithm 'dqn'; valid: bc, td3bc"),
    ("bc", {"pretrain": "none"}, "pretrain = 'none' has no effect on the BC baseline"),
    ("td3bc_cql", {"cql_actions": 0}, "cql_actions = 0 must be >= 1"),
    ("edac", {"entropy_batch": 0}, "entropy_batch = 0 must be >= 1"),
    ("td3bc", {"policy_noise": -0.5}, "TD3BCConfig.policy_noise = -0.5 must be >= 0"),
    ("td3bc", {"noise_clip": -1.0}, "TD3BCConfig.noise_clip = -1.0 must be >= 0"),
    ("rebrac", {"policy_noise": -0.5}, "ReBRACConfig.policy_noise = -0.5 must be >= 0"),
    ("rebrac", {"noise_clip": -1.0}, "ReBRACConfig.noise_clip = -1.0 must be >= 0"),
    ("td3bc_cql", {"cql_temperature": 0.0}, "TD3BCConfig.cql_temperature = 0.0 must be positive"),
    ("td3bc_cql", {"cql_temperature": -1.0}, "TD3BCConfig.cql_temperature = -1.0 must be positive"),
    ("cql", {"cql_temperature": 0.0}, "CQLConfig.cql_temperature = 0.0 must be positive"),
    ("td3bc_cql", {"cql_weight": -5.0}, "TD3BCConfig.cql_weight = -5.0 must be >= 0"),
    ("edac_bc", {"bc_weight": -1.0}, "SACNConfig.bc_weight = -1.0 must be >= 0"),
    ("cql", {"cql_alpha": -10.0}, "CQLConfig.cql_alpha = -10.0 must be >= 0"),
    ("calql", {"calibration_online": "always"}, "CQLConfig.calibration_online = 'always' must be 'episode' or 'off'"),
    ("bc", {"pretrain": "actor+critic"}, "pretrain = 'actor+critic' has no effect on the BC baseline"),
    ("bc", {"pretrain_auto": True}, "pretrain_auto = True has no effect on the BC baseline"),
    # types, checked against each field's annotation before its value
    ("td3bc", {"alpha": True}, "TD3BCConfig.alpha = True must be a number"),
    ("td3bc", {"alpha": "2.5"}, "TD3BCConfig.alpha = '2.5' must be a number"),
    ("td3bc", {"alpha": 10**400}, "0000 must be a finite number"),
    ("td3bc", {"hidden": (16.5,)}, "TD3BCConfig.hidden = (16.5,) must be a tuple of integers"),
    ("td3bc", {"hidden": 16}, "TD3BCConfig.hidden = 16 must be a tuple of integers"),
    ("td3bc", {"hidden": (True, 8)}, "TD3BCConfig.hidden = (True, 8) must be a tuple of integers"),
    ("td3bc", {"hidden": (0, 8)}, "TD3BCConfig.hidden = (0, 8) must be positive layer widths"),
    ("td3bc", {"actor_hidden": "256"}, "TD3BCConfig.actor_hidden = '256' must be a tuple of integers or None"),
    ("td3bc", {"policy_delay": 2.0}, "TD3BCConfig.policy_delay = 2.0 must be an integer"),
    ("td3bc", {"policy_delay": True}, "TD3BCConfig.policy_delay = True must be an integer"),
    ("edac", {"num_critics": 10.0}, "SACNConfig.num_critics = 10.0 must be an integer"),
    ("td3bc", {"actor_layer_norm": 1}, "TD3BCConfig.actor_layer_norm = 1 must be True or False"),
    ("edac", {"backup_entropy": "no"}, "SACNConfig.backup_entropy = 'no' must be True or False"),
    ("td3bc", {"init": 3}, "TD3BCConfig.init = 3 must be a string"),
    ("td3bc", {"lambda_mode": "both"}, "TD3BCConfig.lambda_mode = 'both' must be 'loss' or 'target'"),
    ("td3bc", {"pretrain": ["actor"]}, "TD3BCConfig.pretrain = ['actor'] must be one of none, actor"),
    ("edac", {"hidden_bias": "0.1"}, "SACNConfig.hidden_bias = '0.1' must be a number or None"),
    ("edac", {"log_std_bounds": (-5.0,)}, "SACNConfig.log_std_bounds = (-5.0,) must be a tuple of 2 finite numbers"),
    ("edac", {"log_std_bounds": (-math.inf, 2.0)}, "SACNConfig.log_std_bounds = (-inf, 2.0) must be a tuple of 2"),
    ("edac", {"log_std_bounds": ("a", 2.0)}, "SACNConfig.log_std_bounds = ('a', 2.0) must be a tuple of 2"),
])
def test_config_rejects(algo, overrides, message):
    with pytest.raises(ValueError) as err:
        make_config(algo, "hopper", **overrides)
    assert message in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("env", ["ant", "hopper-medium", "Hopper", 3])
def test_config_rejects_an_unknown_env(env):
    with pytest.raises(ValueError) as err:
        make_config("td3bc", env, "x")
    assert f"unknown env {env!r}; valid: hopper, halfcheetah" in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("algo", sorted(ALGOS))
@pytest.mark.parametrize("env", ["", "hopper", "halfcheetah", "walker2d", "pen", "door", "hammer", "relocate"])
def test_every_default_config_passes_its_type_checks(algo, env):
    for preset in (None, "authors"):
        make_config(algo, env, f"{env}-cloned", preset=preset)


@pytest.mark.parametrize("algo, overrides, stored", [
    ("edac", {"hidden": [8, 8], "log_std_bounds": [-20, 2], "eta": 1, "hidden_bias": 0},
     {"hidden": (8, 8), "log_std_bounds": (-20.0, 2.0), "eta": 1.0, "hidden_bias": 0.0}),
    ("td3bc", {"alpha": 10, "actor_hidden": [16, 16, 16], "policy_delay": 3},
     {"alpha": 10.0, "actor_hidden": (16, 16, 16), "policy_delay": 3}),
])
def test_config_takes_json_forms_and_stores_the_declared_types(algo, overrides, stored):
    config = make_config(algo, "hopper", **overrides)
    for name, value in stored.items():
        assert getattr(config, name) == value and type(getattr(config, name)) is type(value)
    # a resolved config written to config.json and read back is the same config
    replayed = make_config(algo, "hopper", **json.loads(json.dumps(dataclasses.asdict(config))))
    assert replayed == config and hash(replayed) == hash(config)


@pytest.mark.parametrize("fields, message", [
    ({"updates": 0}, "Study.updates = 0 must be a positive integer"),
    ({"batch_size": -1}, "Study.batch_size = -1 must be a positive integer"),
    ({"eval_every": 0}, "Study.eval_every = 0 must be a positive integer"),
    ({"checkpoint_every": -1}, "Study.checkpoint_every = -1 must be an integer >= 0"),
    ({"keep_checkpoints": 1.5}, "Study.keep_checkpoints = 1.5 must be an integer >= 0"),
    ({"updates": 2**31}, "must be a positive integer below 2**31"),
    ({"seeds": ()}, "Study.seeds must not be empty"),
    ({"name": "../escaped"}, "Study.name = '../escaped' must be a non-empty name without /"),
    ({"name": "/tmp/anywhere"}, "Study.name = '/tmp/anywhere' must be a non-empty name without /"),
    ({"seeds": ("abc",)}, "must be integers in [0, 2**31)"),
    ({"updates": 100.5}, "Study.updates = 100.5 must be a positive integer"),
    ({"env": "cartpole"}, "unknown env 'cartpole'; valid: hopper"),
    ({"variants": (Variant.of("a", "td3bc"), Variant.of("a", "td3bc"))}, "unique labels"),
    ({"seeds": (0, 0)}, "Study.seeds = (0, 0) must be distinct"),
    ({"seeds": [1, 2, 1]}, "Study.seeds = (1, 2, 1) must be distinct"),
    ({"seeds": 3}, "Study.seeds = 3 must be a tuple of integers"),
    ({"seeds": (True,)}, "Study.seeds = (True,) must be integers"),
    ({"final_window": (5,)}, "Study.final_window = (5,) must be two integers lo <= hi"),
    ({"final_window": (300, 100)}, "Study.final_window = (300, 100) must be two integers lo <= hi"),
    ({"final_window": (-1, 100)}, "Study.final_window = (-1, 100) must be two integers lo <= hi, both >= 0"),
    ({"final_window": (0.5, 100)}, "Study.final_window = (0.5, 100) must be two integers"),
    ({"final_window": 100}, "Study.final_window = 100 must be two integers"),
    ({"max_transitions": 0}, "Study.max_transitions = 0 must be a positive integer or None"),
    ({"max_transitions": 2.5}, "Study.max_transitions = 2.5 must be a positive integer or None"),
    ({"max_transitions": True}, "Study.max_transitions = True must be a positive integer or None"),
    ({"clip_actions": "no"}, "Study.clip_actions = 'no' must be True or False"),
    ({"vmap_sweeps": 1}, "Study.vmap_sweeps = 1 must be True or False"),
    ({"env": None}, "Study.env = None must be a string"),
    ({"reference": 0}, "Study.reference = 0 must be a variant label or None"),
    ({"variants": ("td3bc",)}, "Study.variants = ('td3bc',) must be a tuple of Variant"),
])
def test_study_rejects(fields, message):
    """(A study's name names its folder in a multi-study run: "../elsewhere" or "/abs" would write outside it.)"""
    base = dict(name="s", dataset="hopper-medium", env="hopper", variants=(Variant.of("a", "td3bc"),))
    with pytest.raises(ValueError, match=None) as err:
        Study(**(base | fields))
    assert message in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("make, message", [
    (lambda: Variant.of("", "td3bc"), "Variant.label = '' must be a non-empty name"),
    (lambda: Variant.of("  ", "td3bc"), "Variant.label = '  ' must be a non-empty name"),
    (lambda: Variant.of(None, "td3bc"), "Variant.label = None must be a non-empty name"),
    (lambda: Variant.of("a/b", "td3bc"), "Variant.label = 'a/b' must be a non-empty name without /"),
    (lambda: Variant.of("..", "td3bc"), "Variant.label = '..' must be a non-empty name without /"),
    (lambda: Variant.of("a", "td3bc", alpha=True), "TD3BCConfig.alpha = True must be a number"),
    (lambda: Variant("a", "td3bc", {"alpha": 2.5}), "Variant.config = {'alpha': 2.5} must be a TD3BCConfig"),
    # a config.json written before variants carried their config: its overrides, checked by the converter
    (lambda: Variant.from_json({"label": "a", "algo": "td3bc", "overrides": [["alpha"]]}, {}, "hopper", ""),
     "variant 'a': overrides = [['alpha']] must be (name, value) pairs"),
    (lambda: Variant.from_json({"label": "a", "algo": "td3bc", "overrides": [[1, 2.5]]}, {}, "hopper", ""),
     "variant 'a': overrides = [[1, 2.5]] must be (name, value) pairs"),
])
def test_variant_rejects(make, message):
    with pytest.raises(ValueError) as err:
        make()
    assert message in str(err.value) and "\n" not in str(err.value)


def test_study_stores_json_lists_as_tuples():
    variants = (Variant.of("a", "td3bc", hidden=(8, 8)), Variant.of("b", "td3bc", hidden=[8, 8], alpha=2))
    study = Study(name="s", dataset="hopper-medium", env="hopper", variants=list(variants), seeds=[0, 1],
                  final_window=[100, 300], updates=20_000)
    assert study.variants == variants and study.seeds == (0, 1) and study.final_window == (100, 300)
    assert study.variants[1].given() == {"alpha": 2.0, "hidden": (8, 8)}
    assert Study.from_json(study.to_json()) == study and hash(Study.from_json(study.to_json())) == hash(study)


@pytest.mark.parametrize("kw, message", [
    ({"seed": "0"}, "seed must be an integer (one of the run's seeds), not '0'"),
    ({"seed": 0.0}, "seed must be an integer (one of the run's seeds), not 0.0"),
    ({"seed": True}, "seed must be an integer (one of the run's seeds), not True"),
    ({"checkpoint": -1}, "checkpoint = -1 must be an update number >= 0"),
    ({"checkpoint": "-1"}, "checkpoint must be 'last', 'best', 'handover' or an update number, not '-1'"),
])
def test_load_policy_rejects_arguments(tmp_path, kw, message):
    with pytest.raises(ValueError) as err:
        load_policy(tmp_path, **kw)  # refused before the run directory is read
    assert message in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("algo", list(ALGOS))  # every algorithm the registry holds
@pytest.mark.parametrize("pretrain", ["none", "actor", "critic", "actor+critic"])
def test_a_configs_planned_phases_are_its_algorithms_phases(algo, pretrain):
    """What a budget check and a dry run read (`Config.phases`, no networks) is what training runs: the same
    phases, each given its update function."""
    from offrl_jax.algos import make_algorithm, make_config

    config = make_config(algo, "hopper", **({} if algo == "bc" else {"pretrain": pretrain, "pretrain_updates": 999}))
    phases = make_algorithm(config, obs_dim=3, act_dim=2, num_transitions=10).phases(5_001)
    planned = config.phases(5_001)
    assert all(p.update is None for p in planned) and all(callable(p.update) for p in phases)
    assert [dataclasses.replace(p, update=None, on_start=None) for p in phases] == planned


def test_a_studys_budget_check_builds_no_algorithm(monkeypatch):
    """Study checks every variant's phases against its evaluation grid from the configs alone."""
    from offrl_jax.algos import FAMILIES

    for family in FAMILIES.values():
        monkeypatch.setattr(family.algorithm, "__init__", lambda *a, **k: pytest.fail("an algorithm was built"))
    study = Study(name="t", dataset="hopper-medium", env="hopper", seeds=(0,), updates=30_000, eval_every=1_000,
                  variants=(Variant.of("a", "td3bc"), Variant.of("b", "edac", "hopper"), Variant.of("c", "rebrac")))
    assert study.config("b").num_critics == 50
    with pytest.raises(ValueError, match="phase 'offline_rl' updates the actor once every 2 critic updates"):
        Study(name="t", dataset="hopper-medium", env="hopper", seeds=(0,), updates=10_000, eval_every=1_001,
              variants=(Variant.of("a", "td3bc", pretrain="none"),))


def test_each_family_builds_its_layers_from_its_own_fields():
    """The shared Config.arch reads only the shared fields; SACN and ReBRAC add their constant hidden bias."""
    from offrl_jax.algos.config import Config

    assert make_config("td3bc", "hopper").arch() == Config.arch(make_config("td3bc", "hopper"))
    assert make_config("td3bc", "hopper").arch().hidden_bias is None
    assert make_config("edac", "hopper").arch().hidden_bias is None
    assert make_config("edac", "hopper", preset="authors").arch().hidden_bias == 0.1
    assert make_config("rebrac", "hopper").arch().hidden_bias == 0.1
    assert dataclasses.replace(make_config("rebrac", "hopper"), hidden_bias=None).arch().hidden_bias is None


def test_a_study_refuses_a_variant_made_with_another_envs_values():
    walker = Variant.of("a", "td3bc", "walker2d")
    with pytest.raises(ValueError) as err:
        Study(name="s", dataset="hopper-medium", env="hopper", variants=(walker,))
    assert "variant 'a' has walker2d's values, and the study is on hopper" in str(err.value)
    assert "\n" not in str(err.value)
    Study(name="s", dataset="hopper-medium", env="hopper", variants=(Variant.of("a", "td3bc"),))  # no env's: taken
