"""What `python -m experiments.<name>` does, as named steps: `run_command(build, parser, argv)`.

    1. read the command      flags checked; the study (or studies) built, replayed from --config, or read back for
                             --resume; what a killed --overwrite of the directory left aside given back; with
                             --dry-run, printed (`offrl_jax.app.dry_run`), and the command ends here
    2. start the processes   this process's CPU cores, a multi-process run's others (`offrl_jax.app.launch`)
    3. claim the output      the run directory chosen (`offrl_jax.app.outputs`), checked writable and locked
    4. load the data         every dataset once, before anything is written; bad data fails here
    5. check a resume        every checkpoint belongs to its study, data and settings (`offrl_jax.run.resume`),
                             --parallel too; a --config replay's data is the saved run's
    6. run                   each study into its directory (`offrl_jax.run.runner.run_study`), its table printed
    7. clean up              an --overwrite'd earlier run deleted, or given back if the new one has no checkpoint
                             yet; a claimed directory that got nothing removed; the lock released

Expected failures (bad flags, bad data, an unwritable place, divergence) print one line, `error: ...`, and exit 2
(3 for divergence); `OFFRL_JAX_DEBUG=1` re-raises them with the traceback instead.

Over 300 lines for a stated reason: the seven steps share one `Command`'s state (the studies, the claimed directory,
the lock, what an --overwrite set aside) and its clean-up on every exit path; split, each step would take and return
that state and the clean-up would be spread over files. The step bodies call out to app/ and run/ for their parts
(a saved run's replay and extension: `offrl_jax.app.replay`).
"""
from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import os
import shlex
import shutil
import sys
from collections.abc import Callable
from pathlib import Path

from offrl_jax.app.dry_run import describe, state_defaults
from offrl_jax.app.launch import check_backend, start_local_processes, start_processes, use_cpu_cores
from offrl_jax.app.outputs import (
    check_resume_dir,
    give_back_replaced,
    has_checkpoint,
    output_dir,
    replaced_dir,
    saved_studies,
    studies_json,
)
from offrl_jax.app.replay import RUN_FIELDS, extend, recorded_parallel, replay
from offrl_jax.data import catalogue
from offrl_jax.data.dataset import DatasetError
from offrl_jax.data.device import too_few_rows
from offrl_jax.run.provenance import fingerprint, recorded_data
from offrl_jax.run.resume import check_resume, edited_resolved
from offrl_jax.run.runner import Diverged, run_study
from offrl_jax.run.study import Study
from offrl_jax.run.summary import print_table
from offrl_jax.system.checkpoint import atomic_write_text
from offrl_jax.system.cli import UsageError, check_writable_dir, lock_run_dir, one_line_warnings, print_error
from offrl_jax.system.interrupts import exit_code, shielded

Build = Callable[[argparse.Namespace], "Study | list[Study]"]

_UNSET = object()
PROCESS_FLAGS = frozenset({"processes", "distributed", "coordinator", "num_processes", "process_id"})
RESUME_FLAGS = frozenset({"resume", "updates", "parallel", "no_progress", "clip_actions", "logger", "dry_run",
                          *PROCESS_FLAGS})
REPLAY_FLAGS = frozenset({"config", "out", "overwrite", "parallel", "no_progress", "logger", "dry_run", "seeds",
                          "seed_offset",
                          "dataset_path", *RUN_FIELDS, *PROCESS_FLAGS})


DATA_FLAGS = frozenset({"dataset_path", "max_transitions", "clip_actions"})  # with --config: other data, knowingly


def given_dests(parser: argparse.ArgumentParser, argv=None) -> set[str]:
    """The destinations of the flags typed on the command line (typed with their default value too)."""
    dests = [a.dest for a in parser._actions if a.dest != argparse.SUPPRESS] + list(parser._defaults)
    probe = argparse.Namespace(**{dest: _UNSET for dest in dests})  # `set_defaults` entries are never typed
    parser.parse_args(sys.argv[1:] if argv is None else argv, probe)
    return {dest for dest, value in vars(probe).items() if value is not _UNSET}


def _flags(parser: argparse.ArgumentParser, dests) -> str:
    names = {a.dest: a.option_strings[0] for a in parser._actions if a.option_strings}
    return ", ".join(names.get(d, d) for d in sorted(dests))


def load_data(study: Study, clip_actions: bool = False):
    """The study's dataset (`clip_actions`: also clip, for a resumed run saved before studies recorded it)."""
    clip = study.clip_actions or clip_actions or None
    ds = catalogue.load(study.dataset, max_transitions=study.max_transitions, clip_actions=clip, env=study.env)
    if ds.env is not None and ds.env != study.env:
        raise UsageError(f"{study.dataset}: dataset is for env '{ds.env}', not '{study.env}'")
    return ds


def _data_key(study: Study) -> tuple:
    return study.dataset, study.env, study.max_transitions, study.clip_actions


@dataclasses.dataclass
class Command:
    """One command's state across its steps (see the module): what it was asked, where it writes, what it holds."""
    args: argparse.Namespace
    parser: argparse.ArgumentParser
    argv: list[str] | None
    given: set[str] = dataclasses.field(default_factory=set)
    built: Study | list[Study] | None = None
    out: Path | None = None
    replace: bool = False  # --overwrite: an earlier run in `out` is to be replaced
    replaced: Path | None = None  # where that earlier run waits until the new one has its first checkpoint
    lock: object = None
    local: object = None  # the other processes of a --processes run
    writer: bool = True  # this process writes the run (process 0 of a multi-process run)
    given_back: bool = False  # the earlier run is back in `out`: the new one ended before its first checkpoint
    interrupted: bool = False  # by Ctrl-C or SIGTERM
    saved_data: dict = dataclasses.field(default_factory=dict)  # --config: study -> the SHA-256 its data had

    @property
    def resuming(self) -> bool:
        return self.args.resume is not None

    @property
    def studies(self) -> list[Study]:
        return self.built if isinstance(self.built, list) else [self.built]

    def study_dir(self, study: Study) -> Path:
        return self.out / study.name if isinstance(self.built, list) else self.out

    # 1. read the command
    def read(self, build: Build, hparams: Callable[[argparse.Namespace], dict] | None,
             hparam_dests: frozenset[str]) -> None:
        args, parser = self.args, self.parser
        self.given = given = given_dests(parser, self.argv)
        if args.logger is not None:  # its writer must be there before anything is written
            module = {"tensorboard": "tensorboardX", "wandb": "wandb"}[args.logger]
            if importlib.util.find_spec(module) is None:
                raise UsageError(f"--logger {args.logger} needs {module}: pip install -e \".[{args.logger}]\"")
        if self.resuming and args.config is not None:
            raise UsageError("--resume and --config exclude each other: --resume continues a run in place, "
                             "--config starts a new one from its settings")
        named = args.resume if self.resuming else args.out
        interrupted = named is not None and replaced_dir(named).is_dir()  # an --overwrite of it was killed
        if interrupted and getattr(args, "dry_run", False):  # a dry run only reads: the next real command mends it
            print(f"note: {replaced_dir(named)} holds the earlier run of an --overwrite that was stopped; the next "
                  "command that is not a dry run puts it in order", file=sys.stderr)
        elif interrupted:  # finish its work
            if give_back_replaced(named) and self.resuming:
                raise UsageError(f"{named}: the --overwrite that was replacing this run stopped before its first "
                                 f"checkpoint, so nothing of it can be resumed; the earlier run is back in {named} "
                                 "(--overwrite starts the new run again, --resume continues the earlier one)")
        if self.resuming:
            check_resume_dir(args.resume)
        if self.resuming and given - RESUME_FLAGS:
            raise UsageError(f"--resume continues {args.resume} with its saved settings, so "
                             f"{_flags(parser, given - RESUME_FLAGS)} cannot change (only --updates, to extend it); "
                             f"to change settings start a new run with --config {args.resume}")
        if args.config is not None:
            if not args.config.exists():
                raise UsageError(f"{args.config}: no such file or directory")
            if args.config.is_dir() and not (args.config / "config.json").is_file():
                raise UsageError(f"{args.config or '.'}: a directory without a config.json (give a run directory "
                                 "or its config.json)")
            unknown = given - REPLAY_FLAGS - hparam_dests
            if unknown:
                raise UsageError(f"--config keeps the saved run's variants, so {_flags(parser, unknown)} cannot be "
                                 "given with it")
            typed = {k: v for k, v in hparams(args).items() if v is not None} if hparams else {}
            path = args.config / "config.json" if args.config.is_dir() else args.config
            saved = saved_studies(path.parent, path)
            for study in saved if isinstance(saved, list) else [saved]:  # an edited `resolved` is not read: refuse
                own = path.parent / study.name / "config.json" if isinstance(saved, list) else path
                if own.is_file() and (edited := edited_resolved(study, own)):
                    raise UsageError(f"{edited}; the `resolved` section is a record, not read: change a value with "
                                     f"its flag (--config {path} --FLAG VALUE)")
                if own.is_file() and (sha := recorded_data(own)):
                    self.saved_data[study.name] = sha
                saved_parallel = recorded_parallel(own, self.parser.prog, self.parser.get_default("parallel"))
                if "parallel" not in given and saved_parallel is not None:  # as it ran: the same rounding
                    args.parallel = saved_parallel
            self.built = replay(saved, args, given, typed)
        elif not self.resuming:
            # validates every hyper-parameter and budget; `typed`: the flags typed, a default value typed included
            self.built = build(argparse.Namespace(**vars(args), typed=frozenset(given)))
        elif getattr(args, "dry_run", False):  # what a resume would continue (the run directory is only read)
            self.built = saved_studies(args.resume)
            if "updates" in given:
                self.built = extend(self.built, args.updates)

    # 2. start the processes
    def start_processes(self) -> None:
        use_cpu_cores()
        self.writer = start_processes(self.args)
        if self.args.processes <= 1:  # a --processes run starts its backend once the others are started
            check_backend()

    # 3. claim the output (and, for --resume, read back what it holds)
    def claim_output(self) -> None:
        args = self.args
        if self.writer:
            self.out, self.replace = output_dir(args, self.parser.prog.split(".")[-1])
            check_writable_dir(self.out)  # before any data is loaded or generated
            self.lock = lock_run_dir(self.out)  # held until the end: one writer per run directory
        else:  # another process of this run writes (and checks) the directory
            self.out = args.resume or args.out
        if self.resuming:
            self.built = saved_studies(self.out)
            if "updates" in self.given:
                self.built = extend(self.built, args.updates)
        self.local = start_local_processes(args, self.argv, self.parser.prog, self.out)

    # 4. load the data
    def load(self) -> list:
        loaded: dict = {}  # each dataset once
        for study in self.studies:
            if _data_key(study) not in loaded:
                loaded[_data_key(study)] = load_data(study, self.args.clip_actions)
        data = [loaded[_data_key(s)] for s in self.studies]
        for study, ds in zip(self.studies, data):
            if study.batch_size > len(ds):
                raise UsageError(f"--batch-size {study.batch_size} is larger than the dataset ({len(ds):,} "
                                 f"transitions of {study.dataset})")
            # the rows the variants' updates may draw (`offrl_jax.data.device.for_updates`)
            if problem := too_few_rows(ds, [study.config(v.label).needs() for v in study.variants],
                                       study.batch_size):
                raise UsageError(f"{study.dataset}: {problem}")
        return data

    # 5. check a resume (every study's checkpoints must be its own) or a replay, before anything is written
    def check_resume(self, data: list, shas: list[str]) -> None:
        self.check_replay(shas)
        if not self.resuming:
            return
        for study in self.studies:  # variants one after another or side by side round differently: not mixed
            groups = len(study.groups())
            saved = recorded_parallel(self.study_dir(study) / "config.json", self.parser.prog,
                                      self.parser.get_default("parallel"))
            if saved is not None and min(saved, groups) != min(self.args.parallel, groups):
                raise UsageError(f"--resume continues {self.out} with its saved settings: it ran with --parallel "
                                 f"{saved}, and --parallel {self.args.parallel} would train the rest differently "
                                 f"(rounding); resume with --parallel {saved}")
        for study, ds, sha in zip(self.studies, data, shas):
            if self.study_dir(study).is_dir():  # a study of a multi-study run not begun yet has none
                check_resume(study, self.study_dir(study), ds, sha)
        if "updates" in self.given and isinstance(self.built, list) and self.writer:
            atomic_write_text(self.out / "config.json", studies_json(self.built))

    def check_replay(self, shas: list[str]) -> None:
        """--config re-runs a run exactly: on the data it trained on, unless a flag given with it changes the data."""
        if self.args.config is None or self.given & DATA_FLAGS:
            return
        for study, sha in zip(self.studies, shas):
            if self.saved_data.get(study.name, sha) != sha:
                raise UsageError(f"{study.dataset}: not the data the saved run trained on (SHA-256 {sha[:12]}..., "
                                 f"recorded {self.saved_data[study.name][:12]}...: a dataset generated again, on "
                                 "another machine or by another version of the code, is not bit-identical); "
                                 "--config re-runs a run exactly: to train on the data as it is now, say so with "
                                 f"--dataset-path {study.dataset}")

    # 6. run
    def run(self, data: list, shas: list[str]) -> None:
        if self.replace:  # moved aside, not deleted: a new run that fails before its first checkpoint gives it back
            aside = replaced_dir(self.out)
            if aside.exists():  # `read` gave back or removed what a killed --overwrite left there
                raise UsageError(f"{aside} exists: it may hold an earlier run; move it away first")
            self.replaced = aside
            self.out.rename(self.replaced)
        if isinstance(self.built, list) and not self.resuming and self.writer:
            self.out.mkdir(parents=True, exist_ok=True)  # the whole studies, so --resume can start those not begun
            atomic_write_text(self.out / "config.json", studies_json(self.built))
        args = self.args
        for study, ds, sha in zip(self.studies, data, shas):
            where = self.study_dir(study)
            if self.writer:
                print(f"{study.name}: {len(ds):,} transitions of {study.dataset}; writing to {where}", file=sys.stderr)
            summary = run_study(study, where, ds, resume=self.resuming, progress=not args.no_progress,
                                parallel=args.parallel, logger=args.logger, data_sha256=sha, verify=False)
            if self.writer:
                print_table(summary)
                online = ", online.png, online/*.hdf5" if study.online is not None else ""
                print(f"results: {where}/summary.json, curves.csv, curves.png{online}", file=sys.stderr)

    # 7. clean up
    def clean_up(self, ok: bool) -> str | None:
        """Everything the command holds given back; returns the failure of another process, if one failed."""
        failed = self.local.close(ok) if self.local is not None else None
        out, args = self.out, self.args
        if self.replaced is not None and self.replaced.exists():
            if ok or has_checkpoint(out):
                shutil.rmtree(self.replaced, ignore_errors=True)
            else:
                shutil.rmtree(out, ignore_errors=True)
                self.replaced.rename(out)
                self.given_back = True
                if not self.interrupted:  # the interruption's own line says it
                    print(f"the earlier run in {out} is kept: the new one ended before its first checkpoint",
                          file=sys.stderr)
        claimed = out is not None and args.resume is None and args.out is None  # runs/<study>/<timestamp>
        if claimed and out.is_dir() and not any(out.iterdir()):  # it got nothing (the data failed to load)
            out.rmdir()
        if self.lock is not None:
            Path(self.lock.name).unlink(missing_ok=True)
            self.lock.close()
            for made in reversed(self.lock.created_dirs):  # parents of --out that the lock made, if nothing went there
                try:
                    made.rmdir()
                except OSError:
                    break
        if claimed:
            for empty in (out.parent, out.parent.parent):  # runs/<study>/ and runs/, if empty now
                try:
                    empty.rmdir()
                except OSError:
                    break
        return failed


def interrupted_line(command: Command) -> str:
    """What an interrupted command says: how to resume the run it leaves, or that the earlier run is back."""
    out = command.out
    if command.given_back:
        return (f"interrupted before the new run's first checkpoint; the earlier run in {out} is kept (the new one "
                "left nothing to resume)")
    display = " --no-progress" if getattr(command.args, "no_progress", False) else ""
    if (parallel := getattr(command.args, "parallel", None)) != command.parser.get_default("parallel"):
        display += f" --parallel {parallel}"  # a resume keeps it (`Command.check_resume`)
    where = (f"; resume with --resume {shlex.quote(str(out))}{display}"
             if out is not None and (out / "config.json").is_file() else "")
    return f"interrupted{where}"


def run_command(build: Build, parser: argparse.ArgumentParser, argv=None,
                hparams: Callable[[argparse.Namespace], dict] | None = None,
                hparam_dests: frozenset[str] = frozenset()) -> int:
    """Parse, build the study (or studies: each in its own sub-directory), run; expected failures are one line.

    For --config: `hparam_dests` are the flags that set single hyper-parameters, and `hparams(args)` the overrides
    they make ({config field: value}, None for a flag not given)."""
    state_defaults(parser, build, argv)  # --help: the --algo's hyper-parameters, each with what the study gives it
    command = Command(parser.parse_args(argv), parser, argv)
    one_line_warnings()
    ok, code = False, 1
    try:
        command.read(build, hparams, hparam_dests)
        if getattr(command.args, "dry_run", False):
            for study in command.studies:  # the data it names is there (a run would refuse it at once)
                catalogue.check_there(study.dataset)
            print(describe(command.studies))
            ok = True
            return 0
        command.start_processes()
        command.claim_output()
        data = command.load()
        shas = [fingerprint(ds) for ds in data]
        command.check_resume(data, shas)
        command.run(data, shas)
        ok = True
    except (UsageError, DatasetError, ValueError, OSError, Diverged) as e:
        if os.environ.get("OFFRL_JAX_DEBUG") == "1":  # the traceback, for whoever is debugging the code
            raise
        print_error(e)
        code = 3 if isinstance(e, Diverged) else 2
        return code
    except KeyboardInterrupt:
        command.interrupted, code = True, 130
        return code
    finally:
        with shielded():  # the results are written, or the run is ending: its clean-up is not cut half-way
            failed = command.clean_up(ok)
        if command.interrupted:  # said once the clean-up has made it true
            print(interrupted_line(command), file=sys.stderr)
        if command.local is not None and not ok:  # leave now: JAX's exit handler would wait for the processes
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(exit_code(code))  # 143 for a SIGTERM's interruption
    if failed is not None:
        print_error(failed)
        return 2
    return 0
