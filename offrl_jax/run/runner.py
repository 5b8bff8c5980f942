"""Run a study: several variants (algorithm + hyper-parameters) on one dataset, each with S seeds in one program,
evaluated between scan chunks, with atomic results, checkpoints every N updates, `resume`, and a clean stop on
divergence.  Each group (a variant, or a sweep group trained as one program) runs in `offrl_jax.run.group`.

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
import sys
from concurrent.futures import FIRST_EXCEPTION, ThreadPoolExecutor, wait
from pathlib import Path

import jax

from offrl_jax.data.dataset import Dataset
from offrl_jax.data.device import DeviceForms
from offrl_jax.run.bc_level import figure_lines
from offrl_jax.run.group import Diverged, Stopped, run_group
from offrl_jax.run.loggers import make_logger
from offrl_jax.run.online_summary import plot_online
from offrl_jax.run.progress import Progress, Recorder
from offrl_jax.run.provenance import fingerprint
from offrl_jax.run.results import curves_title, plot_curves
from offrl_jax.run.resume import check_resume, saved_rows
from offrl_jax.run.study import Study, Variant
from offrl_jax.run.summary import behaviour_score, summarize, summary_json
from offrl_jax.system import distributed
from offrl_jax.system.checkpoint import atomic_write_text
from offrl_jax.system.workers import run_in_processes

__all__ = ["Diverged", "Stopped", "run_study"]  # the run's two failures are `offrl_jax.run.group`'s


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
                         logger if writer else None, saved_rows(out_dir) if resume and writer else [])
    pretrain_ends: dict[str, int] = {}
    groups = study.groups()
    forms = DeviceForms(dataset)  # the groups run in this process share the dataset's device form(s)

    def run(group: tuple[tuple[Variant, ...], str | None]) -> None:
        config = study.config(group[0][0].label)
        data = forms(config.gamma, config.normalize_reward)
        end = run_group(study, *group, dataset, data_sha256, out_dir, resume, bar, recorder, data)
        pretrain_ends.update({v.label: end for v in group[0]})

    try:
        if parallel <= 1 or len(groups) == 1:
            for group in groups:
                run(group)
        elif processes if processes is not None else jax.default_backend() == "cpu":
            tasks = [(study, *group, dataset, data_sha256, out_dir, resume) for group in groups]
            run_in_processes(run_group, tasks, parallel, bar, recorder,
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
