"""Command-line flags generated from the algorithm config dataclasses: one flag per config field.

A field declared in `TD3BCConfig` or `EDACConfig` (`offrl_jax/algos/`) becomes `--field-name`, typed from its
annotation, with the comment beside (or above) the field as its help text.  So adding a hyper-parameter is one
line in a config class: it reaches the command line, `config.json` and the losses from there.

    bool                      --name / --no-name
    int, float                a number (floats must be finite); a field in the config's SWEEPABLE takes several
                              values, a sweep trained as one vmapped program
    tuple[int, ...]           one or more widths
    tuple[float, float]       two numbers
    Literal[...]              one of the choices
    str                       a string (the config checks it)

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
from typing import Any

from offrl_jax.algos.edac import EDACConfig
from offrl_jax.algos.td3bc import TD3BCConfig
from offrl_jax.cli import number, positive_int

CONFIGS = (TD3BCConfig, EDACConfig)
# fields a study sets through its own flags or its algorithm choice, never one-by-one
NOT_FLAGS = frozenset({"pretrain", "pretrain_updates", "pretrain_auto", "bc_only"})
# the fields that have a flag (`add_config_flags` leaves out a study's `omit` too)
FLAG_FIELDS = frozenset(f.name for cls in CONFIGS for f in dataclasses.fields(cls)) - NOT_FLAGS
ALIASES = {"actor_layer_norm": ("--actor-ln",), "critic_layer_norm": ("--critic-ln",),
           "layer_norm_affine": ("--ln-affine",)}


def field_comments(cls: type) -> dict[str, str]:
    """{field: its comment}: the `# ...` after the field on its line, after any comment lines just above it."""
    comments: dict[str, str] = {}
    above: list[str] = []
    for line in inspect.getsource(cls).splitlines()[1:]:
        text = line.strip()
        if text.startswith("#"):
            above.append(text.lstrip("# "))
            continue
        match = re.match(r"([a-z_][a-z0-9_]*)\s*:", text)
        if match and not text.startswith(("def ", "class ", "@")):
            trailing = line.split("  # ", 1)[1].strip() if "  # " in line else ""
            comments[match.group(1)] = " ".join(above + ([trailing] if trailing else []))
        above = []
    return comments


def _fields(configs: tuple[type, ...] = CONFIGS) -> dict[str, dict[str, Any]]:
    """Every config field once (the first config's order first): type, per-class defaults, comment, sweepability."""
    found: dict[str, dict[str, Any]] = {}
    for cls in configs:
        hints, comments = typing.get_type_hints(cls), field_comments(cls)
        for f in dataclasses.fields(cls):
            entry = found.setdefault(f.name, {"type": hints[f.name], "defaults": {}, "comment": "",
                                              "sweepable": False})
            entry["defaults"][cls.__name__.removesuffix("Config").lower()] = f.default
            entry["comment"] = entry["comment"] or comments.get(f.name, "")
            entry["sweepable"] |= f.name in cls.SWEEPABLE
    return found


def _argument(annotation: Any, sweepable: bool) -> dict[str, Any]:
    """argparse keywords for a field's annotation."""
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
    kind = {int: int, float: number(), str: str}[annotation]
    return {"type": kind} | ({"nargs": "+"} if sweepable else {})


def add_config_flags(parser: argparse.ArgumentParser, omit: typing.Iterable[str] = (),
                     configs: tuple[type, ...] = CONFIGS) -> tuple[str, ...]:
    """One flag per field of `configs` (but `NOT_FLAGS` and `omit`), in a group of their own; returns their
    destinations, which are the field names."""
    group = parser.add_argument_group(
        "hyper-parameters", "every field of the algorithm's config (offrl_jax/algos/); not given = the per-env "
        "default (offrl_jax.algos.ENV_DEFAULTS) or the config's own; a field the algorithm does not have is refused")
    dests = []
    for name, entry in _fields(configs).items():
        if name in NOT_FLAGS or name in omit:
            continue
        defaults = entry["defaults"]
        shown = (f"{next(iter(defaults.values()))!r}" if len(set(map(repr, defaults.values()))) == 1 else
                 ", ".join(f"{family} {value!r}" for family, value in defaults.items()))
        text = entry["comment"] + (". " if entry["comment"] else "") + f"Default: {shown}"
        if entry["sweepable"]:
            text += "; several values = a sweep, vmapped in one program"
        group.add_argument(f"--{name.replace('_', '-')}", *ALIASES.get(name, ()), dest=name, default=None,
                           help=text.replace("%", "%%"), **_argument(entry["type"], entry["sweepable"]))
        dests.append(name)
    return tuple(dests)


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
