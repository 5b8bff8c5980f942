"""The Python API's config constructors reject invalid hyper-parameters with one line naming the field."""
import pytest

from offrl_jax.algos import make_config
from offrl_jax.study import Study, Variant


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
    ("bc", {"pretrain": "actor+critic"}, "pretrain = 'actor+critic' has no effect on the BC baseline"),
    ("bc", {"pretrain_auto": True}, "pretrain_auto = True has no effect on the BC baseline"),
])
def test_config_rejects(algo, overrides, message):
    with pytest.raises(ValueError) as err:
        make_config(algo, "hopper", **overrides)
    assert message in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("fields, message", [
    ({"updates": 0}, "Study.updates = 0 must be a positive integer"),
    ({"batch_size": -1}, "Study.batch_size = -1 must be a positive integer"),
    ({"eval_every": 0}, "Study.eval_every = 0 must be a positive integer"),
    ({"checkpoint_every": -1}, "Study.checkpoint_every = -1 must be an integer >= 0"),
    ({"keep_checkpoints": 1.5}, "Study.keep_checkpoints = 1.5 must be an integer >= 0"),
    ({"updates": 2**31}, "must be a positive integer below 2**31"),
    ({"seeds": ()}, "Study.seeds must not be empty"),
    ({"seeds": ("abc",)}, "must be integers in [0, 2**31)"),
    ({"updates": 100.5}, "Study.updates = 100.5 must be a positive integer"),
    ({"env": "cartpole"}, "unknown env 'cartpole'; valid: hopper"),
    ({"variants": (Variant.of("a", "td3bc"), Variant.of("a", "td3bc"))}, "unique labels"),
])
def test_study_rejects(fields, message):
    base = dict(name="s", dataset="hopper-medium", env="hopper", variants=(Variant.of("a", "td3bc"),))
    with pytest.raises(ValueError, match=None) as err:
        Study(**(base | fields))
    assert message in str(err.value)
