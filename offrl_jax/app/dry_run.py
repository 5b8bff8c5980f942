"""What a study will run, before it runs.

`describe`: what `--dry-run` prints: every study a command would run, its budget, and each variant's phases and
resolved config, every field with its value (as config.json's `resolved` records it) and where it came from (as its
`sources` does: `offrl_jax.algos.SOURCES`).  Nothing is written, loaded or trained: the dataset's env is the study's.

`state_defaults`: the hyper-parameter flags `--help` lists, those of the --algo given (else of the default one),
each with its family's help text and, as "Default:", the value the study's variants get: read from the studies the
command builds with that --algo and no other flag (and with each other `--env`), per env where it differs.
"""
from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable

from offrl_jax.algos import ALGOS
from offrl_jax.app.flags import algo_in, show_family
from offrl_jax.run.study import Study
from offrl_jax.system.cli import UsageError


def describe(studies: list[Study]) -> str:
    lines = ["dry run: nothing is written, loaded or trained"]
    for study in studies:
        seeds = study.seeds
        lines += [f"study {study.name}",
                  f"  dataset: {study.dataset} (env {study.env})"
                  + (f", its first {study.max_transitions:,} transitions" if study.max_transitions else ""),
                  f"  budget: {study.updates:,} updates per variant, {len(seeds)} seed{'s' * (len(seeds) != 1)} "
                  f"({', '.join(map(str, seeds))}), batch {study.batch_size}, evaluation every {study.eval_every:,} "
                  f"updates ({study.eval_episodes} episode{'s' * (study.eval_episodes != 1)} per seed)"
                  + (f", final score over updates {study.final_window[0]:,}-{study.final_window[1]:,}"
                     if study.final_window else "")]
        if study.online is not None:
            o = study.online
            lines.append(f"  online: {o.steps:,} env steps per seed after the offline phases ({o.updates():,} "
                         f"updates), blocks of {o.block:,}, utd {o.utd}, warm-up {o.warmup:,}, buffer "
                         f"{o.capacity or 'every step'}, evaluation every {o.eval_every:,} env steps")
        resolved, sources = study.resolved(), study.sources()
        for v in study.variants:
            config = study.config(v.label)
            phases = ", ".join(f"{s.name} {s.steps:,}" + (f" ({s.updates_per_call} per call)" if s.updates_per_call > 1
                                                          else "") + (" (ends itself, at most)" if s.auto_stop else "")
                               for s in config.phases(config.budget(study.updates)))
            lines += [f"  variant {v.label}: {v.algo}" + (f", preset {v.preset}" if v.preset else ""),
                      f"    phases: {phases}"]
            lines += [f"    {name} = {json.dumps(value, default=list)}  ({sources[v.label][name]})"
                      for name, value in resolved[v.label].items()]
    return "\n".join(lines)


def state_defaults(parser: argparse.ArgumentParser, build: Callable, argv: list[str] | None = None) -> None:
    """Have `parser`'s help list the hyper-parameters of the algorithm --algo names in `argv` (else the default
    one's; a study without --algo: every family's) and state, for each, the value the study gives it by default (its
    default env first, the other envs where they differ); worked out when the help is shown."""
    format_help = parser.format_help

    def stated() -> str:
        one = any(a.dest == "algo" and a.option_strings for a in parser._actions)  # the study trains one --algo
        algo = algo_in(sys.argv[1:] if argv is None else list(argv)) if one else None
        shown = algo or (parser.get_default("algo") if one else None)
        family = ALGOS[shown].family if shown in ALGOS else None
        show_family(parser, family)
        try:
            defaults = field_defaults(parser, build, ["--algo", algo] if algo in ALGOS else [])
        except (UsageError, ValueError):  # it needs other flags too (bc: --pretrain actor): its config's own
            defaults = {}
        for group in parser._action_groups:
            if group.title == "hyper-parameters" and family is not None:
                group.description = (f"the fields of {shown}'s config ({family} family, "
                                     f"offrl_jax/algos/{family}.py); --algo X --help lists X's.  Not given = what the "
                                     "study gives it (each Default below; --dry-run shows every value and where it "
                                     "came from); a field the algorithm does not have is refused")
        for action in parser._actions:
            if action.dest in defaults and action.help and "Default: " in action.help:
                action.help = action.help[:action.help.rindex("Default: ")] + "Default: " + defaults[action.dest]
        return format_help()

    parser.format_help = stated


def _studies(parser: argparse.ArgumentParser, build: Callable, argv: list[str]) -> list[Study]:
    args = parser.parse_args(argv)
    built = build(argparse.Namespace(**vars(args), typed=frozenset()))
    return built if isinstance(built, list) else [built]


def field_defaults(parser: argparse.ArgumentParser, build: Callable, argv: list[str] = ()) -> dict[str, str]:
    """{field: its default as --help states it}: over the studies built with `argv` (an --algo) and no other flag,
    and with each other --env; without `argv`, a field their algorithms do not have, over those built with each
    other --algo ("with --algo edac: ...")."""
    options = {a.dest: a.choices or () for a in parser._actions if a.dest in ("env", "algo", "algos")
               and a.option_strings}
    algo_flag = "--algos" if "algos" in options else "--algo"

    def found(argv: list[str]) -> dict[str, dict[str, dict[tuple[str, str], tuple]]]:
        """{field: {env: {(algo, label): (value, source, preset)}}} of the studies built with `argv`, and with each
        other --env"""
        studies = _studies(parser, build, argv)
        for env in options.get("env", ()):
            if env not in {s.env for s in studies}:
                try:
                    studies += _studies(parser, build, [*argv, "--env", env])
                except (UsageError, ValueError):  # a study that does not run on that env states nothing for it
                    pass
        values: dict = {}
        for study in studies:
            resolved, sources = study.resolved(), study.sources()
            for v in study.variants:
                for name, value in resolved[v.label].items():
                    values.setdefault(name, {}).setdefault(study.env, {})[(v.algo, v.label)] = (
                        value, sources[v.label][name], v.preset)
        return values

    stated = {name: _stated(per_env) for name, per_env in found(list(argv)).items()}
    if argv:
        return stated
    default_algos = parser.get_default(algo_flag[2:])
    others: dict[str, dict[str, str]] = {}  # {field: {algo: stated}} for the fields the default algorithms lack
    for algo in options.get("algo", options.get("algos", ())):
        if algo not in (default_algos if isinstance(default_algos, list) else [default_algos]):
            try:
                for name, per_env in found([algo_flag, algo]).items():
                    if name not in stated:
                        others.setdefault(name, {})[algo] = _stated(per_env)
            except (UsageError, ValueError):
                pass
    for name, per_algo in others.items():
        texts = {text: [a for a, t in per_algo.items() if t == text] for text in per_algo.values()}
        stated[name] = "; ".join(f"with --algo {' or '.join(algos)}: {text}" for text, algos in texts.items())
    return stated


def _stated(per_env: dict[str, dict[tuple[str, str], tuple]]) -> str:
    """One field's default: "V", or per variant group "V for td3bc, W for edac"; the first env's, then the others'
    where they differ ("10.0 on hopper (halfcheetah 20.0, walker2d 5.0)"); a preset's value says so."""
    def one(entries: dict[tuple[str, str], tuple]) -> str:
        values = {repr(value) for value, _, _ in entries.values()}
        if len(values) == 1:
            return values.pop()
        by_algo: dict[str, set[str]] = {}
        for (algo, _), (value, _, _) in entries.items():
            by_algo.setdefault(algo, set()).add(repr(value))
        return ", ".join(
            f"{next(iter(values))} for {algo}" if len(values) == 1 else
            ", ".join(f"{repr(value)} for {algo} {label}" for (a, label), (value, _, _) in entries.items() if a == algo)
            for algo, values in by_algo.items())

    envs = list(per_env)
    texts = {env: one(entries) for env, entries in per_env.items()}
    presets = sorted({preset for entries in per_env.values() for _, source, preset in entries.values()
                      if source == "preset"})
    note = f" (preset {', '.join(presets)})" if presets else ""
    if len(set(texts.values())) == 1:
        return texts[envs[0]] + note
    return f"{texts[envs[0]]} on {envs[0]} ({', '.join(f'{env} {texts[env]}' for env in envs[1:])})" + note
