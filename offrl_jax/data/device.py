"""A dataset's device form: the arrays training samples from, on the device once and shared by every seed, with the
observation statistics that normalised them (which evaluation, checkpoints and `offrl_jax.policy` apply to raw
observations).

It depends on the dataset and on two hyper-parameters only: the discount of the returns-to-go and whether rewards are
normalised.  Variants of a study that agree on both read the same arrays (`DeviceForms`).
"""
from __future__ import annotations

import dataclasses
import threading
from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
import numpy as np

from offrl_jax.data.dataset import Dataset, normalize_obs, rows_without_timeouts
from offrl_jax.data.returns import returns_to_go

if TYPE_CHECKING:
    from offrl_jax.algos.common import DataNeeds

DATA_FIELDS = ("observations", "actions", "rewards", "next_observations", "terminals", "timeouts", "returns")
# beyond the device form, on the device only for an algorithm that reads them (`DataNeeds.next_actions`: ReBRAC's
# critic penalty; `next_actions`)
OPTIONAL_FIELDS = ("next_actions",)


@dataclasses.dataclass(frozen=True)
class DeviceData:
    """`arrays`: every field of `DATA_FIELDS`, float32 on the device, T rows each: observations and next observations
    normalised with (`obs_mean`, `obs_std`), rewards (scaled by `Dataset.reward_scale` where the rewards are
    normalised), and the Monte-Carlo returns-to-go of those rewards.  `obs_mean`, `obs_std`: (obs_dim,) float32 on
    the host (`Dataset.obs_stats`)."""
    arrays: dict[str, jax.Array]
    obs_mean: np.ndarray
    obs_std: np.ndarray


def device_data(ds: Dataset, gamma: float, timeout_tail: bool = True, normalize_reward: bool = False) -> DeviceData:
    """`ds` in its device form: returns-to-go discounted by `gamma` (`timeout_tail`: see `returns_to_go`); with
    `normalize_reward` the rewards, and so the returns, are scaled by `Dataset.reward_scale`."""
    mean, std = ds.obs_stats()
    arrays = {
        "observations": normalize_obs(ds.observations, mean, std),
        "next_observations": normalize_obs(ds.next_observations, mean, std),
        "actions": ds.actions,
        "rewards": ds.rewards * ds.reward_scale() if normalize_reward else ds.rewards,
        "terminals": ds.terminals,
        "timeouts": ds.timeouts,
    }
    arrays = {k: jnp.asarray(v, jnp.float32) for k, v in arrays.items()}
    arrays["returns"] = returns_to_go(arrays["rewards"], arrays["terminals"], arrays["timeouts"], gamma, timeout_tail)
    return DeviceData(arrays, mean, std)


def next_actions(actions: jax.Array, terminals: jax.Array, timeouts: jax.Array) -> jax.Array:
    """(T, A) the dataset's action at the next row of the same episode.  The last row of an episode has none: its
    own action stands in (at a terminal the TD target does not bootstrap, so it is never used; at a time-out it is,
    unless timeouts="drop" leaves the row out, as CORL's ReBRAC loader does; and at the dataset's last row)."""
    ends = jnp.maximum(terminals, timeouts).at[-1].set(1.0)
    following = jnp.concatenate([actions[1:], actions[-1:]])
    return jnp.where(ends[:, None] > 0, actions, following)


def for_updates(arrays: dict[str, jax.Array], needs: DataNeeds) -> dict[str, jax.Array]:
    """A device form's `arrays` with what an algorithm's updates read besides (`needs`, its config's `needs()`):
    `next_actions` where it reads them, and `rows` (the (K,) rows that may be drawn) where some are never drawn."""
    if needs.next_actions and "next_actions" not in arrays:
        arrays = arrays | {"next_actions": next_actions(arrays["actions"], arrays["terminals"], arrays["timeouts"])}
    if not needs.cut_rows:  # CORL's loader: time-out rows are never sampled
        rows = rows_without_timeouts(arrays["timeouts"])
        if not len(rows):
            raise ValueError("every transition is a time-out row: timeouts = 'drop' leaves nothing to sample")
        arrays = arrays | {"rows": jnp.asarray(rows, jnp.int32)}
    return arrays


def too_few_rows(ds: Dataset, needs: list[DataNeeds], batch_size: int) -> str | None:
    """Why `batch_size` rows cannot be drawn from `ds` for algorithms with these `needs` (None: they can): where
    time-out rows are never drawn, only the others count."""
    if all(n.cut_rows for n in needs):
        return None
    rows = len(rows_without_timeouts(ds.timeouts))
    if batch_size <= rows:
        return None
    lower = ", or a smaller --batch-size" if rows else ""
    return (f"{rows:,} of its {len(ds):,} transitions remain once its time-out rows are dropped (timeouts = 'drop'), "
            f"fewer than --batch-size {batch_size}; keep them with --timeouts bootstrap or stop{lower}")


class DeviceForms:
    """The device forms of one dataset, each made on its first request and then shared: `forms(gamma,
    normalize_reward)` is `device_data(ds, gamma, normalize_reward=normalize_reward)`, computed once per distinct
    pair.  Thread-safe: a second request for a form being made waits for it."""

    def __init__(self, ds: Dataset):
        self.ds, self.forms, self.lock = ds, {}, threading.Lock()

    def __call__(self, gamma: float, normalize_reward: bool = False) -> DeviceData:
        key = (float(gamma), bool(normalize_reward))
        with self.lock:
            if key not in self.forms:
                self.forms[key] = device_data(self.ds, gamma, normalize_reward=normalize_reward)
            return self.forms[key]
