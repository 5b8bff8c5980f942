"""What every experiment CLI shares: the run flags, the output-directory rules, one-line errors.

Rules: a new run writes to a new timestamped directory under runs/<study>/ unless --out is given; an existing,
non-empty --out is refused unless --overwrite; --resume DIR continues the study saved in DIR from its last complete
checkpoint.  Bad input -> `error: ...` on stderr, exit 2, no traceback.
"""
from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from collections.abc import Callable
from pathlib import Path

from offrl_jax import datasets
from offrl_jax.data.dataset import DatasetError
from offrl_jax.runner import Diverged, Study, print_table, run_study


class UsageError(ValueError):
    pass


def positive_int(text: str) -> int:
    try:
        value = int(float(text)) if "e" in text.lower() else int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got '{text}'") from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got '{text}'")
    return value


class OneLineParser(argparse.ArgumentParser):
    def error(self, message: str):  # argparse prints usage + error; we print one line
        print(f"error: {message}", file=sys.stderr)
        sys.exit(2)


def run_args(parser: argparse.ArgumentParser, updates: int, eval_every: int, seeds: int = 3) -> None:
    g = parser.add_argument_group("run")
    g.add_argument("--seeds", type=positive_int, default=seeds, help="number of seeds, vmapped (default %(default)s)")
    g.add_argument("--seed-offset", type=int, default=0, help="first seed (seeds are offset..offset+N-1)")
    g.add_argument("--updates", type=positive_int, default=updates,
                   help="total gradient updates per variant, pre-training included (default %(default)s)")
    g.add_argument("--eval-every", type=positive_int, default=eval_every, help="updates between evaluations")
    g.add_argument("--eval-episodes", type=positive_int, default=10, help="episodes per evaluation per seed")
    g.add_argument("--batch-size", type=positive_int, default=256)
    g.add_argument("--checkpoint-every", type=int, default=0, help="updates between checkpoints (0: every evaluation)")
    g.add_argument("--dataset-path", default=None, help="a D4RL .hdf5, Minari directory or id, or .npz to use instead")
    g.add_argument("--transitions", type=positive_int, default=None, help="cap the dataset at N transitions")
    g.add_argument("--clip-actions", action="store_true", help="clip out-of-bounds dataset actions (with a warning)")
    g.add_argument("--out", type=Path, default=None, help="output directory (default: runs/<study>/<timestamp>)")
    g.add_argument("--overwrite", action="store_true", help="allow writing into an existing non-empty --out")
    g.add_argument("--resume", type=Path, default=None, help="continue the run saved in this directory")
    g.add_argument("--parallel", type=positive_int, default=2,
                   help="variants trained at once, in threads (default %(default)s: one XLA program at these sizes "
                        "keeps about one CPU core busy); 1 = one after another")
    g.add_argument("--no-progress", action="store_true", help="no progress bar")


def output_dir(args, study_name: str) -> Path:
    if args.resume is not None:
        if not (args.resume / "config.json").exists():
            raise UsageError(f"{args.resume}: nothing to resume (no config.json)")
        return args.resume
    if args.out is None:
        return Path("runs") / study_name / time.strftime("%Y%m%d-%H%M%S")
    if args.out.exists() and any(args.out.iterdir()):
        if not args.overwrite:
            raise UsageError(f"{args.out} exists and is not empty; pass --overwrite or choose another --out")
        shutil.rmtree(args.out)
    return args.out


def study_fields(args) -> dict:
    return dict(seeds=tuple(range(args.seed_offset, args.seed_offset + args.seeds)), updates=args.updates,
                eval_every=args.eval_every, eval_episodes=args.eval_episodes, batch_size=args.batch_size,
                checkpoint_every=args.checkpoint_every, transitions=args.transitions)


def load_data(study: Study, args):
    source = study.dataset
    ds = datasets.load(source, transitions=study.transitions, clip_actions=args.clip_actions or None, env=study.env)
    if study.transitions and len(ds) > study.transitions:
        ds = ds.select(slice(0, study.transitions))
    if ds.env is not None and ds.env != study.env:
        raise UsageError(f"{source}: dataset is for env '{ds.env}', not '{study.env}'")
    return ds


def main_guard(build: Callable[[argparse.Namespace], Study | list[Study]], parser: argparse.ArgumentParser,
               argv=None) -> int:
    """Parse, build the study (or studies: each in its own sub-directory), run; expected failures are one line."""
    args = parser.parse_args(argv)
    out = None
    try:
        built = None if args.resume is not None else build(args)  # validates every hyper-parameter first
        out = output_dir(args, parser.prog.split(".")[-1])
        if args.resume is not None:
            subs = sorted(out.glob("*/config.json"))
            built = [Study.from_json(p.read_text()) for p in subs] if subs else Study.from_json(
                (out / "config.json").read_text())
        studies = built if isinstance(built, list) else [built]
        if isinstance(built, list) and args.resume is None:
            out.mkdir(parents=True, exist_ok=True)
            (out / "config.json").write_text(json.dumps({"studies": [s.name for s in built]}) + "\n")
        for study in studies:
            study_out = out / study.name if isinstance(built, list) else out
            ds = load_data(study, args)
            print(f"{study.name}: {len(ds):,} transitions of {study.dataset}; writing to {study_out}", file=sys.stderr)
            summary = run_study(study, study_out, ds, resume=args.resume is not None, progress=not args.no_progress,
                                parallel=args.parallel)
            print_table(summary)
            print(f"results: {study_out}/summary.json, curves.csv, curves.png", file=sys.stderr)
    except (UsageError, DatasetError, ValueError, FileNotFoundError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except Diverged as e:
        print(f"error: {e}", file=sys.stderr)
        return 3
    except KeyboardInterrupt:
        print(f"interrupted; resume with --resume {out}", file=sys.stderr)
        return 130
    return 0
