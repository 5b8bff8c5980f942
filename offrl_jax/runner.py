"""Run a study: several variants (algorithm + hyper-parameters) on one dataset, each with S vmapped seeds, evaluated
between scan chunks, with atomic results, checkpoints every N updates, `resume`, and a clean stop on divergence.

Output directory:
    config.json      the study (enough to resume or replay it), every variant's resolved config ("resolved": every
                     field after per-env defaults and presets), and one record per start or resume ("runs": command,
                     git commit, versions, backend, dataset fingerprint; `offrl_jax.provenance`)
    curves.csv       variant, seed, phase, update, seconds, score, every logged metric; `seconds` is the variant's
                     training wall-clock so far: its jitted chunks including their XLA compilation, excluding the
                     evaluations (so a run stopped with SIGSTOP, or sharing its core, shows longer seconds)
    summary.json     one object per variant (see `summarize`)
    curves.png       mean and 95 % CI per variant against updates, pre-training end marked
    checkpoints/     <variant>.msgpack, the last complete chunk of every variant
"""
from __future__ import annotations

import csv
import dataclasses
import io
import json
import math
import sys
import threading
import time
import warnings
from concurrent.futures import FIRST_EXCEPTION, ThreadPoolExecutor, wait
from pathlib import Path
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from offrl_jax.algos import ALGOS, make_algorithm, make_config
from offrl_jax.checkpoint import atomic_write_bytes, atomic_write_text, load_checkpoint, save_checkpoint
from offrl_jax.data.dataset import Dataset
from offrl_jax.driver import Driver, check_call_grid, device_data
from offrl_jax.envs import get_env_spec
from offrl_jax.evaluate import evaluate_normalized, make_policy
from offrl_jax.provenance import run_record


class Diverged(RuntimeError):
    """Every seed of a variant produced a non-finite loss or parameter."""


@dataclasses.dataclass(frozen=True)
class Variant:
    label: str  # unique, used in files: "pretrained", "scratch", "lambda=0.1", ...
    algo: str
    overrides: tuple[tuple[str, Any], ...] = ()  # config overrides as (name, value) pairs

    @staticmethod
    def of(label: str, algo: str, **overrides: Any) -> Variant:
        return Variant(label, algo, tuple(sorted(overrides.items())))


@dataclasses.dataclass(frozen=True)
class Study:
    name: str
    dataset: str  # a known name ("hopper-medium") or a path
    env: str
    variants: tuple[Variant, ...]
    seeds: tuple[int, ...] = (0, 1, 2)
    updates: int = 100_000
    eval_every: int = 5_000
    eval_episodes: int = 10
    batch_size: int = 256
    checkpoint_every: int = 0  # 0 = at every evaluation
    max_transitions: int | None = None  # train on the first N transitions only (quick runs, tests); never cached
    clip_actions: bool = False  # clip out-of-bounds dataset actions (with a warning) instead of refusing the data
    reference: str | None = None  # label of the from-scratch variant whose final score is the asymptote (None: no
    # asymptote, and no updates/seconds to 90 %)
    final_window: tuple[int, int] | None = None  # final score = mean of evaluations in [lo, hi] (Adroit protocol)
    vmap_sweeps: bool = True  # variants differing only in one sweepable value (e.g. alpha) share one vmapped program

    def __post_init__(self):
        for name in ("updates", "eval_every", "eval_episodes", "batch_size"):
            if getattr(self, name) <= 0:
                raise ValueError(f"Study.{name} = {getattr(self, name)} must be positive")
        if not self.seeds:
            raise ValueError("Study.seeds must not be empty")
        if self.checkpoint_every < 0:
            raise ValueError(f"Study.checkpoint_every = {self.checkpoint_every} must be >= 0")
        labels = [v.label for v in self.variants]
        if not labels or len(set(labels)) != len(labels):
            raise ValueError(f"Study.variants need unique labels, got {labels}")
        if self.reference is not None and not any(reference_label(self, label) for label in labels):
            raise ValueError(f"Study.reference = {self.reference!r} is not a variant label ({', '.join(labels)})")
        get_env_spec(self.env)
        for v in self.variants:  # every variant's hyper-parameters and budget are checked before anything is written
            config = make_config(v.algo, self.env, self.dataset, **dict(v.overrides))
            phases = make_algorithm(config, obs_dim=1, act_dim=1, num_transitions=1).phases(self.updates)
            check_call_grid(phases, self.eval_every)

    def to_json(self) -> str:
        return json.dumps(dataclasses.asdict(self), indent=2)

    def resolved(self) -> dict[str, dict[str, Any]]:
        """{label: every field of the variant's algorithm config, after per-env defaults, preset and overrides}."""
        return {v.label: dataclasses.asdict(make_config(v.algo, self.env, self.dataset, **dict(v.overrides)))
                for v in self.variants}

    def record_json(self, ds: Dataset | None = None, previous: str | None = None) -> str:
        """config.json: the study, its resolved configs, and the run records so far plus this one."""
        runs = json.loads(previous).get("runs", []) if previous else []
        raw = dataclasses.asdict(self) | {"resolved": self.resolved(),
                                          "runs": runs + [run_record(ds, self.dataset)]}
        return json.dumps(raw, indent=2, default=list) + "\n"

    @staticmethod
    def from_json(text: str) -> Study:
        raw = json.loads(text)
        for recorded in ("resolved", "runs"):  # what the run wrote about itself; the study is the rest
            raw.pop(recorded, None)
        if "transitions" in raw:  # runs saved before the cap was renamed
            raw["max_transitions"] = raw.pop("transitions")
        value = lambda x: tuple(x) if isinstance(x, list) else x  # noqa: E731  JSON has lists; configs use tuples
        raw["variants"] = tuple(Variant(v["label"], v["algo"], tuple((k, value(x)) for k, x in v["overrides"]))
                                for v in raw["variants"])
        raw["seeds"] = tuple(raw["seeds"])
        raw["final_window"] = tuple(raw["final_window"]) if raw.get("final_window") else None
        return Study(**raw)


def run_study(study: Study, out_dir: Path, dataset: Dataset, resume: bool = False, progress: bool = True,
              parallel: int = 1) -> list[dict]:
    """Run (or resume) every variant; write results as it goes; return the summary.

    Variants that differ only in one sweepable hyper-parameter (`sweep_groups`) train as one vmapped program unless
    `study.vmap_sweeps` is off.  `parallel` > 1 runs that many variants (or groups) at once in threads: a jitted
    chunk releases the GIL, and at these network sizes one XLA program keeps only about one CPU core busy, so two
    variants at once use a 2-core machine better.  Results do not depend on either (each variant's randomness is
    its own).
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    config_path = out_dir / "config.json"  # a resumed multi-study run may not have begun this study yet
    previous = config_path.read_text() if resume and config_path.exists() else None
    atomic_write_text(config_path, study.record_json(dataset, previous))
    bar = tqdm(total=len(study.variants) * study.updates, disable=not progress, unit="upd", dynamic_ncols=True,
               file=sys.stderr)
    recorder = _Recorder(out_dir / "curves.csv", [v.label for v in study.variants])
    pretrain_ends: dict[str, int] = {}
    groups = sweep_groups(study.variants) if study.vmap_sweeps else [((v,), None) for v in study.variants]

    def run(group: tuple[tuple[Variant, ...], str | None]) -> None:
        end = _run_group(study, *group, dataset, out_dir, resume, bar, recorder)
        pretrain_ends.update({v.label: end for v in group[0]})

    try:
        if parallel <= 1 or len(groups) == 1:
            for group in groups:
                run(group)
        else:
            with ThreadPoolExecutor(max_workers=parallel) as pool:
                futures = [pool.submit(run, g) for g in groups]
                try:
                    done, _ = wait(futures, return_when=FIRST_EXCEPTION)
                    for future in [f for f in done if f.exception() is not None] + futures:  # a failure first
                        future.result()
                except BaseException:
                    recorder.stop.set()  # the other variants stop at their next chunk boundary
                    raise
    finally:
        bar.close()
    history = recorder.all_rows()
    summary = summarize(study, history, pretrain_ends)
    atomic_write_text(out_dir / "summary.json", summary_json(summary))
    plot_curves(out_dir / "curves.png", study, history, pretrain_ends)
    return summary


class Stopped(RuntimeError):
    """Another variant failed or the run was interrupted; this one stopped at a chunk boundary."""


class _Recorder:
    """Rows of every variant (in study order), written to curves.csv after each evaluation; thread-safe."""

    def __init__(self, path: Path, labels: list[str]):
        self.path, self.rows = path, {label: [] for label in labels}
        self.lock, self.stop = threading.Lock(), threading.Event()

    def set(self, rows_by_label: dict[str, list[dict]]) -> None:
        with self.lock:
            self.rows.update({label: list(rows) for label, rows in rows_by_label.items()})
            write_curves(self.path, self.all_rows())

    def all_rows(self) -> list[dict]:
        return [row for rows in self.rows.values() for row in rows]


def sweep_groups(variants: tuple[Variant, ...]) -> list[tuple[tuple[Variant, ...], str | None]]:
    """Variants of one algorithm whose overrides differ only in one sweepable hyper-parameter (`SWEEPABLE`, e.g.
    TD3+BC's alpha) run as one vmapped program: [(variants, swept name or None)], in study order of first member."""
    groups: list[list] = []  # [[variants], swept name or None]
    for v in variants:
        for group in groups:
            key = _swept_name(group[0][0], v)
            if key is not None and group[1] in (None, key):
                group[0].append(v)
                group[1] = key
                break
        else:
            groups.append([[v], None])
    return [(tuple(members), name) for members, name in groups]


def _swept_name(a: Variant, b: Variant) -> str | None:
    if a.algo != b.algo:
        return None
    da, db = dict(a.overrides), dict(b.overrides)
    diff = [k for k in sorted(da.keys() | db.keys()) if da.get(k) != db.get(k)]
    if len(diff) != 1 or diff[0] not in da or diff[0] not in db:
        return None
    sweepable = ALGOS[a.algo][0].SWEEPABLE
    return diff[0] if diff[0] in sweepable and all(isinstance(d[diff[0]], (int, float)) for d in (da, db)) else None


def _run_group(study: Study, group: tuple[Variant, ...], swept: str | None, ds: Dataset, out_dir: Path, resume: bool,
               bar, recorder: _Recorder) -> int:
    """Train one variant (S vmapped seeds), or a sweep group (values x seeds in one vmapped program), evaluating
    between chunks; returns the number of pre-training updates."""
    first_variant, labels, seeds = group[0], [v.label for v in group], study.seeds
    config = make_config(first_variant.algo, study.env, study.dataset, **dict(first_variant.overrides))
    algo = make_algorithm(config, ds.obs_dim, ds.act_dim, len(ds))
    data, (obs_mean, obs_std) = device_data(ds, config.gamma)
    sweep = (swept, tuple(float(dict(v.overrides)[swept]) for v in group)) if swept else None
    driver = Driver(algo, data, seeds, study.batch_size, sweep=sweep)
    policy = make_policy(algo.act, obs_mean, obs_std)
    phases = algo.phases(study.updates)
    pretrain_end = sum(p.steps for p in phases if p.name != "offline_rl")
    last_update = sum(p.steps for p in phases)  # TD3 trims an odd budget to its 2-update call grid
    name = " + ".join(labels)
    ckpt_path = out_dir / "checkpoints" / f"{'+'.join(labels)}.msgpack"
    states, start, seconds, rows = None, 0, 0.0, []

    def record():
        recorder.set({label: [r for r in rows if r["variant"] == label] for label in labels})

    member_names = [(v, seed) for v in group for seed in seeds]  # member j * S + i = (variant j, seed i)
    ended, last_metrics = {}, None  # self-ended pre-training phases, for a resumed run
    if resume and ckpt_path.exists():
        states, start, seconds, rows = load_checkpoint(ckpt_path, driver.init())
        ended = {r["phase"]: r["update"] for r in rows if r.get("phase_ended")}
        last_metrics = _metrics_at(rows, member_names, start)
        record()
    bar.update(start * len(group))
    if start >= last_update:
        return pretrain_end
    every = study.checkpoint_every or study.eval_every
    last_saved = start
    last_score = {(r["variant"], r["seed"]): r["score"] for r in rows}  # resumed: a seed that had diverged stays out
    alive = np.array([math.isfinite(last_score.get((v.label, seed), 0.0)) for v, seed in member_names])
    for chunk in driver.run(phases, study.eval_every, states, start, seconds, ended, last_metrics):
        if recorder.stop.is_set():
            raise Stopped(f"{name} stopped at update {start}; last checkpoint: update {last_saved}")
        finite = np.asarray(chunk.metrics.pop("finite"), bool)
        if not finite.all():
            newly = [f"{v.label}/seed {s}" if swept else str(s)
                     for (v, s), ok, a in zip(member_names, finite, alive) if a and not ok]
            alive &= finite
            if newly:
                tqdm.write(f"diverged: {first_variant.algo} ({name}), phase {chunk.phase}, seed(s) "
                           f"{', '.join(newly)}, by update {chunk.update}", file=sys.stderr)
            if not alive.any():
                record()
                raise Diverged(f"{first_variant.algo} ({name}) diverged in phase {chunk.phase} for every seed by "
                               f"update {chunk.update}; last good checkpoint: update {last_saved} in {ckpt_path}")
        tic = time.perf_counter()
        scores = evaluate_normalized(policy, chunk.states, study.env, study.eval_episodes).mean(axis=1)
        scores[~alive] = np.nan
        rows += _rows(member_names, chunk, scores)
        if chunk.ended:  # a pre-training phase ended itself here: the hand-over, recorded for the summary and resume
            for row in rows[-len(member_names):]:
                row["phase_ended"] = 1
        bar.update((chunk.update - start) * len(group))
        start = chunk.update
        mean_score = float(np.nanmean(scores)) if alive.any() else float("nan")
        bar.set_postfix_str(f"{name} | {chunk.phase} | {chunk.updates_per_s:.0f} upd/s | score "
                            f"{mean_score:.1f} | eval {time.perf_counter() - tic:.1f}s")
        # checkpoints go on after a partial divergence: on resume the diverged seeds' NaN scores keep them out
        if chunk.update - last_saved >= every or chunk.update == last_update:
            save_checkpoint(ckpt_path, chunk.states, chunk.update, chunk.seconds, rows)
            last_saved = chunk.update
        record()
    if any(p.auto_stop for p in phases):  # where pre-training actually ended
        return max(pretrain_ends_of(rows).values(), default=pretrain_end)
    return pretrain_end


def _metrics_at(rows: list[dict], members: list[tuple[Variant, int]], update: int) -> dict[str, np.ndarray] | None:
    """Every metric of the rows at `update`, one value per member (None if a member has no row there)."""
    at = {(r["variant"], r["seed"]): r for r in rows if r["update"] == update}
    if any((v.label, seed) not in at for v, seed in members):
        return None
    fixed = {"variant", "algo", "seed", "phase", "update", "seconds", "score", "phase_ended"}
    names = [k for k in at[(members[0][0].label, members[0][1])] if k not in fixed]
    try:
        return {k: np.array([at[(v.label, seed)][k] for v, seed in members]) for k in names}
    except KeyError:
        return None


def _rows(members: list[tuple[Variant, int]], chunk, scores: np.ndarray) -> list[dict]:
    return [
        {"variant": variant.label, "algo": variant.algo, "seed": seed, "phase": chunk.phase, "update": chunk.update,
         "seconds": round(chunk.seconds, 3), "score": float(scores[m])}
        | {name: float(np.asarray(value)[m]) for name, value in sorted(chunk.metrics.items())}
        for m, (variant, seed) in enumerate(members)
    ]


def write_curves(path: Path, rows: list[dict]) -> None:
    columns = list(dict.fromkeys(k for row in rows for k in row))
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=columns, restval="")
    writer.writeheader()
    writer.writerows(rows)
    atomic_write_text(path, buffer.getvalue())


def read_curves(path: Path) -> list[dict]:
    """A curves.csv back as rows: seed and update as ints, text columns as text, the rest as floats; empty cells
    (a metric another variant logs) are left out."""
    ints, texts = {"seed", "update"}, {"variant", "algo", "phase"}
    with open(path, newline="") as f:
        return [{k: v if k in texts else int(v) if k in ints else float(v) for k, v in row.items() if v != ""}
                for row in csv.DictReader(f)]


def pretrain_ends_of(rows: list[dict]) -> dict[str, int]:
    """Per variant, the last evaluation before offline RL (0 if none): what `run_study` records as its
    pre-training end (for BC, whose whole run is actor pre-training, the last evaluation)."""
    ends: dict[str, int] = {}
    for r in rows:
        ends.setdefault(r["variant"], 0)
        if r.get("phase", "offline_rl") != "offline_rl":
            ends[r["variant"]] = max(ends[r["variant"]], r["update"])
    return ends


def merge_runs(run_dirs: list[Path], out_dir: Path) -> list[dict]:
    """One study from runs of it that each trained some of its variants (say one process per variant on a GPU):
    their variants and curves side by side in `out_dir` (config.json, curves.csv, summary.json, curves.png),
    re-summarised, so that the from-scratch asymptote and the updates to 90 % of it reach every variant.  The runs
    must agree on everything but their variants (and checkpoint interval); `out_dir` must not hold a run yet."""
    if (out_dir / "config.json").exists():
        raise FileExistsError(f"{out_dir} already holds a run; merge into a new directory")
    studies = []
    for d in run_dirs:
        if not (d / "config.json").exists() or not (d / "curves.csv").exists():
            raise FileNotFoundError(f"{d}: not a run directory (config.json and curves.csv expected)")
        studies.append(Study.from_json((d / "config.json").read_text()))
    own = ("variants", "reference", "checkpoint_every")
    shared = [{k: v for k, v in dataclasses.asdict(s).items() if k not in own} for s in studies]
    for d, fields in zip(run_dirs[1:], shared[1:]):
        if differ := [k for k in fields if fields[k] != shared[0][k]]:
            raise ValueError(f"{d} is not the same study as {run_dirs[0]}: {', '.join(differ)} differ")
    variants = tuple(v for s in studies for v in s.variants)
    # a run without the from-scratch variant names no reference; the one that trained it does
    references = sorted({s.reference for s in studies if s.reference is not None})
    if len(references) > 1:
        raise ValueError(f"the runs name different reference variants: {', '.join(references)}")
    reference = references[0] if references else None
    study = dataclasses.replace(studies[0], variants=variants, reference=reference)  # checks labels are unique
    rows = [r for d in run_dirs for r in read_curves(d / "curves.csv")]
    ends = pretrain_ends_of(rows)
    summary = summarize(study, rows, ends)
    out_dir.mkdir(parents=True, exist_ok=True)
    records = [r for d in run_dirs for r in json.loads((d / "config.json").read_text()).get("runs", [])]
    atomic_write_text(out_dir / "config.json", study.record_json(previous=json.dumps({"runs": records})))
    write_curves(out_dir / "curves.csv", rows)
    atomic_write_text(out_dir / "summary.json", summary_json(summary))
    plot_curves(out_dir / "curves.png", study, rows, ends)
    return summary


T95 = {1: 12.706, 2: 4.303, 3: 3.182, 4: 2.776, 5: 2.571, 6: 2.447, 7: 2.365, 8: 2.306, 9: 2.262, 10: 2.228}


def t975(df: int) -> float:
    """Student-t 97.5 % quantile: exact table to df = 10, then the Cornish-Fisher expansion (error < 0.1 %)."""
    if df in T95:
        return T95[df]
    z = 1.959964
    return z + (z**3 + z) / (4 * df) + (5 * z**5 + 16 * z**3 + 3 * z) / (96 * df**2)


def ci95(values: np.ndarray) -> float:
    """Half-width of the 95 % t-interval of the mean of the finite values (0 for a single value)."""
    values = values[np.isfinite(values)]
    if len(values) < 2:
        return 0.0
    return float(t975(len(values) - 1) * values.std(ddof=1) / math.sqrt(len(values)))


def score_matrix(rows: list[dict], label: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(updates (E,), seconds (E,), scores (S, E)) of one variant."""
    mine = [r for r in rows if r["variant"] == label]
    updates = np.array(sorted({r["update"] for r in mine}))
    seeds = sorted({r["seed"] for r in mine})
    scores = np.full((len(seeds), len(updates)), np.nan)
    seconds = np.zeros(len(updates))
    for r in mine:
        j = int(np.searchsorted(updates, r["update"]))
        scores[seeds.index(r["seed"]), j] = r["score"]
        seconds[j] = r["seconds"]
    return updates, seconds, scores


def reference_label(study: Study, label: str) -> str | None:
    """The from-scratch variant `label` is measured against: `study.reference` (None: none), or in a sweep, where
    labels end in " alpha=2.5" etc., the reference with the same value ("scratch alpha=2.5")."""
    reference = study.reference
    if reference is None:
        return None
    labels = {v.label for v in study.variants}
    if reference in labels:
        return reference
    last = label.rsplit(" ", 1)[-1]
    swept = reference + " " + last if " " in label and "=" in last else None
    return swept if swept in labels else None


def summarize(study: Study, rows: list[dict], pretrain_ends: dict[str, int]) -> list[dict]:
    """Per variant: final score (per seed, the mean of the last 10 % of evaluations, or of those inside
    `final_window`; then mean and 95 % CI over seeds), the from-scratch asymptote, and the first evaluation at which
    the seed-mean reaches 90 % of it (in a sweep: of the reference with the same swept value)."""
    with warnings.catch_warnings():  # NaN means of all-NaN data (no reference, every seed diverged) are expected
        warnings.simplefilter("ignore", RuntimeWarning)
        return _summarize(study, rows, pretrain_ends)


def _summarize(study: Study, rows: list[dict], pretrain_ends: dict[str, int]) -> list[dict]:
    finals = {}
    for v in study.variants:
        updates, _, scores = score_matrix(rows, v.label)
        if study.final_window:
            keep = (updates >= study.final_window[0]) & (updates <= study.final_window[1])
        else:
            keep = np.arange(len(updates)) >= len(updates) - max(1, int(round(0.1 * len(updates))))
        # a seed that diverged before or inside the window has NaN there, so its final is NaN (not the mean of
        # its evaluations before it diverged): it is left out of the mean and listed in seeds_diverged
        finals[v.label] = scores[:, keep].mean(axis=1) if keep.any() else np.full(len(study.seeds), np.nan)
    summary = []
    for v in study.variants:
        reference = reference_label(study, v.label)
        asymptote = float(np.nanmean(finals[reference])) if reference else float("nan")
        trend = _trend(np.nanmean(score_matrix(rows, reference)[2], axis=0)) if reference else None
        updates, seconds, scores = score_matrix(rows, v.label)
        threshold = asymptote - 0.1 * abs(asymptote)  # 90 % of a positive asymptote; below a negative one too
        reached = np.flatnonzero(np.nanmean(scores, axis=0) >= threshold) if len(updates) else []
        config = make_config(v.algo, study.env, study.dataset, **dict(v.overrides))
        mean_curve = np.nanmean(scores, axis=0) if len(updates) else np.array([np.nan])
        peak = int(np.nanargmax(mean_curve)) if np.isfinite(mean_curve).any() else None
        summary.append({
            "variant": v.label, "env": study.env, "dataset": study.dataset, "algo": v.algo,
            "pretrain": getattr(config, "pretrain", "none"), "seeds": list(study.seeds), "updates": study.updates,
            "final_score_mean": float(np.nanmean(finals[v.label])), "final_score_ci95": ci95(finals[v.label]),
            "final_score_std": float(np.nanstd(finals[v.label], ddof=1)) if len(study.seeds) > 1 else 0.0,
            "asymptote": asymptote,
            # seed-mean of the reference over its last 20 % of evaluations minus the 20 % before: far from 0 means
            # the "asymptote" is not one yet (the budget ended while the reference was still moving)
            "asymptote_trend": trend,
            "updates_to_90pct": int(updates[reached[0]]) if len(reached) else None,
            # training wall-clock of the program that trained this variant: in a vmapped sweep, the whole group's
            "seconds_to_90pct": float(seconds[reached[0]]) if len(reached) else None,
            "pretrain_updates": pretrain_ends.get(v.label, 0),
            # the seed-mean curve's best evaluation, and how far the final score is below it (the paper's
            # stability question: does a variant stay up?)
            "peak_score_mean": float(mean_curve[peak]) if peak is not None else float("nan"),
            "peak_update": int(updates[peak]) if peak is not None else None,
            "fall_from_peak": float(mean_curve[peak] - np.nanmean(finals[v.label])) if peak is not None
            else float("nan"),
            # seeds whose final score is not finite (diverged and stopped): the mean and CI above leave them out
            "seeds_diverged": [seed for seed, f in zip(study.seeds, finals[v.label]) if not np.isfinite(f)],
            "overrides": dict(v.overrides),
            "config": dataclasses.asdict(config),
        })
    return summary


def summary_json(summary: list[dict]) -> str:
    """summary.json text: NaN (no asymptote, every seed diverged) becomes null, which JSON has and NaN is not."""
    def clean(x):
        if isinstance(x, float) and not math.isfinite(x):
            return None
        if isinstance(x, dict):
            return {k: clean(v) for k, v in x.items()}
        return [clean(v) for v in x] if isinstance(x, list) else x
    return json.dumps(clean(summary), indent=2)


def _trend(curve: np.ndarray) -> float | None:
    k = max(1, int(round(0.2 * len(curve))))
    if len(curve) < 2 * k or not np.isfinite(curve[-2 * k:]).any():
        return None
    return float(np.nanmean(curve[-k:]) - np.nanmean(curve[-2 * k:-k]))


def plot_curves(path: Path, study: Study, rows: list[dict], pretrain_ends: dict[str, int]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for i, v in enumerate(study.variants):
        updates, _, scores = score_matrix(rows, v.label)
        if not len(updates):
            continue
        mean = np.nanmean(scores, axis=0)
        half = np.array([ci95(scores[:, j]) for j in range(len(updates))])
        line, = ax.plot(updates, mean, label=v.label, color=f"C{i}")
        ax.fill_between(updates, mean - half, mean + half, alpha=0.2, color=f"C{i}")
        if pretrain_ends.get(v.label):
            ax.axvline(pretrain_ends[v.label], color=line.get_color(), ls=":", lw=1)
    ax.set_xlabel("updates (pre-training included; dotted: end of pre-training)")
    ax.set_ylabel("D4RL-normalised score")
    ax.set_title(f"{study.name}: {study.dataset}, {len(study.seeds)} seeds, mean and 95% CI")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=120)
    plt.close(fig)
    atomic_write_bytes(path, buffer.getvalue())


def summary_table(summary: list[dict]) -> str:
    """One markdown table.  In a sweep each variant has its own reference (the scratch run with the same swept
    value), so when the asymptotes differ they get a column instead of the header."""
    first = summary[0]
    known = [s for s in summary if _known(s["asymptote"])]
    asymptotes = {round(s["asymptote"], 6) for s in known}
    per_variant = len(asymptotes) > 1
    head = f"{first['dataset']}, {len(first['seeds'])} seeds, {first['updates']:,} updates per variant"
    if per_variant:
        head += "; asymptote (final of the from-scratch run with the same swept value) per variant"
    elif not asymptotes:
        head += "; no from-scratch asymptote (no reference variant, or every seed of it diverged)"
    else:
        trend = known[0].get("asymptote_trend")
        head += (f"; asymptote (from-scratch final) {known[0]['asymptote']:.1f}"
                 + (f", its trend over the last 20 % of evaluations {trend:+.1f}" if trend is not None else ""))
    cols = "| variant | final score | updates to 90 % | seconds to 90 % | pre-training updates | peak (fall to final) |"
    rule = "|---|--:|--:|--:|--:|--:|"
    if per_variant:
        cols, rule = cols + " asymptote (trend) |", rule + "--:|"
    lines = [head, "", cols, rule]
    for s in summary:
        u = "never" if s["updates_to_90pct"] is None else f"{s['updates_to_90pct']:,}"
        t = "never" if s["seconds_to_90pct"] is None else f"{s['seconds_to_90pct']:.0f}"
        gone = s.get("seeds_diverged") or []  # older summaries lack the key
        variant = s["variant"] + (f" ({len(gone)} seed(s) diverged, not in the mean)" if gone else "")
        final = f"{s['final_score_mean']:.1f} ± {s['final_score_ci95']:.1f}" if _known(s["final_score_mean"]) else "n/a"
        peak = s.get("peak_score_mean")  # older summaries lack it
        peak = (f"{peak:.1f} at {s['peak_update']:,} ({s['fall_from_peak']:.1f})" if _known(peak) else "n/a")
        row = (f"| {variant} | {final} | {u} | {t} | "
               f"{s['pretrain_updates']:,} | {peak} |")
        if per_variant:
            tr = s.get("asymptote_trend")
            row += (f" {s['asymptote']:.1f}" if _known(s["asymptote"]) else " n/a") + (
                f" ({tr:+.1f})" if tr is not None else "") + " |"
        lines.append(row)
    return "\n".join(lines)


def _known(x) -> bool:
    """A number summary.json has (null, or NaN in older files, where there is none)."""
    return x is not None and x == x


def print_table(summary: list[dict]) -> None:
    print(summary_table(summary))
