"""A run's directory: where a new run writes, what --overwrite may replace, and the study (or studies) a run
directory was started with.

Rules: a new run writes to a new timestamped directory under runs/<study>/ unless --out is given; an existing,
non-empty --out is refused unless --overwrite, and --overwrite replaces only a directory whose config.json is a
saved study and which holds nothing a run does not write; --resume DIR continues the study (or studies) saved in
DIR.  `offrl_jax.app.command` moves an earlier run aside (`replaced_dir`) and gives it back; a command killed
before it could do either leaves it there, and `give_back_replaced` finishes its work for the next command.
"""
from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from pathlib import Path

from offrl_jax.run.study import Study, check_file_name
from offrl_jax.system.cli import UsageError, file_for_run_dir, lock_run_dir


def output_dir(args, study_name: str) -> tuple[Path, bool]:
    """(directory, whether an earlier run in it is to be replaced); nothing is deleted here.  The default
    runs/<study>/<timestamp>[-n] is claimed at once (created empty), so runs started in the same second differ."""
    if args.resume is not None:
        check_resume_dir(args.resume)
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


def replaced_dir(out: Path) -> Path:
    """Where --overwrite keeps the earlier run in `out` until the new run has its first checkpoint."""
    return out.with_name(f".{out.name}.replaced")


def has_checkpoint(out: Path) -> bool:
    """Whether run directory `out` has a checkpoint to resume from (a best one alone is none: `is_resumable`)."""
    from offrl_jax.run.resume import is_resumable  # jax and the families: only when a run directory is looked at

    return out.is_dir() and any(is_resumable(p) for p in out.rglob("*.msgpack"))


def give_back_replaced(out: Path) -> bool:
    """Finish the work of an --overwrite of `out` that was killed (nothing else leaves `replaced_dir(out)` behind):
    the earlier run is given back if the new one had no checkpoint yet (True is returned), and otherwise removed, as
    that command would have done; either is said on stderr.  Nothing happens while another process holds `out`'s
    lock."""
    aside = replaced_dir(out)
    if not aside.is_dir():
        return False
    try:
        lock = lock_run_dir(out)
    except OSError:  # the --overwrite is still running: its own clean-up decides
        return False
    try:
        if not aside.is_dir():
            return False
        if has_checkpoint(out):
            shutil.rmtree(aside)
            print(f"removed {aside}: the run that an interrupted --overwrite of {out} replaced (the new run there "
                  "has its checkpoints)", file=sys.stderr)
            return False
        if out.exists():
            try:
                new = saved_studies(out)
            except (UsageError, OSError):
                new = []
            foreign = not_from_a_run(out, new) if out.is_dir() else [out.name]
            if foreign:
                raise UsageError(f"{aside} holds the run that an interrupted --overwrite of {out} was replacing, but "
                                 f"{out} holds {', '.join(foreign[:3])}, which a run does not write: move them, then "
                                 f"move {aside} back to {out}")
            shutil.rmtree(out)
        aside.rename(out)
        print(f"the earlier run in {out} is given back: an --overwrite of it was stopped before the new run's first "
              "checkpoint", file=sys.stderr)
        return True
    finally:
        Path(lock.name).unlink(missing_ok=True)
        lock.close()


def check_resume_dir(path: Path) -> None:
    """Raise one line unless `path` is a run directory (one with a config.json) that --resume can continue."""
    if refusal := file_for_run_dir(path, "a run directory", "config.json"):
        raise UsageError(refusal)
    if not (path / "config.json").is_file():
        raise UsageError(f"{path}: nothing to resume (no config.json)")


# what a run writes in its directory (offrl_jax/run/runner.py, offrl_jax/run/loggers.py, offrl_jax/system/checkpoint.py)
RUN_FILES = frozenset({"config.json", "curves.csv", "curves.png", "online.png", "summary.json", "wandb-run-id"})
RUN_FOLDERS = {"checkpoints": lambda name: name.endswith(".msgpack"),  # <variant>[.best|.<update>].msgpack
               "online": lambda name: name.endswith(".hdf5"),  # <env>-<variant>-seed<seed>.hdf5 (`online.record`)
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
