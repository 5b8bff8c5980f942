"""Command-line flags: the run flags every experiment shares (`run_args`), and the flags generated from the
algorithm config dataclasses, one per config field.

A field of a registered family's config (`offrl_jax.algos.FAMILIES`: `TD3BCConfig`, `SACNConfig`, and the
`Config` they extend) becomes `--field-name`, typed from its annotation, with the comment beside (or above) the
field as its help text.  So adding a hyper-parameter is one
line in a config class: it reaches the command line, `config.json` and the losses from there.

    bool                      --name / --no-name
    int, float                a number (floats must be finite); a field in the config's SWEEPABLE takes several
                              values, a sweep trained as one program
    tuple[int, ...]           one or more widths
    tuple[float, float]       two numbers
    Literal[...]              one of the choices
    str                       one of `CHOICES[field]`, the tuple the config's own check uses; a field not there is a
                              string the config checks

Every flag defaults to None, which means "not given": the per-env default or the config's own then applies.
`ALIASES` keeps the short names the studies had before (`--actor-ln`, `--ln-affine`, ...).
"""
from __future__ import annotations

import argparse
import dataclasses
import inspect
import re
import types
import typing
from pathlib import Path
from typing import Any

from offrl_jax.algos import FAMILIES
from offrl_jax.algos.config import REPLAY_MODES, TIMEOUTS
from offrl_jax.algos.sacn import SOFT_ENTROPY_AT
from offrl_jax.losses import BALANCES
from offrl_jax.nets import FANS, INITS, TANH_LOG_DETS
from offrl_jax.run.loggers import LOGGERS
from offrl_jax.run.study import MAX_MEMBERS
from offrl_jax.system.cli import int_at_least, integer, number, positive_int, seed_int

CONFIGS = tuple(family.config for family in FAMILIES.values())
# fields a study sets through its own flags or its algorithm choice, never one-by-one
NOT_FLAGS = frozenset({"pretrain", "pretrain_updates", "pretrain_auto", "bc_only", "offline_updates"})
# the fields that have a flag (`add_config_flags` leaves out a study's `omit` too)
FLAG_FIELDS = frozenset(f.name for cls in CONFIGS for f in dataclasses.fields(cls)) - NOT_FLAGS
# the accepted values of the str fields, the same tuples their configs' __post_init__ checks use
CHOICES = {"init": INITS, "timeouts": TIMEOUTS, "balance": BALANCES, "tanh_log_det": TANH_LOG_DETS,
           "replay": REPLAY_MODES, "soft_entropy_at": SOFT_ENTROPY_AT, "critic_fan": FANS}
ALIASES = {"actor_layer_norm": ("--actor-ln",), "critic_layer_norm": ("--critic-ln",),
           "layer_norm_affine": ("--ln-affine",)}


def field_comments(cls: type) -> dict[str, str]:
    """{field: its comment}: the `# ...` after the field on its line, after any comment lines just above it; a field a
    class re-declares without a comment (a new default) keeps the comment of the class it extends."""
    comments: dict[str, str] = {}
    for klass in reversed([k for k in cls.__mro__ if dataclasses.is_dataclass(k)]):
        above: list[str] = []
        for line in inspect.getsource(klass).splitlines()[1:]:
            text = line.strip()
            if text.startswith("#"):
                above.append(text.lstrip("# "))
                continue
            match = re.match(r"([a-z_][a-z0-9_]*)\s*:", text)
            if match and not text.startswith(("def ", "class ", "@")):
                trailing = line.split("  # ", 1)[1].strip() if "  # " in line else ""
                comment = " ".join(above + ([trailing] if trailing else []))
                if comment or match.group(1) not in comments:
                    comments[match.group(1)] = comment
            above = []
    return comments


def _family_name(cls: type) -> str:
    """The family a config class belongs to, as `--help` names it (a registered family's name, else the class's)."""
    return next((name for name, family in FAMILIES.items() if family.config is cls),
                cls.__name__.removesuffix("Config").lower())


def _fields(configs: tuple[type, ...] = CONFIGS) -> dict[str, dict[str, Any]]:
    """Every config field once (the first config's order first): type, per-class defaults, comment, sweepability.
    All families share one flag per field name, parsed by one type: a family that declares a field of another's
    name with another type is refused (ValueError naming both), as it would be parsed by the other's type."""
    found: dict[str, dict[str, Any]] = {}
    for cls in configs:
        hints, comments = typing.get_type_hints(cls), field_comments(cls)
        for f in dataclasses.fields(cls):
            entry = found.setdefault(f.name, {"type": hints[f.name], "defaults": {}, "comment": "",
                                              "sweepable": False, "declared": cls})
            if hints[f.name] != entry["type"]:
                raise ValueError(f"{cls.__name__}.{f.name} is {hints[f.name]} but {entry['declared'].__name__}."
                                 f"{f.name} is {entry['type']}: one --{f.name.replace('_', '-')} flag cannot parse "
                                 "both; give the field another name")
            entry["defaults"][_family_name(cls)] = f.default
            entry.setdefault("comments", {})[_family_name(cls)] = comments.get(f.name, "")
            entry["comment"] = entry["comment"] or comments.get(f.name, "")
            entry["sweepable"] |= f.name in getattr(cls, "SWEEPABLE", ())
            if f.name in getattr(cls, "SWEEPABLE", ()):
                entry.setdefault("swept_in", set()).add(_family_name(cls))
    return found


def _argument(name: str, annotation: Any, sweepable: bool) -> dict[str, Any]:
    """argparse keywords for a field's annotation (and, for a str field, its `CHOICES`)."""
    if name in CHOICES:
        return {"choices": CHOICES[name]}
    args = typing.get_args(annotation)
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):  # X | None
        annotation = next(a for a in args if a is not type(None))
        args = typing.get_args(annotation)
    origin = typing.get_origin(annotation)
    if annotation is bool:
        return {"action": argparse.BooleanOptionalAction}
    if origin is typing.Literal:
        return {"choices": args}
    if origin is tuple:
        kind = number() if args[0] is float else positive_int
        return {"type": kind, "nargs": "+" if args[-1] is Ellipsis else len(args), "metavar": args[0].__name__.upper()}
    kind = {int: integer, float: number(), str: str}[annotation]
    return {"type": kind} | ({"nargs": "+"} if sweepable else {})


def add_config_flags(parser: argparse.ArgumentParser, omit: typing.Iterable[str] = (),
                     configs: tuple[type, ...] = CONFIGS) -> tuple[str, ...]:
    """One flag per field of `configs` (but `NOT_FLAGS` and `omit`), in a group of their own; returns their
    destinations, which are the field names."""
    group = parser.add_argument_group(
        "hyper-parameters", "every field of the algorithm's config (offrl_jax/algos/); not given = what the study "
        "gives it (each Default below: a preset's, the per-env table's or the config's own; --dry-run shows every "
        "value and where it came from); a field the algorithm does not have is refused")
    dests = []
    for name, entry in _fields(configs).items():
        if name in NOT_FLAGS or name in omit:
            continue
        defaults = entry["defaults"]
        shown = (f"{next(iter(defaults.values()))!r}" if len(set(map(repr, defaults.values()))) == 1 else
                 ", ".join(f"{family} {value!r}" for family, value in defaults.items()))
        def text(comment: str, default: str, sweep: bool = entry["sweepable"]) -> str:
            return ((comment + ". " if comment else "") + ("Several values = a sweep, vmapped in one program. "
                                                           if sweep else "") + f"Default: {default}").replace("%", "%%")

        action = group.add_argument(f"--{name.replace('_', '-')}", *ALIASES.get(name, ()), dest=name, default=None,
                                    help=text(entry["comment"], shown),
                                    **_argument(name, entry["type"], entry["sweepable"]))
        # each family's own help for the field (`show_family`): its comment, its dataclass default
        action.family_help = {family: text(comment or entry["comment"], repr(defaults[family]),
                                           family in entry.get("swept_in", ()))
                              for family, comment in entry["comments"].items()}
        dests.append(name)
    return tuple(dests)


def show_family(parser: argparse.ArgumentParser, family: str | None) -> None:
    """Have `parser`'s hyper-parameter flags in --help be those of `family` (`FAMILIES`) with its help texts and
    defaults, the others hidden (None: every family's, as they were added)."""
    for action in parser._actions:
        if not hasattr(action, "family_help"):
            continue
        if not hasattr(action, "all_help"):
            action.all_help = action.help
        action.help = action.all_help if family is None else action.family_help.get(family, argparse.SUPPRESS)


def algo_in(argv: list[str]) -> str | None:
    """The algorithm the last --algo in `argv` names (None: no --algo)."""
    algo = None
    for word, after in zip(argv, [*argv[1:], ""]):
        if word == "--algo" or word.startswith("--algo="):
            algo = word.split("=", 1)[1] if "=" in word else after
    return algo


def sweepable_fields() -> frozenset[str]:
    return frozenset(name for cls in CONFIGS for name in cls.SWEEPABLE)


def config_values(args: argparse.Namespace, dests: typing.Iterable[str]) -> dict[str, Any]:
    """{field: value} of the config flags given (tuples for multi-valued non-sweep fields; a sweepable field given
    once is that value, given several times a list)."""
    sweep = sweepable_fields()
    values = {}
    for name in dests:
        value = getattr(args, name, None)
        if value is None:
            continue
        if isinstance(value, list):
            value = (value[0] if len(value) == 1 else value) if name in sweep else tuple(value)
        values[name] = value
    return values


def nonempty(text: str) -> str:
    if not text.strip():
        raise argparse.ArgumentTypeError("expected a path or name, got an empty string")
    return text


def host_port(text: str) -> str:
    """HOST:PORT of process 0 of a multi-process run (the port an integer in [1, 65535])."""
    host, _, port = text.rpartition(":")
    if not host or not port.isdigit() or not 1 <= int(port) <= 65535 or any(c.isspace() for c in text):
        raise argparse.ArgumentTypeError(f"expected HOST:PORT with a port in [1, 65535], got {text!r}")
    return text


def plain_path(text: str) -> Path:
    """An output path without control characters (a newline in a directory name would split every log line)."""
    if not text or any(ord(c) < 32 or ord(c) == 127 for c in text):
        raise argparse.ArgumentTypeError(f"expected a path without control characters (newline, tab, ...), got "
                                         f"{text!r}")
    return Path(text)


BATCH_SIZE = 256  # --batch-size's default


def seed_count(text: str) -> int:
    """--seeds: a positive integer up to `MAX_MEMBERS` (a variant's seeds are one program, all in memory at once)."""
    value = positive_int(text)
    if value > MAX_MEMBERS:
        raise argparse.ArgumentTypeError(f"expected a positive integer up to {MAX_MEMBERS:,} (a variant's seeds train "
                                         f"as one program, every seed's networks in memory at once), got {text!r}")
    return value


def run_args(parser: argparse.ArgumentParser, updates: int | None, eval_every: int | None, seeds: int = 3,
             eval_episodes: int = 10) -> None:
    """The run flags; `updates`/`eval_every` None leaves that flag out (a study that sets it itself)."""
    g = parser.add_argument_group("run")
    g.add_argument("--seeds", type=seed_count, default=seeds,
                   help="number of seeds, the member axis of one program (default %(default)s)")
    g.add_argument("--seed-offset", type=seed_int, default=0, help="first seed (seeds are offset..offset+N-1)")
    if updates is not None:
        g.add_argument("--updates", type=positive_int, default=updates,
                       help="total gradient updates per variant, pre-training included (default %(default)s)")
    if eval_every is not None:
        g.add_argument("--eval-every", type=positive_int, default=eval_every,
                       help="updates between evaluations (default %(default)s)")
    g.add_argument("--eval-episodes", type=positive_int, default=eval_episodes,
                   help="episodes per evaluation per seed (default %(default)s)")
    g.add_argument("--batch-size", type=positive_int, default=BATCH_SIZE,
                   help="transitions per gradient update, per seed, drawn uniformly with replacement "
                        "(default %(default)s)")
    g.add_argument("--checkpoint-every", type=int_at_least(0), default=0,
                   help="updates between checkpoints (0: every evaluation)")
    g.add_argument("--keep-checkpoints", type=int_at_least(0, 2**31 - 1), default=0,
                   help="besides the last and the best, keep the N newest periodic checkpoints as "
                        "checkpoints/<variant>.<update>.msgpack (default 0)")
    g.add_argument("--dataset-path", type=nonempty, default=None,
                   help="a D4RL .hdf5, Minari directory or id, or .npz to use instead")
    g.add_argument("--max-transitions", "--transitions", dest="max_transitions", type=positive_int, default=None,
                   help="train on the first N transitions only (a dataset not cached yet is generated at that size "
                        "for this run, and not cached)")
    g.add_argument("--clip-actions", action="store_true", help="clip out-of-bounds dataset actions (with a warning)")
    g.add_argument("--out", type=plain_path, default=None, help="output directory (default: runs/<study>/<timestamp>)")
    g.add_argument("--overwrite", action="store_true",
                   help="replace the earlier run in --out (only a directory whose config.json is a saved study)")
    g.add_argument("--resume", type=Path, default=None,
                   help="continue the run saved in this directory with the settings saved there; --updates N "
                        "larger than the saved budget extends it (not a run with an online phase), --no-progress "
                        "may change, --parallel only to the run's own; any other flag is refused")
    g.add_argument("--config", type=Path, default=None,
                   help="re-run the run saved in this config.json (or run directory) exactly, into a new --out; "
                        "run flags and single-valued hyper-parameter flags given with it change that one value "
                        "(for every variant)")
    g.add_argument("--parallel", type=positive_int, default=2,
                   help="variants trained at once (default %(default)s); on the CPU each in a process pinned to its "
                        "own core(s), on a GPU in threads; 1 = one after another, each splitting its seeds over "
                        "every core")
    g.add_argument("--dry-run", action="store_true",
                   help="print every variant's resolved config (each value, and where it came from: default, algo, "
                        "per-env, preset, study or flag), the budget and the phases, then exit: nothing is written, "
                        "loaded or trained")
    g.add_argument("--no-progress", action="store_true",
                   help="no progress bar: one plain line per evaluation instead (for batch logs)")
    m = parser.add_argument_group("many processes or hosts (jax.distributed; offrl_jax/system/distributed.py)")
    m.add_argument("--processes", type=positive_int, default=1,
                   help="split the seeds of every variant over N processes of this machine, each on its share of "
                        "the cores (one run: process 0 writes it; default 1). One process already splits a "
                        "variant's seeds over its cores, so this is mostly a test of a multi-host launch")
    m.add_argument("--distributed", action="store_true",
                   help="one run over every process JAX finds in the cluster's environment (SLURM, a TPU slice, "
                        "Open MPI); needs --out or --resume")
    m.add_argument("--coordinator", type=host_port, default=None, metavar="HOST:PORT",
                   help="or set the processes by hand: process 0's address, with --num-processes and --process-id")
    m.add_argument("--num-processes", type=positive_int, default=None,
                   help="with --coordinator: how many processes the run has in all, on every host")
    m.add_argument("--process-id", type=int_at_least(0), default=None,
                   help="with --coordinator: this process's index, 0 to --num-processes - 1 (0 writes the run)")
    g.add_argument("--logger", choices=LOGGERS, default=None,
                   help="also send every evaluation's scores and metrics to TensorBoard (RUN/tensorboard/) or "
                        "Weights & Biases; curves.csv stays the record (pip install -e \".[tensorboard]\" or "
                        "\".[wandb]\")")
