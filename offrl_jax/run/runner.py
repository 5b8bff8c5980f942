"""Run a study: several variants (algorithm + hyper-parameters) on one dataset, each with S seeds in one program,
evaluated between scan chunks, with atomic results, checkpoints every N updates, `resume`, and a clean stop on
divergence.

Output directory:
    config.json      the study (enough to resume or replay it), every variant's resolved config ("resolved": every
                     field after per-env defaults and presets; "sources": where each value came from), and one record
                     per start or resume ("runs": command,
                     git commit, versions, backend, dataset fingerprint; `offrl_jax.run.provenance`)
    curves.csv       variant, seed, phase, update, seconds, score, every logged metric; `seconds` is the variant's
                     training wall-clock so far: its jitted chunks including their XLA compilation, excluding the
                     evaluations (so a run stopped with SIGSTOP, or sharing its core, shows longer seconds)
    summary.json     one object per variant (see `summarize`)
    curves.png       mean and 95 % CI per variant against updates, pre-training end marked
    checkpoints/     <variant>.msgpack, the last complete chunk of every variant (of every sweep group:
                     <label>+<label>...), <variant>.best.msgpack, its seeds at its best seed-mean evaluation, and
                     with `keep_checkpoints` = N the N newest of <variant>.<update>.msgpack; each with the
                     observation statistics and the env, for `offrl_jax.policy.load_policy`; with an online phase,
                     <variant>.handover.msgpack (where it started) and <variant>.online.msgpack while it runs
"""
from __future__ import annotations

import json
import math
import os
import shutil
import sys
import time
from concurrent.futures import FIRST_EXCEPTION, ThreadPoolExecutor, wait
from pathlib import Path

import jax
import numpy as np

from offrl_jax.algos import make_algorithm
from offrl_jax.algos.common import OFFLINE_RL
from offrl_jax.data.dataset import Dataset
from offrl_jax.data.device import DeviceData, DeviceForms, device_data
from offrl_jax.driver import Chunk, Driver
from offrl_jax.envs.evaluate import evaluate_normalized, make_policy
from offrl_jax.online.loop import online_state_key, run_online
from offrl_jax.online.record import record_chunk
from offrl_jax.run.bc_level import figure_lines
from offrl_jax.run.loggers import make_logger
from offrl_jax.run.online_summary import plot_online
from offrl_jax.run.progress import Progress, Recorder
from offrl_jax.run.provenance import fingerprint
from offrl_jax.run.results import curves_title, plot_curves, pretrain_ends_of
from offrl_jax.run.resume import (
    check_resume,
    checkpoint_path,
    group_identity,
    kept_updates,
    load_online_state,
    save_online_state,
    start_from,
)
from offrl_jax.run.study import Study, Variant
from offrl_jax.run.summary import behaviour_score, summarize, summary_json
from offrl_jax.system import distributed
from offrl_jax.system.checkpoint import atomic_write_text, load_checkpoint, save_checkpoint
from offrl_jax.system.workers import run_in_processes


class Diverged(RuntimeError):
    """Every seed of a variant produced a non-finite loss or parameter."""


def run_study(study: Study, out_dir: Path, dataset: Dataset, resume: bool = False, progress: bool = True,
              parallel: int = 1, processes: bool | None = None, logger: str | None = None,
              data_sha256: str | None = None, verify: bool = True) -> list[dict]:
    """Run (or resume) every variant; write results as it goes; return the summary.

    Variants that differ only in one sweepable hyper-parameter (`sweep_groups`) train as one program unless
    `study.vmap_sweeps` is off. `parallel` > 1 runs that many variants (or groups) at once. On the CPU they run in
    worker processes pinned to their own cores (`offrl_jax.system.workers`, 10-20 % faster than threads on 2 cores);
    elsewhere (one GPU), or with `processes=False`, in threads of this process (a jitted chunk releases the GIL).
    Results do not depend on either (each variant's randomness is its own). `logger` ("tensorboard" or "wandb") also
    sends every evaluation's scores and metrics there (`offrl_jax.run.loggers`); curves.csv stays the record.
    `data_sha256`: the dataset's `fingerprint`, where the caller has computed it already; `verify` False skips the
    resume check for a caller that has just made it (the command line checks every study before the first one
    starts).
    """
    data_sha256 = data_sha256 or fingerprint(dataset)  # given by a caller that has it (~0.3 s per 1M rows)
    if resume and verify:  # before anything is written: the checkpoints must belong to this study and this data
        check_resume(study, out_dir, dataset, data_sha256)
    writer = distributed.is_writer()  # with several processes (system.distributed) only process 0 writes files
    if distributed.processes() > 1:
        parallel = 1  # every process runs the groups in the same order
    config_path = out_dir / "config.json"  # a resumed multi-study run may not have begun this study yet
    previous = config_path.read_text() if resume and config_path.exists() else None
    try:
        record = study.record_json(dataset, previous, data_sha256)
    except ValueError as e:
        raise ValueError(f"{config_path}: {e}") from None
    if writer:
        out_dir.mkdir(parents=True, exist_ok=True)
    if logger is not None and writer:  # a logger that cannot start (no wandb login, ...) is a warning: the run goes on
        try:
            logger = make_logger(logger, out_dir, study, json.loads(record), resume)
        except ValueError as e:
            print(f"warning: {e}; the run goes on without it (curves.csv is the record)", file=sys.stderr)
            logger = None
    if writer:
        atomic_write_text(config_path, record)
    online_updates = study.online.updates() if study.online else 0
    offline = sum(study.config(v.label).budget(study.updates) for v in study.variants)
    bar = Progress(offline + len(study.variants) * online_updates, progress, quiet=not writer)
    recorder = Recorder(out_dir / "curves.csv" if writer else None, [v.label for v in study.variants],
                         logger if writer else None)
    pretrain_ends: dict[str, int] = {}
    groups = study.groups()
    forms = DeviceForms(dataset)  # the groups run in this process share the dataset's device form(s)

    def run(group: tuple[tuple[Variant, ...], str | None]) -> None:
        config = study.config(group[0][0].label)
        data = forms(config.gamma, config.normalize_reward)
        end = _run_group(study, *group, dataset, data_sha256, out_dir, resume, bar, recorder, data)
        pretrain_ends.update({v.label: end for v in group[0]})

    try:
        if parallel <= 1 or len(groups) == 1:
            for group in groups:
                run(group)
        elif processes if processes is not None else jax.default_backend() == "cpu":
            tasks = [(study, *group, dataset, data_sha256, out_dir, resume) for group in groups]
            run_in_processes(_run_group, tasks, parallel, bar, recorder,
                             lambda i, end: pretrain_ends.update({v.label: end for v in groups[i][0]}))
        else:
            with ThreadPoolExecutor(max_workers=parallel) as pool:
                futures = [pool.submit(run, g) for g in groups]
                try:
                    done, _ = wait(futures, return_when=FIRST_EXCEPTION)
                    for future in [f for f in done if f.exception() is not None] + futures:  # a failure first
                        future.result()
                except BaseException:
                    recorder.stop.set()  # the other variants stop at the end of their current slice
                    raise
    finally:
        bar.close()
        if recorder.logger is not None:
            try:
                recorder.logger.close()
            except Exception as e:  # noqa: BLE001 -- never in the way of the run's own outcome
                print(f"warning: closing the logger failed ({type(e).__name__}: {e})", file=sys.stderr)
    history = recorder.all_rows()
    summary = summarize(study, history, pretrain_ends, behaviour_score(dataset))
    if writer:
        atomic_write_text(out_dir / "summary.json", summary_json(summary))
        plot_curves(out_dir / "curves.png", study, history, pretrain_ends, figure_lines(summary))
        if study.online is not None:
            plot_online(out_dir / "online.png", [v.label for v in study.variants], history, study.seeds,
                        curves_title(study.name, "online phase", len(study.seeds)),
                        behaviour_score(dataset))
    return summary


class Stopped(RuntimeError):
    """Another variant failed or the run was interrupted; this one stopped at the end of a slice."""


def _run_group(study: Study, group: tuple[Variant, ...], swept: str | None, ds: Dataset, data_sha256: str,
               out_dir: Path, resume: bool, bar, recorder: Recorder, data: DeviceData | None = None) -> int:
    """Train one variant (S seeds in one program), or a sweep group (values x seeds in one program), evaluating
    between chunks; returns the number of pre-training updates.  `data`: `ds`'s device form for the group's config,
    where the caller shares one (a worker process makes its own)."""
    first_variant, labels, seeds = group[0], [v.label for v in group], study.seeds
    config = study.config(first_variant.label)
    algo = make_algorithm(config, ds.obs_dim, ds.act_dim, len(ds))
    data = data if data is not None else device_data(ds, config.gamma, normalize_reward=config.normalize_reward)
    sweep = (swept, tuple(float(getattr(study.config(v.label), swept)) for v in group)) if swept else None
    driver = Driver(algo, data.arrays, seeds, study.batch_size, sweep=sweep)
    policy = make_policy(algo.act, data.obs_mean, data.obs_std)
    phases = algo.phases(config.budget(study.updates))
    pretrain_end = sum(p.steps for p in phases if p.pretraining)
    last_update = sum(p.steps for p in phases)  # TD3 trims an odd budget to its 2-update call grid
    name = " + ".join(labels)
    ckpt_path = checkpoint_path(out_dir, group)
    meta = {"identity": json.dumps(group_identity(study, group, data_sha256)), "env": study.env,
            "members": [[v.label, seed] for v in group for seed in seeds],
            "obs_mean": data.obs_mean, "obs_std": data.obs_std}
    states, start, seconds, rows = None, 0, 0.0, []
    writer = distributed.is_writer()

    def record():
        recorder.set({label: [r for r in rows if r["variant"] == label] for label in labels})

    member_names = [(v, seed) for v in group for seed in seeds]  # member j * S + i = (variant j, seed i)
    ended, last_metrics = {}, None  # self-ended pre-training phases, for a resumed run
    online = study.online
    handover_path = checkpoint_path(out_dir, group, "handover")
    online_path, saved_online = checkpoint_path(out_dir, group, "online"), None
    if study.start_from is not None and resume and not ckpt_path.exists() and handover_path.is_file():
        states, start, seconds, rows = load_checkpoint(handover_path, driver.init())  # stopped before its first
        record()  # online evaluation: it goes on from its hand-over (checked by `check_resume`)
    elif study.start_from is not None and not (resume and ckpt_path.exists()):  # a finished run's offline phases
        states, start, seconds, rows = start_from(study, group, data_sha256, driver.init(), last_update)
        if writer:  # where this run's online phase starts, as a run that trained its offline phases keeps it
            save_checkpoint(handover_path, states, start, seconds, rows, meta)
        record()
    elif resume and ckpt_path.exists():
        states, start, seconds, rows = load_checkpoint(ckpt_path, driver.init())
        env_steps = max((r.get("env_steps", 0) for r in rows), default=0)
        if online is not None and 0 < env_steps < online.steps:  # inside the online phase: it goes on exactly
            saved_online = load_online_state(online_path, online_state_key(start, env_steps, last_update, online))
            if saved_online is not None:
                bar.write(f"{name}: the online phase goes on from env step {env_steps:,} (update {start})")
            else:  # no saved envs: it starts again from the hand-over, which it recomputes exactly (its randomness
                # and the envs' resets are functions of the seeds and the env step)
                states, start, seconds, rows = load_checkpoint(handover_path, driver.init())
                bar.write(f"{name}: the online phase starts again from the hand-over (update {start}); it had "
                          f"reached env step {env_steps:,}")
        ended = {r["phase"]: r["update"] for r in rows if r.get("phase_ended")}
        last_metrics = _metrics_at(rows, member_names, start)
        record()
        if online is not None and env_steps >= online.steps:
            bar.update((last_update + online.updates()) * len(group))
            return ended_pretraining(phases, rows, pretrain_end)
    bar.update(start * len(group))
    if start >= last_update and online is None:
        return ended_pretraining(phases, rows, pretrain_end)
    every = study.checkpoint_every or study.eval_every
    last_saved = start
    last_score = {(r["variant"], r["seed"]): r["score"] for r in rows}  # resumed: a seed that had diverged stays out
    alive = np.array([math.isfinite(last_score.get((v.label, seed), 0.0)) for v, seed in member_names])
    best = _best_scores(rows)  # resumed: the best checkpoints already written
    moved = 0  # updates of the chunk under way, shown as its slices end

    def on_slice(updates: int) -> None:
        nonlocal moved
        if recorder.stop.is_set():
            raise Stopped(f"{name} stopped at update {start + moved}; last checkpoint: update {last_saved}")
        moved += updates
        bar.update(updates * len(group))

    bar.status(f"{name} | compiling, then {min(study.eval_every, max(last_update - start, 1)):,} updates to the "
               "first evaluation")
    handover = {"states": states, "seconds": seconds}  # the offline phases' last states, where online starts
    recording = True  # the online transitions go to online/*.hdf5 until a file cannot go on (`record_chunk`)

    def chunks():
        if last_update == 0 and not rows:  # no offline phase (an online-only arm): evaluate the initial policy
            handover.update(states=driver.init(), seconds=0.0)
            yield Chunk(OFFLINE_RL, 0, handover["states"], {"finite": np.ones(len(member_names), bool)}, 0.0, 0.0)
        for chunk in driver.run(phases, study.eval_every, states, start, seconds, ended, last_metrics, on_slice):
            handover.update(states=chunk.states, seconds=chunk.seconds)
            yield chunk
        if online is not None:
            scale = ds.reward_scale() if config.normalize_reward else 1.0
            yield from run_online(driver, algo, online, study.env, data, handover["states"], last_update,
                                  handover["seconds"], scale, on_slice, saved=saved_online)

    for chunk in chunks():
        if recorder.stop.is_set():
            raise Stopped(f"{name} stopped at update {chunk.update}; last checkpoint: update {last_saved}")
        finite = np.asarray(chunk.metrics.pop("finite"), bool)
        if not finite.all():
            newly = [f"{v.label}/seed {s}" if swept else str(s)
                     for (v, s), ok, a in zip(member_names, finite, alive) if a and not ok]
            alive &= finite
            if newly:
                bar.write(f"diverged: {first_variant.algo} ({name}), phase {chunk.phase}, seed(s) "
                           f"{', '.join(newly)}, by update {chunk.update}", file=sys.stderr)
            if not alive.any():
                record()
                raise Diverged(f"{first_variant.algo} ({name}) diverged in phase {chunk.phase} for every seed by "
                               f"update {chunk.update}; " + (f"last good checkpoint: update {last_saved} in "
                                                             f"{ckpt_path}" if ckpt_path.exists() else
                                                             "no checkpoint had been written"))
        tic = time.perf_counter()
        host_states, scores = distributed.evaluate_shared(
            chunk.states, lambda s: evaluate_normalized(policy, s, study.env, study.eval_episodes).mean(axis=1))
        scores[~alive] = np.nan
        rows += _rows(member_names, chunk, scores)
        if chunk.ended:  # a pre-training phase ended itself here: the hand-over, recorded for the summary and resume
            for row in rows[-len(member_names):]:
                row["phase_ended"] = 1
        bar.update((chunk.update - start - moved) * len(group))
        start, moved = chunk.update, 0
        mean_score = float(np.nanmean(scores)) if alive.any() else float("nan")
        rate = "upd/s" if chunk.env_steps is None else f"env steps/s | env step {chunk.env_steps:,}"
        bar.set_postfix_str(f"{name} | {chunk.phase} | {chunk.updates_per_s:.0f} {rate} | score "
                            f"{mean_score:.1f} | eval {time.perf_counter() - tic:.1f}s")
        # checkpoints go on after a partial divergence: on resume the diverged seeds' NaN scores keep them out
        # the first evaluation too: a variant with rows in curves.csv always has a checkpoint to resume from
        # every evaluation (`checkpoint_every` 0), or the first one past each multiple of `checkpoint_every`
        due = not study.checkpoint_every or chunk.update // every > last_saved // every
        online_chunk = chunk.env_steps is not None  # online: every evaluation, with the envs and buffers
        if due or online_chunk or chunk.update == last_update or not ckpt_path.exists():
            carried = chunk.carry() if online_chunk and chunk.env_steps < online.steps else None  # every process
            if writer:
                if chunk.transitions is not None and recording:  # the online env steps as datasets
                    failed = record_chunk(out_dir, study.env, [(v.label, s) for v, s in member_names],
                                          chunk.env_steps, chunk.transitions)
                    if failed:
                        bar.write(failed, file=sys.stderr)
                        recording = False
                if carried is not None:  # first, so that a checkpoint never points at an older online state
                    save_online_state(online_path, carried)
                save_checkpoint(ckpt_path, host_states, chunk.update, chunk.seconds, rows, meta)
                if online_chunk and carried is None:  # the phase's end, or envs that cannot be saved
                    online_path.unlink(missing_ok=True)
                if study.keep_checkpoints and not online_chunk:
                    _keep(out_dir, group, chunk.update, study.keep_checkpoints)
                if online is not None and not online_chunk and chunk.update == last_update:
                    save_checkpoint(handover_path, host_states, chunk.update, chunk.seconds, rows, meta)
            last_saved = chunk.update
        for j, variant in enumerate(group):  # each variant's best evaluation so far (its seed mean) is kept too
            mine = slice(j * len(seeds), (j + 1) * len(seeds))
            if alive[mine].any() and np.nanmean(scores[mine]) > best.get(variant.label, -math.inf):
                best[variant.label] = float(np.nanmean(scores[mine]))
                if not writer:
                    continue
                save_checkpoint(checkpoint_path(out_dir, (variant,), "best"),
                                jax.tree.map(lambda x, m=mine: x[m], host_states), chunk.update, chunk.seconds,
                                [r for r in rows if r["variant"] == variant.label],
                                meta | {"members": meta["members"][mine], "best_score": best[variant.label]})
        record()
    return ended_pretraining(phases, rows, pretrain_end)


def ended_pretraining(phases: list, rows: list[dict], planned: int) -> int:
    """The pre-training updates of a group: the `planned` ones, or where a self-ending phase ended (its rows say)."""
    if any(p.auto_stop for p in phases):
        return max(pretrain_ends_of(rows).values(), default=planned)
    return planned


def _keep(out_dir: Path, group: tuple[Variant, ...], update: int, keep: int) -> None:
    """The last checkpoint, just written at `update`, is kept under its update too (a hard link: no copy; the next
    save replaces the last one by a rename, so the link keeps this one); only the `keep` newest kept ones remain."""
    last, kept = checkpoint_path(out_dir, group), checkpoint_path(out_dir, group, update)
    kept.unlink(missing_ok=True)
    try:
        os.link(last, kept)
    except OSError:  # a file system without hard links
        shutil.copyfile(last, kept)
    for old in kept_updates(out_dir, group)[:-keep]:
        checkpoint_path(out_dir, group, old).unlink(missing_ok=True)


def _best_scores(rows: list[dict]) -> dict[str, float]:
    """Per variant, the best seed-mean score of its evaluations so far."""
    by_eval: dict[tuple[str, int, int], list[float]] = {}  # an evaluation: its update and env step (the warm-up's
    for r in rows:  # evaluations share the hand-over's update)
        if math.isfinite(r["score"]):
            by_eval.setdefault((r["variant"], r["update"], r.get("env_steps") or 0), []).append(r["score"])
    best: dict[str, float] = {}
    for (label, *_), scores in by_eval.items():
        best[label] = max(best.get(label, -math.inf), sum(scores) / len(scores))
    return best


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
        | ({} if chunk.env_steps is None else {"env_steps": chunk.env_steps})
        | {name: float(np.asarray(value)[m]) for name, value in sorted(chunk.metrics.items())}
        for m, (variant, seed) in enumerate(members)
    ]
