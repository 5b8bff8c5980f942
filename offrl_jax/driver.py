"""The training driver: a run is a list of phases; between evaluations it runs K updates as one jitted `lax.scan`,
sampling minibatches on the device inside the scan, for S seeds (members) at once in one program.

Where the members go (`member_layout`): split over the devices (`jax.shard_map` over a 1-D mesh), and on each device
batched with `jax.vmap` (GPU, TPU) or run one after another with `lax.map` (CPU, where batched matmuls are slower
than plain ones: +24 % TD3+BC updates/s at S = 4 on one core, benchmarks/README.md).  On the CPU the command line
gives a process one single-threaded XLA device per core (`system.workers.cpu_flags`), so one run of S seeds fills
every core.  Members that do not divide over the devices are padded with copies of the last one, whose results are
dropped.

Randomness is a pure function of (seed, global update index): the key of the update call at update u is
fold_in(fold_in(PRNGKey(seed), CHUNK), u), drawn inside the scan.  So how the updates are cut into chunks (the
evaluation interval, a resume, a self-ending phase's windows) does not change training, and seed i of a run is a
single run with seed i (exactly with `lax.map`; with `vmap` up to the rounding of batched matmuls, which float32 RL
training amplifies as it does across machines: tests/test_driver.py).

A chunk runs as up to `SLICES` slices of equal length (`slice_calls`), each one jitted call: the same updates, so
the same parameters, but the caller hears of every slice (`on_slice`: a progress bar that moves within a chunk, a
stop that comes within seconds instead of at the next evaluation).

A hyper-parameter sweep (`Driver(..., sweep=("alpha", (1.0, 2.5, 10.0)))`) runs every (value, seed) pair as one
member of the same program: the members' axis is value-major (member j * S + i = value j, seed i), each member
gets its value as a traced hyper-parameter (`offrl_jax.algos.common.with_hparams`), and member (j, i) equals a
single run with seed i and value j.

Over 300 lines for a stated reason: the file is one program, the jitted scan of a chunk, with what it is built from:
its key streams (`seed_keys`), its slices, the members' layout over the devices that it shards and batches over
(`member_layout`, `over_members`) and the `Driver` that holds them; the promises above (randomness, the member axis,
a sweep) are facts about those parts together, so split, each part would be read with the others open.
"""
from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Iterator
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec as P

from offrl_jax.algos.common import Phase, with_hparams
from offrl_jax.data.device import DATA_FIELDS, OPTIONAL_FIELDS, for_updates
from offrl_jax.system.distributed import to_host

# draw(key, data, a member's online buffer, shape) -> the minibatches of an online update call
Draw = Callable[[jax.Array, dict[str, jax.Array], Any, tuple[int, ...]], dict[str, jax.Array]]


def seed_keys(seeds: tuple[int, ...], stream: int, index: int | None = None) -> jax.Array:
    """(S, 2) keys: fold_in(PRNGKey(seed), stream), then fold_in(., index) unless index is None, for every seed."""
    keys = [jax.random.fold_in(jax.random.PRNGKey(s), stream) for s in seeds]
    return jnp.stack(keys if index is None else [jax.random.fold_in(k, index) for k in keys])


INIT, CHUNK, PHASE_START = 0, 1, 2  # key streams


SLICES = 10  # a chunk runs as at most this many slices (one jitted call each) ...
MIN_SLICE_CALLS = 100  # ... of at least this many update calls: shorter ones would cost dispatch and compilation


def slice_calls(calls: int) -> int:
    """The calls of one slice of a chunk of `calls` update calls: the largest divisor of `calls` no larger than
    ceil(calls / SLICES) and at least MIN_SLICE_CALLS, so every slice of the chunk is the same program; `calls`
    itself (one slice) when no such divisor exists."""
    most = -(-calls // SLICES)
    return next((d for d in range(most, MIN_SLICE_CALLS - 1, -1) if calls % d == 0), calls)


def check_call_grid(phases: list[Phase], chunk_updates: int) -> None:
    """A phase making k > 1 updates per call (TD3's delayed actor) must start, end and be evaluated on multiples of
    k; otherwise chunks would drift off the evaluation grid.  Raises ValueError naming the numbers."""
    start = 0
    for p in phases:
        if p.auto_stop is not None and chunk_updates % p.auto_stop.window:
            raise ValueError(f"phase '{p.name}' ends itself, checked every {p.auto_stop.window} updates, so the "
                             f"evaluation interval ({chunk_updates}) must be a multiple of that window")
        k = p.updates_per_call
        if k > 1 and (start % k or p.steps % k or chunk_updates % k):
            raise ValueError(f"phase '{p.name}' updates the actor once every {k} critic updates (the policy delay), so "
                             f"the updates before it ({start}), the updates up to its end ({start + p.steps}) and the "
                             f"evaluation interval ({chunk_updates}) must be multiples of {k}")
        start += p.steps


@dataclasses.dataclass(frozen=True)
class Layout:
    """Where the members of a run go: `padded` members (the `members` of the run, then copies of the last one) split
    evenly over `mesh` (1-D, axis "members"), each device running its share batched ("vmap") or one after another
    ("map")."""
    mesh: Mesh
    members: int
    padded: int
    mode: str

    @property
    def split(self) -> NamedSharding:
        return NamedSharding(self.mesh, P("members"))

    @property
    def replicated(self) -> NamedSharding:
        return NamedSharding(self.mesh, P())

    def place(self, tree: Any) -> Any:
        """A pytree of the run's members (leading axis) padded with copies of the last one and split over the mesh;
        every leaf gets its own buffer (targets start equal to params), so a chunk function can donate them."""
        pad = self.padded - self.members
        grow = (lambda x: x) if not pad else (lambda x: np.concatenate([x, np.repeat(x[-1:], pad, axis=0)]))
        return jax.device_put(jax.tree.map(lambda x: grow(np.array(x)), tree), self.split)


def default_mode(device=None) -> str:
    """How a device runs its members by default: one after another on the CPU ("map"), batched elsewhere."""
    return "map" if (device or jax.devices()[0]).platform == "cpu" else "vmap"


def member_layout(members: int, devices=None, mode: str | None = None) -> Layout:
    """The layout of `members` members over `devices` (default: every device; with one process, the fewest devices
    that give the busiest device as few members as all of them would).  `mode` defaults to "map" on the CPU and
    "vmap" elsewhere.  With several processes every device takes part, since every process runs the program."""
    devices = list(jax.devices() if devices is None else devices)
    if jax.process_count() == 1:
        per_device = -(-members // len(devices))
        devices = devices[:-(-members // per_device)]
    mode = mode or default_mode(devices[0])
    if mode not in ("map", "vmap"):
        raise ValueError(f"member mode must be 'map' or 'vmap', not {mode!r}")
    padded = -(-members // len(devices)) * len(devices)
    return Layout(Mesh(np.array(devices), ("members",)), members, padded, mode)


def make_chunk_fn(phase: Phase, batch_size: int, num_calls: int,
                  phase_for: Callable[[dict[str, jax.Array]], Phase] | None = None,
                  layout: Layout | None = None, draw: Draw | None = None,
                  phase_at: Callable[[dict[str, jax.Array] | None, jax.Array], Phase] | None = None,
                  swept: bool = False) -> Callable:
    """jit(members(scan of `num_calls` update calls)):
    (states (M..), data, keys (M, 2), start update ()) -> (states, metrics (M, ...)).

    `layout` places the members (`member_layout`; default: one device, its default mode); M is its padded count.

    `keys` are the members' run keys (`seed_keys(seeds, CHUNK)`); the call at global update u uses fold_in(key, u),
    so the result does not depend on where chunks begin.  With `phase_for` (a sweep: hyper-parameters -> the phase
    built with them) the function takes a last argument, hparams: {name: (S,) values}, and member m runs
    `phase_for({name: value_m})`.

    The online phase: with `draw` the function takes the members' online buffers (`offrl_jax.online.buffer`,
    leading axis M) after the start update, and each call's minibatches are `draw(key, data, the member's buffer,
    shape)` (`offrl_jax.online.sampling.sample` with the phase's `Replay`); `phase_at(hparams or None, u)` gives the
    phase of update u (a schedule over the phase, e.g. a decaying penalty) in place of `phase` / `phase_for`;
    `swept` then says whether the function takes the hparams argument (a sweep).
    """

    def one_seed(state, data, key, start, buffer, hparams):
        member_phase = phase if phase_for is None else phase_for(hparams)
        rows = data.get("rows")  # the rows that may be sampled, when some are never drawn (`data.device.for_updates`)
        n = data["rewards"].shape[0] if rows is None else rows.shape[0]

        def body(state, update):
            k_idx, k_update = jax.random.split(jax.random.fold_in(key, update))
            now = member_phase if phase_at is None else phase_at(hparams, update)
            shape = (now.updates_per_call, batch_size)
            if draw is not None:
                return now.update(state, draw(k_idx, data, buffer, shape), k_update)
            idx = jax.random.randint(k_idx, shape, 0, n)
            idx = idx if rows is None else rows[idx]
            batch = {k: data[k][idx] for k in DATA_FIELDS + OPTIONAL_FIELDS if k in data} | {"idx": idx}
            return now.update(state, batch, k_update)

        updates = start + member_phase.updates_per_call * jnp.arange(num_calls, dtype=jnp.int32)
        state, metrics = jax.lax.scan(body, state, updates)
        finite = jnp.all(jnp.stack([jnp.all(jnp.isfinite(m)) for m in jax.tree.leaves(metrics)]))
        finite &= jnp.all(jnp.stack([jnp.all(jnp.isfinite(p)) for p in jax.tree.leaves(state)]))
        return state, jax.tree.map(lambda m: jnp.mean(m, axis=0), metrics) | {"finite": finite}

    swept = swept or phase_for is not None
    args = ["state", "data", "key", "start"] + (["buffer"] if draw is not None else []) + (["hparams"] if swept
                                                                                                else [])
    in_axes = tuple({"data": None, "start": None}.get(a, 0) for a in args)

    def fn(*values):
        named = dict(zip(args, values))
        return one_seed(named["state"], named["data"], named["key"], named["start"], named.get("buffer"),
                        named.get("hparams"))

    mode = layout.mode if layout is not None else default_mode()
    fn = over_members(fn, in_axes, mode)
    if layout is not None and layout.mesh.size > 1:  # each device runs `fn` on its own block of members
        fn = jax.shard_map(fn, mesh=layout.mesh, in_specs=tuple(P() if ax is None else P("members") for ax in in_axes),
                           out_specs=P("members"))
    return jax.jit(fn, donate_argnums=0)


def over_members(fn: Callable, in_axes: tuple, mode: str = "vmap") -> Callable:
    """`fn` over the leading (member) axis of the arguments whose `in_axes` is 0: batched (`jax.vmap`) or one member
    after another (`lax.map`, "map"); one member runs `fn` itself on the squeezed arguments either way.

    On XLA CPU batched matmuls and batch-axis reductions are slower than plain ones, even over an axis of size 1
    (benchmarks/README.md), so "map" is faster there; "vmap" is what fills a GPU.
    """
    def call(*args):
        members = [a for a, ax in zip(args, in_axes) if ax is not None]

        def one(block):
            it = iter(block)
            return fn(*[a if ax is None else next(it) for a, ax in zip(args, in_axes)])

        if jax.tree.leaves(args[0])[0].shape[0] == 1:
            return jax.tree.map(lambda x: x[None], one(jax.tree.map(lambda x: x[0], members)))
        if mode == "map":
            return jax.lax.map(one, members)
        return jax.vmap(fn, in_axes=in_axes)(*args)

    return call


@dataclasses.dataclass
class Chunk:
    """What the driver reports after each chunk of updates."""

    phase: str
    update: int  # global updates done (pre-training included)
    states: Any  # agent states, leading axis M = members (S seeds, or values x seeds in a sweep)
    metrics: dict[str, np.ndarray]  # each (M,)
    seconds: float  # wall-clock seconds of training so far (compilation included, evaluation excluded)
    updates_per_s: float
    ended: bool = False  # this chunk ended a self-ending (auto_stop) phase before its cap
    env_steps: int | None = None  # the online phase: env steps every member has taken (updates_per_s: env steps/s)
    # the online phase: what a checkpoint saves to go on from here exactly (called before the phase goes on)
    carry: Callable[[], dict | None] | None = None
    # the online phase: the env transitions of this chunk's env steps, raw, each (M, n, ...) (`online.record`)
    transitions: dict[str, np.ndarray] | None = None


def _swept_on_start(phase_for: Callable[[dict[str, jax.Array]], Phase]) -> Callable:
    return lambda state, data, key, hparams: phase_for(hparams).on_start(state, data, key)


class Driver:
    """Trains `algo` for `seeds` (and `sweep` values) on `data`: a dataset's device arrays
    (`offrl_jax.data.device.DeviceData.arrays`, or any dict of the `DATA_FIELDS`)."""

    def __init__(self, algo, data: dict[str, jax.Array], seeds: tuple[int, ...], batch_size: int = 256,
                 devices=None, sweep: tuple[str, tuple[float, ...]] | None = None, members: str | None = None):
        self.algo, self.seeds, self.batch_size, self.sweep = algo, tuple(seeds), batch_size, sweep
        values = tuple(sweep[1]) if sweep else (None,)
        self.members = tuple(s for _ in values for s in self.seeds)  # value-major: member j * S + i
        self.layout = member_layout(len(self.members), devices, members)  # members: "map"/"vmap" (default: platform)
        data = for_updates(data, algo.cfg.needs())  # what the algorithm's updates read besides the device form
        self.data = jax.device_put(data, self.layout.replicated)  # one copy per device, shared by its members
        self.hparams = None
        if sweep:
            per_member = np.repeat(np.asarray(values, np.float32), len(self.seeds))
            self.hparams = self.layout.place({sweep[0]: per_member})
        self.run_keys = self.layout.place(seed_keys(self.members, CHUNK))
        self._chunk_fns: dict[tuple[str, int], Callable] = {}

    def init(self) -> Any:
        """The members' initial agent states (leading axis: the run's members, not padded)."""
        return jax.jit(jax.vmap(self.algo.init))(seed_keys(self.members, INIT, 0))

    def real(self, tree: Any) -> Any:
        """The run's own members of a padded member-batched pytree (on the host if it spans processes)."""
        if self.layout.padded == len(self.members):
            return tree
        if jax.process_count() > 1:
            tree = to_host(tree)
        return jax.tree.map(lambda x: x[:len(self.members)], tree)

    def _phase_for(self, total: int, index: int) -> Callable[[dict[str, jax.Array]], Phase]:
        """hparams -> phase `index` of the algorithm rebuilt with those (traced) hyper-parameter values."""
        return lambda hparams: with_hparams(self.algo, **hparams).phases(total)[index]

    def chunk_fn(self, phase: Phase, num_calls: int, phase_for=None, draw: Draw | None = None,
                 phase_at=None) -> Callable:
        """The jitted chunk function of `num_calls` update calls of `phase` (`make_chunk_fn` on this driver's
        members), made once per (phase name, calls) and kept; `draw` and `phase_at` for the online phase."""
        key = (phase.name, num_calls)
        if key not in self._chunk_fns:
            self._chunk_fns[key] = make_chunk_fn(phase, self.batch_size, num_calls, phase_for, self.layout, draw,
                                                 phase_at, swept=self.hparams is not None)
        return self._chunk_fns[key]

    def run(self, phases: list[Phase], chunk_updates: int, states: Any = None, start_update: int = 0,
            seconds: float = 0.0, ended: dict[str, int] | None = None,
            last_metrics: dict[str, np.ndarray] | None = None,
            on_slice: Callable[[int], None] | None = None) -> Iterator[Chunk]:
        """Run `phases` in order, yielding after every `chunk_updates` updates and at every phase end.

        `states`/`start_update`/`seconds` resume a run from a checkpoint taken at a chunk boundary.  A phase with
        `auto_stop` runs in windows of `auto_stop.window` updates and may end before its cap (the chunk that ends
        it has `ended=True`; the updates it did not use go to the last phase).  To resume such a run, `ended`
        gives the end update of every self-ended phase, and `last_metrics` the metrics of the window before
        `start_update` (what the last yielded chunk had), so the stopping rule sees what it would have seen.
        `on_slice(updates)` is called after every slice of a chunk with the updates it made; what it raises (a
        stop) ends the run there, its last chunk's states being the last ones yielded.
        """
        phases = list(phases)
        for name, end in (ended or {}).items():
            _end_phase(phases, [p.name for p in phases].index(name), end)
        check_call_grid(phases, chunk_updates)
        states = self.layout.place(self.init() if states is None else states)
        total = sum(p.steps for p in phases)
        extra = () if self.hparams is None else (self.hparams,)
        phase_start = 0
        for index in range(len(phases)):
            phase = phases[index]
            phase_end = phase_start + phase.steps
            if start_update >= phase_end:
                phase_start = phase_end
                continue
            phase_for = None if self.hparams is None else self._phase_for(total, index)
            if phase.on_start is not None and start_update == phase_start:
                hook = jax.jit(jax.vmap(phase.on_start, in_axes=(0, None, 0)) if phase_for is None else
                               jax.vmap(_swept_on_start(phase_for), in_axes=(0, None, 0, 0)))
                keys = seed_keys(self.members, PHASE_START, index)
                states = hook(states, self.data, self.layout.place(keys), *extra)
            update = max(start_update, phase_start)
            auto = phase.auto_stop  # the metrics of the last whole window of this phase, if any
            previous = last_metrics if auto is not None and update - phase_start >= auto.window else None
            while update < phase_end:
                n = min(chunk_updates - update % chunk_updates, phase_end - update)  # align chunks globally
                if auto is not None:  # and the stopping rule's windows (on the global grid, like the chunks)
                    n = min(n, auto.window - update % auto.window)
                calls = max(1, n // phase.updates_per_call)
                tic = time.perf_counter()
                states, metrics = self._run_slices(phase, calls, phase_for, states, update, extra, on_slice)
                elapsed = time.perf_counter() - tic
                seconds += elapsed
                update += calls * phase.updates_per_call
                stop = False
                if auto is not None and update % auto.window == 0 and calls * phase.updates_per_call == auto.window:
                    stop = update < phase_end and auto.converged(previous, metrics)  # a whole window: compare
                    previous = metrics
                    if stop:
                        _end_phase(phases, index, update)
                        phase_end = update
                if auto is None or update % chunk_updates == 0 or update == phase_end:
                    yield Chunk(phase.name, update, self.real(states), metrics, seconds,
                                calls * phase.updates_per_call / elapsed, ended=stop)
            phase_start = phase_end
            start_update = update


    def _run_slices(self, phase: Phase, calls: int, phase_for, states, update: int, extra: tuple,
                    on_slice: Callable[[int], None] | None) -> tuple[Any, dict[str, np.ndarray]]:
        """`calls` update calls from global update `update`, as slices of `slice_calls(calls)`: (states, every
        member's metrics on the host, each the mean over the chunk, `finite` over all of it)."""
        size = slice_calls(calls)
        fn, parts = self.chunk_fn(phase, size, phase_for), []
        for k in range(calls // size):
            start = update + k * size * phase.updates_per_call
            states, metrics = fn(states, self.data, self.run_keys, jnp.int32(start), *extra)
            parts.append(self.real(to_host(metrics)))  # every member's, on every process
            if on_slice is not None:
                on_slice(size * phase.updates_per_call)
        return states, merge_metrics(parts)


def merge_metrics(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Every member's metrics over several calls (each call's means): the mean of each metric, `finite` over all."""
    if len(parts) == 1:
        return parts[0]
    finite = np.logical_and.reduce([np.asarray(p.pop("finite"), bool) for p in parts])
    return {k: np.mean([p[k] for p in parts], axis=0) for k in parts[0]} | {"finite": finite}


def _end_phase(phases: list[Phase], index: int, end: int) -> None:
    """End phase `index` at global update `end` (in place); the last phase gets the updates it leaves."""
    start = sum(p.steps for p in phases[:index])
    if not start <= end <= start + phases[index].steps:
        raise ValueError(f"phase '{phases[index].name}' cannot end at update {end} (it runs from {start} to "
                         f"{start + phases[index].steps})")
    left = start + phases[index].steps - end
    phases[index] = dataclasses.replace(phases[index], steps=end - start)
    phases[-1] = dataclasses.replace(phases[-1], steps=phases[-1].steps + left)
