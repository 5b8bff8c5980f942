"""Minibatches of the online phase, drawn inside jit for one member from the offline data (shared by every member)
and the member's online buffer (`offrl_jax.online.buffer`).  The caller passes the key, so randomness stays a pure
function of (seed, update index) as in the offline phases.

Modes (`REPLAY_MODES`):
  mix          exactly round(f * B) rows of each minibatch from the online buffer (rounding half up), the rest from
               the offline data: a fixed share however large either grows (Cal-QL, CORL's ReBRAC: f = 0.5)
  append       B rows uniform over the offline rows and the member's drawable online rows together, as if the online
               rows were appended to the dataset (CORL's IQL and AWAC)
  online-only  every row from the online buffer: the offline data is dropped once the online phase starts (WSRL)
Only filled rows are drawn; with `ended_only` (an algorithm that reads the Monte-Carlo returns) only rows of episodes
that have ended, whose returns are known.  While the buffer has no drawable row, every row comes from the offline
data (the warm-up steps before the first online update normally fill it first).

A minibatch has the offline minibatch's fields (`DATA_FIELDS`) plus `idx` (an offline row's dataset index; T + its
ring position for an online row, T the dataset's rows, so each row of the union has one index) and `online` (1.0 for
an online row).
"""
from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from offrl_jax.algos.config import REPLAY_MODES
from offrl_jax.data.device import DATA_FIELDS, OPTIONAL_FIELDS
from offrl_jax.online.buffer import OnlineBuffer


@dataclasses.dataclass(frozen=True)
class Replay:
    """How the online phase samples: `mode` (`REPLAY_MODES`), `online_fraction` f (mix only), `ended_only`."""
    mode: str = "mix"
    online_fraction: float = 0.5
    ended_only: bool = False

    def __post_init__(self):
        if self.mode not in REPLAY_MODES:
            raise ValueError(f"replay must be one of {', '.join(REPLAY_MODES)}, not {self.mode!r}")
        if not 0.0 <= self.online_fraction <= 1.0:
            raise ValueError(f"the online fraction must be in [0, 1], not {self.online_fraction}")

    def online_rows(self, batch_size: int) -> int | None:
        """Online rows per minibatch of `batch_size`: fixed for mix and online-only, None (random) for append."""
        if self.mode == "mix":
            return int(self.online_fraction * batch_size + 0.5)
        return batch_size if self.mode == "online-only" else None


def draw_rows(key: jax.Array, replay: Replay, shape: tuple[int, ...], offline_rows: int,
              drawable: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
    """Which rows a minibatch of `shape` (.., B) reads: (online (.., B) bool, offline index (.., B) in
    [0, offline_rows), online offset (.., B) in [0, drawable), counted from the buffer's oldest row).  Where a row is
    online its offline index is 0, and the other way round.  drawable: () int, the member's drawable online rows."""
    k_offline, k_online = jax.random.split(key)
    batch = shape[-1]
    have = drawable > 0
    if replay.mode == "append":
        u = jax.random.randint(k_offline, shape, 0, offline_rows + drawable)
        online = u >= offline_rows
        return online, jnp.where(online, 0, u), jnp.where(online, u - offline_rows, 0)
    n_online = replay.online_rows(batch)
    online = jnp.broadcast_to(jnp.arange(batch) >= batch - n_online, shape) & have  # the last n_online of each
    offline = jax.random.randint(k_offline, shape, 0, offline_rows)
    offset = jax.random.randint(k_online, shape, 0, jnp.maximum(drawable, 1))
    return online, jnp.where(online, 0, offline), jnp.where(online, offset, 0)


def sample(key: jax.Array, replay: Replay, data: dict[str, jax.Array], buffer: OnlineBuffer,
           shape: tuple[int, ...]) -> dict[str, jax.Array]:
    """One member's minibatches of `shape` ((k, B) for k minibatches of B rows): leaves (*shape, ...).

    data: the offline device arrays (`DATA_FIELDS`, T rows, and `rows`, the sampleable rows, when some are left
    out); buffer: this member's (leaves (C, ...) and ())."""
    rows = data.get("rows")
    total = data["rewards"].shape[0]
    offline_rows = total if rows is None else rows.shape[0]
    online, offline, offset = draw_rows(key, replay, shape, offline_rows, buffer.drawable(replay.ended_only))
    offline = offline if rows is None else rows[offline]
    pos = (buffer.oldest() + offset) % buffer.capacity
    batch = {}
    for f in DATA_FIELDS:
        off, on = data[f][offline], buffer.arrays[f][pos]
        batch[f] = jnp.where(online.reshape(online.shape + (1,) * (off.ndim - online.ndim)), on, off)
    for f in OPTIONAL_FIELDS:  # an online row has no next dataset action: its own stands in (read with weight 0)
        if f in data:
            off = data[f][offline]
            batch[f] = jnp.where(online[..., None], buffer.arrays["actions"][pos], off)
    batch["idx"] = jnp.where(online, total + pos, offline)
    batch["online"] = online.astype(jnp.float32)
    return batch
