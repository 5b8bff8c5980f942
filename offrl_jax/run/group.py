"""One group's run: a variant's S seeds, or a sweep group's values x seeds, trained as one program and evaluated
between chunks, with its checkpoints and its rows of curves.csv (`offrl_jax.run.runner.run_study` runs the groups).

`run_group` is the group's whole life, in the steps of `GroupRun`, each a method:

    GroupRun(...)     build: the algorithm, its device data, the driver and policy, the planned phases, the files
    restore           where it starts: from scratch, from a `--from` run's hand-over, or (resumed) from its last
                      checkpoint; inside the online phase from its saved envs, or again from its hand-over
    chunks            what is evaluated: the driver's offline chunks, then the online phase's
    check_finite      divergence: a seed whose loss or parameters went non-finite drops out; every seed: `Diverged`
    evaluate          every member's score, its rows, the progress bar
    save              the last checkpoint when due (with the online state, the kept ones, the hand-over)
    save_best         each variant's best evaluation so far

The rows' own helpers (`ended_pretraining`, `best_scores`, `metrics_at`, `chunk_rows`) are `offrl_jax.run.results`'s.
"""
from __future__ import annotations

import json
import math
import os
import shutil
import sys
import time
from pathlib import Path

import jax
import numpy as np

from offrl_jax.algos import make_algorithm
from offrl_jax.algos.common import OFFLINE_RL
from offrl_jax.data.dataset import Dataset
from offrl_jax.data.device import DeviceData, device_data
from offrl_jax.driver import Chunk, Driver
from offrl_jax.envs.evaluate import evaluate_normalized, make_policy
from offrl_jax.online.loop import online_state_key, run_online
from offrl_jax.online.record import record_chunk
from offrl_jax.run.progress import Recorder
from offrl_jax.run.results import best_scores, chunk_rows, ended_pretraining, metrics_at
from offrl_jax.run.resume import (
    checkpoint_path,
    group_identity,
    kept_updates,
    load_online_state,
    save_online_state,
    start_from,
)
from offrl_jax.run.study import Study, Variant
from offrl_jax.system import distributed
from offrl_jax.system.checkpoint import load_checkpoint, save_checkpoint


class Diverged(RuntimeError):
    """Every seed of a variant produced a non-finite loss or parameter."""


class Stopped(RuntimeError):
    """Another variant failed or the run was interrupted; this one stopped at the end of a slice."""


def run_group(study: Study, group: tuple[Variant, ...], swept: str | None, ds: Dataset, data_sha256: str,
              out_dir: Path, resume: bool, bar, recorder: Recorder, data: DeviceData | None = None) -> int:
    """Train one variant (S seeds in one program), or a sweep group (values x seeds in one program), evaluating
    between chunks; returns the number of pre-training updates.  `data`: `ds`'s device form for the group's config,
    where the caller shares one (a worker process makes its own)."""
    run = GroupRun(study, group, swept, ds, data_sha256, out_dir, bar, recorder, data)
    if run.restore(resume):  # a resumed run whose online phase had ended
        bar.update((run.last_update + study.online.updates()) * len(group))
        return run.pretraining_updates()
    bar.update(run.start * len(group))
    if run.start >= run.last_update and study.online is None:
        return run.pretraining_updates()
    bar.status(f"{run.name} | compiling, then {min(study.eval_every, max(run.last_update - run.start, 1)):,} "
               "updates to the first evaluation")
    for chunk in run.chunks():
        if recorder.stop.is_set():
            raise Stopped(f"{run.name} stopped at update {chunk.update}; last checkpoint: update {run.last_saved}")
        run.check_finite(chunk)
        host_states, scores = run.evaluate(chunk)
        run.save_best(chunk, host_states, scores)  # first: a resume goes on from `save`'s checkpoint, never back
        run.save(chunk, host_states)
        run.record()
    return run.pretraining_updates()


class GroupRun:
    """One group's run, step by step (the module's docstring lists the steps); its attributes are the run's state:
    `states`, `start`, `seconds` and `rows` where it goes on from, then `start` and `rows` as its chunks end."""

    def __init__(self, study: Study, group: tuple[Variant, ...], swept: str | None, ds: Dataset, data_sha256: str,
                 out_dir: Path, bar, recorder: Recorder, data: DeviceData | None = None):
        """Build what the group trains with: its algorithm, device data, driver and policy, the planned phases, and
        the checkpoint files it reads and writes."""
        self.study, self.group, self.swept, self.ds, self.data_sha256 = study, group, swept, ds, data_sha256
        self.out_dir, self.bar, self.recorder = out_dir, bar, recorder
        self.labels = [v.label for v in group]
        self.config = config = study.config(group[0].label)
        self.algo = make_algorithm(config, ds.obs_dim, ds.act_dim, len(ds))
        self.data = data if data is not None else device_data(ds, config.gamma,
                                                               normalize_reward=config.normalize_reward)
        sweep = (swept, tuple(float(getattr(study.config(v.label), swept)) for v in group)) if swept else None
        self.driver = Driver(self.algo, self.data.arrays, study.seeds, study.batch_size, sweep=sweep)
        self.policy = make_policy(self.algo.act, self.data.obs_mean, self.data.obs_std)
        self.phases = self.algo.phases(config.budget(study.updates))
        self.pretrain_end = sum(p.steps for p in self.phases if p.pretraining)
        self.last_update = sum(p.steps for p in self.phases)  # TD3 trims an odd budget to its 2-update call grid
        self.name = " + ".join(self.labels)
        self.members = [(v, seed) for v in group for seed in study.seeds]  # member j * S + i = (variant j, seed i)
        self.ckpt_path = checkpoint_path(out_dir, group)
        self.handover_path = checkpoint_path(out_dir, group, "handover")
        self.online_path = checkpoint_path(out_dir, group, "online")
        self.meta = {"identity": json.dumps(group_identity(study, group, data_sha256)), "env": study.env,
                     "members": [[v.label, seed] for v in group for seed in study.seeds],
                     "obs_mean": self.data.obs_mean, "obs_std": self.data.obs_std}
        self.writer = distributed.is_writer()  # with several processes only process 0 writes files
        self.states, self.start, self.seconds, self.rows = None, 0, 0.0, []
        self.ended, self.last_metrics = {}, None  # self-ended pre-training phases, for a resumed run
        self.saved_online = None  # a resumed online phase's envs and buffers
        self.every = study.checkpoint_every or study.eval_every
        self.last_saved = 0
        self.alive = np.ones(len(self.members), bool)  # the members that have not diverged
        self.best: dict[str, float] = {}  # each variant's best seed-mean score so far
        self.moved = 0  # updates of the chunk under way, shown as its slices end
        self.handover = {"states": None, "seconds": 0.0}  # the offline phases' last states, where online starts
        self.recording = True  # the online transitions go to online/*.hdf5 until a file cannot go on (`record_chunk`)

    def record(self) -> None:
        """The group's rows so far, to curves.csv (and the logger)."""
        self.recorder.set({label: [r for r in self.rows if r["variant"] == label] for label in self.labels})

    def pretraining_updates(self) -> int:
        """The group's pre-training updates: planned, or where a self-ending phase ended."""
        return ended_pretraining(self.phases, self.rows, self.pretrain_end)

    def restore(self, resume: bool) -> bool:
        """Where the group starts: from scratch; from a `--from` run's offline phases (saved here as this run's own
        hand-over); or, resumed, from its hand-over (a `--from` run stopped before its first online evaluation,
        checked by `check_resume`) or its last checkpoint.  Inside the online phase it goes on exactly from the saved
        envs, or without them starts again from the hand-over, which it recomputes exactly (its randomness and the
        envs' resets are functions of the seeds and the env step).  Sets the run's state (a resumed seed that had
        diverged stays out; the best checkpoints already written count); True when a resumed run's online phase
        had ended."""
        study, online, init = self.study, self.study.online, self.driver.init
        finished = False
        if study.start_from is not None and resume and not self.ckpt_path.exists() and self.handover_path.is_file():
            self.states, self.start, self.seconds, self.rows = load_checkpoint(self.handover_path, init())
            self.record()
        elif study.start_from is not None and not (resume and self.ckpt_path.exists()):
            self.states, self.start, self.seconds, self.rows = start_from(study, self.group, self.data_sha256, init(),
                                                                          self.last_update)
            if self.writer:  # where this run's online phase starts, as a run that trained its offline phases keeps it
                save_checkpoint(self.handover_path, self.states, self.start, self.seconds, self.rows, self.meta)
            self.record()
        elif resume and self.ckpt_path.exists():
            self.states, self.start, self.seconds, self.rows = load_checkpoint(self.ckpt_path, init())
            env_steps = max((r.get("env_steps", 0) for r in self.rows), default=0)
            if online is not None and 0 < env_steps < online.steps:  # inside the online phase
                key = online_state_key(self.start, env_steps, self.last_update, online)
                self.saved_online = load_online_state(self.online_path, key)
                if self.saved_online is not None:
                    self.bar.write(f"{self.name}: the online phase goes on from env step {env_steps:,} (update "
                                   f"{self.start})")
                else:
                    self.states, self.start, self.seconds, self.rows = load_checkpoint(self.handover_path, init())
                    self.bar.write(f"{self.name}: the online phase starts again from the hand-over (update "
                                   f"{self.start}); it had reached env step {env_steps:,}")
            self.ended = {r["phase"]: r["update"] for r in self.rows if r.get("phase_ended")}
            self.last_metrics = metrics_at(self.rows, self.members, self.start)
            self.record()
            finished = online is not None and env_steps >= online.steps
        self.last_saved = self.start
        last_score = {(r["variant"], r["seed"]): r["score"] for r in self.rows}
        self.alive = np.array([math.isfinite(last_score.get((v.label, seed), 0.0)) for v, seed in self.members])
        self.best = best_scores(self.rows)
        self.handover = {"states": self.states, "seconds": self.seconds}
        return finished

    def on_slice(self, updates: int) -> None:
        """A slice of the chunk under way ended: stop there if told to, else move the bar."""
        if self.recorder.stop.is_set():
            raise Stopped(f"{self.name} stopped at update {self.start + self.moved}; last checkpoint: update "
                          f"{self.last_saved}")
        self.moved += updates
        self.bar.update(updates * len(self.group))

    def chunks(self):
        """The chunks to evaluate: the initial policy of an arm with no offline phase, the driver's offline chunks
        from where the run starts, then the online phase from the offline phases' last states."""
        study, online = self.study, self.study.online
        if self.last_update == 0 and not self.rows:  # no offline phase (an online-only arm)
            self.handover.update(states=self.driver.init(), seconds=0.0)
            yield Chunk(OFFLINE_RL, 0, self.handover["states"], {"finite": np.ones(len(self.members), bool)}, 0.0,
                        0.0)
        for chunk in self.driver.run(self.phases, study.eval_every, self.states, self.start, self.seconds,
                                     self.ended, self.last_metrics, self.on_slice):
            self.handover.update(states=chunk.states, seconds=chunk.seconds)
            yield chunk
        if online is not None:
            scale = self.ds.reward_scale() if self.config.normalize_reward else 1.0
            yield from run_online(self.driver, self.algo, online, study.env, self.data, self.handover["states"],
                                  self.last_update, self.handover["seconds"], scale, self.on_slice,
                                  saved=self.saved_online)

    def check_finite(self, chunk: Chunk) -> None:
        """The members whose loss or parameters went non-finite in `chunk` drop out (said once each); when none is
        left, `Diverged` (the rows so far recorded)."""
        finite = np.asarray(chunk.metrics.pop("finite"), bool)
        if finite.all():
            return
        algo = self.group[0].algo
        newly = [f"{v.label}/seed {s}" if self.swept else str(s)
                 for (v, s), ok, a in zip(self.members, finite, self.alive) if a and not ok]
        self.alive &= finite
        if newly:
            self.bar.write(f"diverged: {algo} ({self.name}), phase {chunk.phase}, seed(s) {', '.join(newly)}, by "
                           f"update {chunk.update}", file=sys.stderr)
        if not self.alive.any():
            self.record()
            raise Diverged(f"{algo} ({self.name}) diverged in phase {chunk.phase} for every seed by update "
                           f"{chunk.update}; " + (f"last good checkpoint: update {self.last_saved} in "
                                                  f"{self.ckpt_path}" if self.ckpt_path.exists() else
                                                  "no checkpoint had been written"))

    def evaluate(self, chunk: Chunk) -> tuple[object, np.ndarray]:
        """Every member's score at `chunk` (NaN for a diverged one) and its rows; the bar moves to the chunk's end.
        Returns the states on the host and the scores."""
        study = self.study
        tic = time.perf_counter()
        host_states, scores = distributed.evaluate_shared(
            chunk.states, lambda s: evaluate_normalized(self.policy, s, study.env, study.eval_episodes).mean(axis=1))
        scores[~self.alive] = np.nan
        self.rows += chunk_rows(self.members, chunk, scores)
        if chunk.ended:  # a pre-training phase ended itself here: the hand-over, recorded for the summary and resume
            for row in self.rows[-len(self.members):]:
                row["phase_ended"] = 1
        self.bar.update((chunk.update - self.start - self.moved) * len(self.group))
        self.start, self.moved = chunk.update, 0
        mean_score = float(np.nanmean(scores)) if self.alive.any() else float("nan")
        rate = "upd/s" if chunk.env_steps is None else f"env steps/s | env step {chunk.env_steps:,}"
        self.bar.set_postfix_str(f"{self.name} | {chunk.phase} | {chunk.updates_per_s:.0f} {rate} | score "
                                 f"{mean_score:.1f} | eval {time.perf_counter() - tic:.1f}s")
        return host_states, scores

    def save(self, chunk: Chunk, host_states) -> None:
        """The last checkpoint, when due: at every evaluation (`checkpoint_every` 0) or the first one past each
        multiple of `checkpoint_every`, at every online evaluation (with the envs and buffers, and the online
        transitions as datasets), at the offline phases' end (before an online phase, also as its hand-over) and
        at the first evaluation (a variant with rows in curves.csv always has a checkpoint to resume from).
        Checkpoints go on after a partial divergence: on resume the diverged seeds' NaN scores keep them out."""
        study, online = self.study, self.study.online
        due = not study.checkpoint_every or chunk.update // self.every > self.last_saved // self.every
        online_chunk = chunk.env_steps is not None
        if not (due or online_chunk or chunk.update == self.last_update or not self.ckpt_path.exists()):
            return
        carried = chunk.carry() if online_chunk and chunk.env_steps < online.steps else None  # every process
        if self.writer:
            if chunk.transitions is not None and self.recording:  # the online env steps as datasets
                failed = record_chunk(self.out_dir, study.env, [(v.label, s) for v, s in self.members],
                                      chunk.env_steps, chunk.transitions)
                if failed:
                    self.bar.write(failed, file=sys.stderr)
                    self.recording = False
            # what a resume cannot remake (the online state, the hand-over) is written before the last checkpoint,
            # so a stop in between leaves the checkpoint behind them, never ahead
            if carried is not None:
                save_online_state(self.online_path, carried)
            if online is not None and not online_chunk and chunk.update == self.last_update:
                save_checkpoint(self.handover_path, host_states, chunk.update, chunk.seconds, self.rows, self.meta)
            save_checkpoint(self.ckpt_path, host_states, chunk.update, chunk.seconds, self.rows, self.meta)
            if online_chunk and carried is None:  # the phase's end, or envs that cannot be saved
                self.online_path.unlink(missing_ok=True)
            if study.keep_checkpoints and not online_chunk:
                keep_copy(self.out_dir, self.group, chunk.update, study.keep_checkpoints)
        self.last_saved = chunk.update

    def save_best(self, chunk: Chunk, host_states, scores: np.ndarray) -> None:
        """Each variant's best evaluation so far (its seed mean): its seeds' states at it, as <variant>.best."""
        seeds = self.study.seeds
        for j, variant in enumerate(self.group):
            mine = slice(j * len(seeds), (j + 1) * len(seeds))
            if self.alive[mine].any() and np.nanmean(scores[mine]) > self.best.get(variant.label, -math.inf):
                self.best[variant.label] = float(np.nanmean(scores[mine]))
                if not self.writer:
                    continue
                save_checkpoint(checkpoint_path(self.out_dir, (variant,), "best"),
                                jax.tree.map(lambda x, m=mine: x[m], host_states), chunk.update, chunk.seconds,
                                [r for r in self.rows if r["variant"] == variant.label],
                                self.meta | {"members": self.meta["members"][mine],
                                             "best_score": self.best[variant.label]})


def keep_copy(out_dir: Path, group: tuple[Variant, ...], update: int, newest: int) -> None:
    """The last checkpoint, just written at `update`, is kept under its update too (a hard link: no copy; the next
    save replaces the last one by a rename, so the link keeps this one); only the `newest` kept ones remain.  After
    the last checkpoint, so that a kept copy means a checkpoint to resume from (`resume.is_resumable`); a stop in
    between loses this one copy, not the run's."""
    last, kept = checkpoint_path(out_dir, group), checkpoint_path(out_dir, group, update)
    kept.unlink(missing_ok=True)
    try:
        os.link(last, kept)
    except OSError:  # a file system without hard links
        shutil.copyfile(last, kept)
    for old in kept_updates(out_dir, group)[:-newest]:
        checkpoint_path(out_dir, group, old).unlink(missing_ok=True)
