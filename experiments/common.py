"""What every experiment CLI shares: the output-directory rules, saved studies, one-line errors (the run flags
are in experiments/flags.py: `run_args`).

Expected failures (bad flags, bad data, an unwritable place, divergence) print one line; `OFFRL_JAX_DEBUG=1` in the
environment re-raises them with the traceback instead.

Rules: a new run writes to a new timestamped directory under runs/<study>/ unless --out is given; an existing,
non-empty --out is refused unless --overwrite, and --overwrite replaces only a directory whose config.json is a
saved study, after the new run's data has loaded; --resume DIR continues the study (or studies) saved in DIR
from the last complete checkpoints.  Bad input -> `error: ...` on stderr, exit 2, no traceback.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import shutil
import sys
import time
from collections.abc import Callable
from pathlib import Path

from experiments.launch import check_backend, start_local_processes, start_processes, use_cpu_cores
from offrl_jax import datasets
from offrl_jax.checkpoint import atomic_write_text
from offrl_jax.cli import (  # noqa: F401  (OneLineParser, positive_int, UsageError: re-exported, the studies import them here)
    OneLineParser,
    UsageError,
    check_writable_dir,
    lock_run_dir,
    one_line_warnings,
    positive_int,
    print_error,
)
from offrl_jax.data.dataset import DatasetError
from offrl_jax.provenance import fingerprint
from offrl_jax.resume import check_resume
from offrl_jax.runner import Diverged, run_study
from offrl_jax.study import Study, Variant, check_file_name
from offrl_jax.summary import print_table


def output_dir(args, study_name: str) -> tuple[Path, bool]:
    """(directory, whether an earlier run in it is to be replaced); nothing is deleted here.  The default
    runs/<study>/<timestamp>[-n] is claimed at once (created empty), so runs started in the same second differ."""
    if args.resume is not None:
        if not (args.resume / "config.json").is_file():
            raise UsageError(f"{args.resume}: nothing to resume (no config.json)")
        return args.resume, False
    if args.out is None:
        stamp = Path("runs") / study_name / time.strftime("%Y%m%d-%H%M%S")
        stamp.parent.mkdir(parents=True, exist_ok=True)
        for n in range(1, 1000):
            out = stamp if n == 1 else stamp.with_name(f"{stamp.name}-{n}")
            try:
                out.mkdir()
                return out, False
            except FileExistsError:
                continue
        raise UsageError(f"{stamp}: too many runs started in one second")
    if args.out.exists() and not args.out.is_dir():
        raise UsageError(f"{args.out} is a file, not a directory")
    if args.out.exists() and any(args.out.iterdir()):
        if not args.overwrite:
            raise UsageError(f"{args.out} exists and is not empty; pass --overwrite or choose another --out")
        try:
            saved = saved_studies(args.out)
        except (UsageError, OSError):
            raise UsageError(f"{args.out} holds no earlier run (no saved study in config.json); --overwrite will not "
                             "delete it") from None
        foreign = not_from_a_run(args.out, saved)
        if foreign:
            raise UsageError(f"{args.out} holds {', '.join(foreign[:5])}{', ...' if len(foreign) > 5 else ''}, which "
                             "a run does not write; --overwrite replaces only a run: move them or choose another --out")
        return args.out, True
    return args.out, False


# what a run writes in its directory (offrl_jax/runner.py, offrl_jax/loggers.py, offrl_jax/checkpoint.py)
RUN_FILES = frozenset({"config.json", "curves.csv", "curves.png", "summary.json", "wandb-run-id"})
RUN_FOLDERS = {"checkpoints": lambda name: name.endswith(".msgpack"),  # <variant>[.best|.<update>].msgpack
               "tensorboard": lambda name: name.startswith("events.out.tfevents."),
               "wandb": None}  # wandb's own folder (`--logger wandb`), whatever it holds


def _temporary(name: str) -> bool:
    """A temporary file of an atomic write a killed run left (`.<name>.<random>.tmp`)."""
    return name.startswith(".") and name.endswith(".tmp")


def not_from_a_run(out: Path, saved: Study | list[Study]) -> list[str]:
    """The entries of run directory `out` that no run writes, as paths relative to `out`: what --overwrite must not
    delete.  A run's folders may hold only what the run puts there; a study's sub-directory of a multi-study run is
    a run directory itself."""
    studies = {s.name for s in saved} if isinstance(saved, list) else set()

    def foreign(folder: Path, prefix: str, nested: bool) -> list[str]:
        found = []
        for entry in sorted(folder.iterdir()):
            where = f"{prefix}{entry.name}"
            if nested and entry.name in studies and entry.is_dir() and not entry.is_symlink():
                found += foreign(entry, f"{where}/", False)
            elif entry.name in RUN_FOLDERS and entry.is_dir() and not entry.is_symlink():
                if entry.name != "wandb":  # wandb's own folder, whatever it holds
                    found += [f"{where}/{e.name}" for e in sorted(entry.iterdir())
                              if not (e.is_file() and (RUN_FOLDERS[entry.name](e.name) or _temporary(e.name)))]
            elif not ((entry.name in RUN_FILES or _temporary(entry.name)) and entry.is_file()):
                found.append(where)
        return found

    return foreign(out, "", True)


def refuse_existing(parser: argparse.ArgumentParser, out: Path | None, overwrite: bool, names: tuple[str, ...]) -> None:
    """For commands that write a few named files (`names`) into --out: an --out that is a file, a directory holding
    anything else (--overwrite replaces only those files), or a non-empty one without --overwrite is a usage error
    (one line, exit 2), before any work is done."""
    if out is None or not out.exists():
        return
    if not out.is_dir():
        parser.error(f"{out} is a file, not a directory")
    entries = sorted(out.iterdir())
    others = [p.name for p in entries if p.name not in names or not p.is_file()]
    if others:
        listed = ", ".join(others[:3]) + (f" and {len(others) - 3} more" if len(others) > 3 else "")
        parser.error(f"{out} holds {listed}, which this command does not write; --overwrite replaces only "
                     f"{', '.join(names)}: choose another --out")
    if entries and not overwrite:
        parser.error(f"{out} exists and is not empty; pass --overwrite or choose another --out")


def study_fields(args) -> dict:
    """Study fields from the run flags (a study without --updates / --eval-every sets those itself)."""
    fields = dict(seeds=tuple(range(args.seed_offset, args.seed_offset + args.seeds)),
                  eval_episodes=args.eval_episodes, batch_size=args.batch_size,
                  checkpoint_every=args.checkpoint_every, keep_checkpoints=args.keep_checkpoints,
                  max_transitions=args.max_transitions,
                  clip_actions=args.clip_actions)
    return fields | {k: getattr(args, k) for k in ("updates", "eval_every") if hasattr(args, k)}


def studies_json(studies: list[Study]) -> str:
    """The top-level config.json of a multi-study run: every study whole, so --resume can start those not begun."""
    return json.dumps({"studies": [json.loads(s.to_json()) for s in studies]}, indent=2) + "\n"


def saved_studies(out: Path, path: Path | None = None) -> Study | list[Study]:
    """The study (or studies) a run directory was started with, from its config.json (or `path`)."""
    path = path or out / "config.json"
    try:
        raw = json.loads(path.read_text())
        if "studies" not in raw:
            return Study.from_json(path.read_text())
        if all(isinstance(s, dict) for s in raw["studies"]):
            return [Study.from_json(json.dumps(s)) for s in raw["studies"]]
        # runs started before the top-level file held whole studies: only the studies begun have their config
        for name in raw["studies"]:
            check_file_name(f"{path}: a study's name", name)
        begun = [name for name in raw["studies"] if (out / name / "config.json").is_file()]
        if not begun:
            raise UsageError(f"{path}: none of its studies had begun; start the run again instead of resuming it")
        if len(begun) < len(raw["studies"]):
            lost = ", ".join(n for n in raw["studies"] if n not in begun)
            print(f"warning: {path} predates saving whole studies; not begun, so not resumed (run them again): "
                  f"{lost}", file=sys.stderr)
        return [Study.from_json((out / name / "config.json").read_text()) for name in begun]
    except UsageError:
        raise
    except (KeyError, TypeError, AttributeError, ValueError) as e:  # bad JSON, or values a Study refuses
        kind = "" if type(e) is ValueError else f"{type(e).__name__}: "
        raise UsageError(f"{path}: not a saved study ({kind}{e})") from None


def load_data(study: Study, clip_actions: bool = False):
    """The study's dataset (`clip_actions`: also clip, for a resumed run saved before studies recorded it)."""
    source = study.dataset
    clip = study.clip_actions or clip_actions or None
    ds = datasets.load(source, max_transitions=study.max_transitions, clip_actions=clip, env=study.env)
    if ds.env is not None and ds.env != study.env:
        raise UsageError(f"{source}: dataset is for env '{ds.env}', not '{study.env}'")
    return ds


def _data_key(study: Study) -> tuple:
    return study.dataset, study.env, study.max_transitions, study.clip_actions


_UNSET = object()
PROCESS_FLAGS = frozenset({"processes", "distributed", "coordinator", "num_processes", "process_id"})
RESUME_FLAGS = frozenset({"resume", "updates", "parallel", "no_progress", "clip_actions", "logger", *PROCESS_FLAGS})
# run flag destination -> the Study field it sets (seeds and --dataset-path are mapped in `replay`)
RUN_FIELDS = ("updates", "eval_every", "eval_episodes", "batch_size", "checkpoint_every", "keep_checkpoints",
              "max_transitions", "clip_actions")
REPLAY_FLAGS = frozenset({"config", "out", "overwrite", "parallel", "no_progress", "logger", "seeds", "seed_offset",
                          "dataset_path", *RUN_FIELDS, *PROCESS_FLAGS})


def given_dests(parser: argparse.ArgumentParser, argv=None) -> set[str]:
    """The destinations of the flags typed on the command line (typed with their default value too)."""
    probe = argparse.Namespace(**{a.dest: _UNSET for a in parser._actions if a.dest != argparse.SUPPRESS})
    parser.parse_args(sys.argv[1:] if argv is None else argv, probe)
    return {dest for dest, value in vars(probe).items() if value is not _UNSET}


def _flags(parser: argparse.ArgumentParser, dests) -> str:
    names = {a.dest: a.option_strings[0] for a in parser._actions if a.option_strings}
    return ", ".join(names.get(d, d) for d in sorted(dests))


def extend(saved: Study | list[Study], updates: int) -> Study | list[Study]:
    """The saved study (or studies) with a larger budget: --resume --updates N continues a run past its end."""
    studies = saved if isinstance(saved, list) else [saved]
    if any(updates < s.updates for s in studies):
        raise UsageError(f"--updates {updates:,} is less than the saved run's {max(s.updates for s in studies):,}; "
                         "a resumed run can be extended, not shortened")
    longer = [dataclasses.replace(s, updates=updates) for s in studies]
    return longer if isinstance(saved, list) else longer[0]


def replay(saved: Study | list[Study], args, given: set[str], hparams: dict) -> Study | list[Study]:
    """The saved study (or studies) with the run flags in `given` and the hyper-parameters `hparams` replaced."""
    swept = sorted(k for k, v in hparams.items() if isinstance(v, list))  # `config_values`: a sweep is a list
    if swept:
        raise UsageError(f"--config takes one value per hyper-parameter (got several for {', '.join(swept)}); "
                         "start a new run to sweep")
    fields = {f: getattr(args, f) for f in RUN_FIELDS if f in given}
    if given & {"seeds", "seed_offset"}:
        fields["seeds"] = tuple(range(args.seed_offset, args.seed_offset + args.seeds))
    if "dataset_path" in given:
        fields["dataset"] = str(args.dataset_path)

    def one(study: Study) -> Study:
        variants = tuple(Variant.of(v.label, v.algo, **(dict(v.overrides) | hparams)) for v in study.variants)
        return dataclasses.replace(study, variants=variants, **fields)

    return [one(s) for s in saved] if isinstance(saved, list) else one(saved)


def main_guard(build: Callable[[argparse.Namespace], Study | list[Study]], parser: argparse.ArgumentParser,
               argv=None, hparams: Callable[[argparse.Namespace], dict] | None = None,
               hparam_dests: frozenset[str] = frozenset()) -> int:
    """Parse, build the study (or studies: each in its own sub-directory), run; expected failures are one line.

    For --config: `hparam_dests` are the flags that set single hyper-parameters, and `hparams(args)` the overrides
    they make ({config field: value}, None for a flag not given)."""
    args = parser.parse_args(argv)
    one_line_warnings()
    out, replace, lock, local, ok, code = None, False, None, None, False, 1
    replaced = None  # where --overwrite keeps the earlier run until the new one has its first checkpoint
    try:
        given = given_dests(parser, argv)
        if args.logger is not None:  # its writer must be there before anything is written
            import importlib.util

            module = {"tensorboard": "tensorboardX", "wandb": "wandb"}[args.logger]
            if importlib.util.find_spec(module) is None:
                raise UsageError(f"--logger {args.logger} needs {module}: pip install -e \".[{args.logger}]\"")
        if args.resume is not None and args.config is not None:
            raise UsageError("--resume and --config exclude each other: --resume continues a run in place, "
                             "--config starts a new one from its settings")
        if args.resume is not None and not (args.resume / "config.json").is_file():
            raise UsageError(f"{args.resume}: nothing to resume (no config.json)")
        if args.resume is not None and given - RESUME_FLAGS:
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
            built = replay(saved_studies(path.parent, path), args, given, typed)
        elif args.resume is None:
            built = build(args)  # validates every hyper-parameter and budget
        use_cpu_cores()
        writer = start_processes(args)
        if args.processes <= 1:  # a --processes run starts its backend once the others are started
            check_backend()
        if writer:
            out, replace = output_dir(args, parser.prog.split(".")[-1])
            check_writable_dir(out)  # before any data is loaded or generated
            lock = lock_run_dir(out)  # held until the end: one writer per run directory
        else:  # another process of this run writes (and checks) the directory
            out = args.resume or args.out
        if args.resume is not None:
            built = saved_studies(out)
            if "updates" in given:
                built = extend(built, args.updates)
        studies = built if isinstance(built, list) else [built]
        local = start_local_processes(args, argv, parser.prog, out)
        loaded: dict = {}  # bad data fails here, before anything is written; each dataset is loaded once
        for study in studies:
            if _data_key(study) not in loaded:
                loaded[_data_key(study)] = load_data(study, args.clip_actions)
        data = [loaded[_data_key(s)] for s in studies]
        for study, ds in zip(studies, data):
            if study.batch_size > len(ds):
                raise UsageError(f"--batch-size {study.batch_size} is larger than the dataset ({len(ds):,} "
                                 f"transitions of {study.dataset})")
        shas = [fingerprint(ds) for ds in data]
        if args.resume is not None:  # every study's checkpoints must be its own, before anything is written
            for study, ds, sha in zip(studies, data, shas):
                study_out = out / study.name if isinstance(built, list) else out
                if study_out.is_dir():  # a study of a multi-study run not begun yet has none
                    check_resume(study, study_out, ds, sha)
            if "updates" in given and isinstance(built, list) and writer:
                atomic_write_text(out / "config.json", studies_json(built))
        if replace:  # moved aside, not deleted: a new run that fails before its first checkpoint gives it back
            replaced = out.with_name(f".{out.name}.replaced")
            shutil.rmtree(replaced, ignore_errors=True)
            out.rename(replaced)
        if isinstance(built, list) and args.resume is None and writer:
            out.mkdir(parents=True, exist_ok=True)  # the whole studies, so --resume can start those not begun yet
            atomic_write_text(out / "config.json", studies_json(built))
        for study, ds, sha in zip(studies, data, shas):
            study_out = out / study.name if isinstance(built, list) else out
            if writer:
                print(f"{study.name}: {len(ds):,} transitions of {study.dataset}; writing to {study_out}",
                      file=sys.stderr)
            summary = run_study(study, study_out, ds, resume=args.resume is not None, progress=not args.no_progress,
                                parallel=args.parallel, logger=args.logger, data_sha256=sha, verify=False)
            if writer:
                print_table(summary)
                print(f"results: {study_out}/summary.json, curves.csv, curves.png", file=sys.stderr)
        ok = True
    except (UsageError, DatasetError, ValueError, OSError, Diverged) as e:
        if os.environ.get("OFFRL_JAX_DEBUG") == "1":  # the traceback, for whoever is debugging the code
            raise
        print_error(e)
        code = 3 if isinstance(e, Diverged) else 2
        return code
    except KeyboardInterrupt:
        where = f"; resume with --resume {out}" if out is not None and (out / "config.json").is_file() else ""
        print(f"interrupted{where}", file=sys.stderr)
        code = 130
        return code
    finally:
        failed = local.close(ok) if local is not None else None  # the other processes of a --processes run
        if replaced is not None and replaced.exists():
            if ok or (out.is_dir() and any(out.rglob("*.msgpack"))):
                shutil.rmtree(replaced, ignore_errors=True)
            else:
                shutil.rmtree(out, ignore_errors=True)
                replaced.rename(out)
                print(f"the earlier run in {out} is kept: the new one ended before its first checkpoint",
                      file=sys.stderr)
        # a claimed timestamped directory that got nothing (the data failed to load) is not left behind,
        # nor its runs/<study>/ when that is empty then (a multi-process run always has --out or --resume)
        if out is not None and args.resume is None and args.out is None and out.is_dir() and not any(out.iterdir()):
            out.rmdir()
        if lock is not None:
            Path(lock.name).unlink(missing_ok=True)
            lock.close()
            for made in reversed(lock.created_dirs):  # parents of --out that the lock made, if nothing went there
                try:
                    made.rmdir()
                except OSError:
                    break
        if out is not None and args.out is None and args.resume is None:
            for empty in (out.parent, out.parent.parent):
                try:
                    empty.rmdir()  # only if empty
                except OSError:
                    break
        if local is not None and not ok:  # leave now: JAX's exit handler would wait for the processes just stopped
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(code)
    if failed is not None:
        print_error(failed)
        return 2
    return 0
