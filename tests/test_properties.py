"""Property-based tests (hypothesis): whatever a user types or whatever a file holds, the answer is a valid value
or one line naming the problem, never a traceback from deep inside."""
from __future__ import annotations

import argparse
import io
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from offrl_jax.algos import make_config
from offrl_jax.data.dataset import DatasetError
from offrl_jax.data.readers import load_dataset_path
from offrl_jax.system.cli import number, positive_int

FAST = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
ANY_FLOAT = st.floats(allow_nan=True, allow_infinity=True)


@FAST
@given(text=st.one_of(st.text(max_size=12), ANY_FLOAT.map(repr), st.integers().map(str)))
def test_a_typed_number_is_finite_and_in_range_or_one_line(text):
    convert = number(0, low_open=True)
    try:
        value = convert(text)
    except argparse.ArgumentTypeError as e:
        assert "\n" not in str(e) and "expected a" in str(e)
    else:
        assert math.isfinite(value) and value > 0


@FAST
@given(text=st.one_of(st.text(max_size=12), ANY_FLOAT.map(repr), st.integers().map(str)))
def test_a_positive_integer_is_one_or_one_line(text):
    try:
        value = positive_int(text)
    except argparse.ArgumentTypeError as e:
        assert "\n" not in str(e)
    else:
        assert isinstance(value, int) and value > 0


@FAST
@given(algo=st.sampled_from(["td3bc", "edac", "td3bc_cql", "edac_bc", "cql"]),
       field=st.sampled_from(["alpha", "gamma", "tau", "actor_lr", "critic_lr", "lam", "eta", "policy_noise",
                              "noise_clip", "bc_weight", "cql_weight", "cql_alpha"]),
       value=ANY_FLOAT)
def test_a_config_value_is_usable_or_refused_in_one_line_naming_it(algo, field, value):
    try:
        config = make_config(algo, "hopper", **{field: value})
    except ValueError as e:
        assert "\n" not in str(e) and field in str(e)
    else:
        assert math.isfinite(getattr(config, field))
        if field in ("gamma", "tau"):
            assert 0 < getattr(config, field) <= 1


@FAST
@given(content=st.binary(max_size=512), suffix=st.sampled_from([".npz", ".hdf5"]))
def test_a_file_of_random_bytes_is_refused_in_one_line_naming_it(tmp_path_factory, content, suffix):
    path = tmp_path_factory.mktemp("bytes") / f"data{suffix}"
    path.write_bytes(content)
    with pytest.raises(DatasetError) as e:
        load_dataset_path(path, env="hopper")
    assert "\n" not in str(e.value) and str(path) in str(e.value)


arrays = st.integers(1, 40).flatmap(lambda n: st.fixed_dictionaries({
    "observations": st.sampled_from([(n, 39), (n, 11), (n,), (n + 1, 39)]),
    "actions": st.sampled_from([(n, 28), (n, 3), (n + 2, 28)]),
    "rewards": st.sampled_from([(n,), (n, 1), (n + 1,)]),
    "episode_lengths": st.sampled_from([(1,), (2,), (0,)]),
}))


@FAST
@given(shapes=arrays, fill=st.sampled_from([0.0, 1.0, np.nan, np.inf]))
def test_a_door_npz_of_any_shapes_loads_consistently_or_is_refused(tmp_path_factory, shapes, fill):
    """An .npz with the demonstrations' keys but arbitrary shapes and values: either a dataset whose arrays agree
    in length and are finite, or one line naming the file."""
    path = tmp_path_factory.mktemp("npz") / "door.npz"
    buffer = io.BytesIO()
    arrays = {k: np.full(shape, fill, np.float32) for k, shape in shapes.items() if k != "episode_lengths"}
    n = len(arrays["rewards"])  # one episode of all rows, two halves, or none
    arrays["episode_lengths"] = {(1,): np.array([n]), (2,): np.array([n - n // 2, n // 2]),
                                 (0,): np.zeros(0)}[shapes["episode_lengths"]]
    np.savez(buffer, **arrays)
    path.write_bytes(buffer.getvalue())
    try:
        ds = load_dataset_path(path, env="door")
    except DatasetError as e:
        assert "\n" not in str(e) and str(path) in str(e)
    else:
        assert len(ds.rewards) == len(ds.observations) == len(ds.actions) == len(ds.next_observations)
        assert all(np.isfinite(getattr(ds, k)).all() for k in ("observations", "actions", "rewards"))
