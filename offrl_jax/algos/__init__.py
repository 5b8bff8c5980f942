"""The algorithm registry: the families, and `resolve`, which gives an algorithm's config on an env.

A family is one file of this package: its config dataclass (extending `offrl_jax.algos.config.Config`), its
algorithm class, and four names the registry reads:

    FAMILY        `Family(config class, algorithm class)`, registered under the file's name
    ALGOS         {algorithm: `Algo(family, values)`}: the named algorithms made from it
    ENV_DEFAULTS  {(section, env): values}: its per-env values; a section is the family or one of its algorithms, an
                  env a short name ("hopper") or "env:dataset-part" (applies when the dataset's name contains it)
    PRESETS       {preset: {algorithm or family: values}}: its named sets of values (--preset)

A config's dataclass defaults are the values a run gets with no env and no preset.  A new family is its file and
its name in `FAMILY_FILES` (docs/extending.md); `register` adds one from elsewhere (tests/test_new_family.py).
"""
from __future__ import annotations

import dataclasses
import importlib
from collections.abc import Iterable, Mapping
from typing import Any

from offrl_jax.algos.common import Algo, Family, Phase
from offrl_jax.algos.config import Config
from offrl_jax.envs.registry import ENVS

# the families, each a file of this package, in --algo order
FAMILY_FILES = ("td3bc", "sacn", "cql", "rebrac", "iql", "awac")

FAMILIES: dict[str, Family] = {}
ALGOS: dict[str, Algo] = {}
ENV_DEFAULTS: dict[tuple[str, str], dict[str, Any]] = {}
PRESETS: dict[str, dict[str, dict[str, Any]]] = {}


def register(name: str, module: Any) -> None:
    """Add the family that `module` holds (its FAMILY, ALGOS, ENV_DEFAULTS and PRESETS) to the registry under
    `name`, as its name in `FAMILY_FILES` does.  A name or algorithm already registered is refused.

    For a family outside this package (a test's throwaway one): register it before `offrl_jax.app` is imported,
    whose flags are made from the registry then; worker processes (`--parallel` on the CPU) start without it."""
    if name in FAMILIES or (taken := sorted(set(module.ALGOS) & set(ALGOS))):
        raise ValueError(f"cannot register family {name!r}: {name if name in FAMILIES else taken[0]!r} is "
                         "registered already")
    FAMILIES[name] = module.FAMILY
    ALGOS.update(module.ALGOS)
    ENV_DEFAULTS.update(module.ENV_DEFAULTS)
    for preset, values in module.PRESETS.items():
        PRESETS.setdefault(preset, {}).update(values)


for _name in FAMILY_FILES:
    register(_name, importlib.import_module(f"{__name__}.{_name}"))


def family_of(algo: str) -> Family:
    """The family `algo` is made from."""
    if not isinstance(algo, str) or algo not in ALGOS:
        raise ValueError(f"unknown algorithm {algo!r}; valid: {', '.join(ALGOS)}")
    return FAMILIES[ALGOS[algo].family]


def preset_values(preset: str | None, algo: str) -> dict[str, Any]:
    """The config values `preset` sets for `algo` ({} for no preset): its entry for `algo`, else for its family."""
    if preset is None:
        return {}
    if preset not in PRESETS:
        raise ValueError(f"unknown preset '{preset}'; valid: {', '.join(PRESETS)}")
    values = PRESETS[preset]
    return dict(values[algo] if algo in values else values.get(ALGOS[algo].family, {}))


def env_defaults(algo: str, env: str, dataset: str = "") -> dict[str, Any]:
    """The per-env values `ENV_DEFAULTS` gives `algo` on `env` (and `dataset`; {} for no env): for its family's
    section, then its `sections`, then its own, the section's env entry and a matching dataset entry."""
    entry = ALGOS[algo]
    sections = list(dict.fromkeys((entry.family, *entry.sections, algo)))
    d: dict[str, Any] = {}
    if not env:
        return d
    for section in sections:
        keys = [(section, env)] + [k for k in ENV_DEFAULTS if k[0] == section and k[1].startswith(f"{env}:")
                                   and k[1][len(env) + 1:] in dataset]
        for key in keys:
            d |= {k: v for k, v in ENV_DEFAULTS.get(key, {}).items()
                  if section in (entry.family, algo) or k not in entry.skip}
    return d


# Where a resolved value came from, in the order `resolve` applies them (a later one wins):
#   default   the family's config dataclass
#   algo      the values that make the algorithm (`ALGOS`, e.g. the hybrid's CQL weight)
#   per-env   `ENV_DEFAULTS` for the env (and dataset)
#   preset    the preset's values (`PRESETS`: --preset, or the study's default preset)
#   study     a value the study sets for a variant (its pre-training mode, a swept lambda, ...)
#   flag      a value given on the command line
#   variant   a variant's value in a run saved before study and flag values were told apart
SOURCES = ("default", "algo", "per-env", "preset", "study", "flag", "variant")


@dataclasses.dataclass(frozen=True)
class Resolved:
    config: Config
    sources: dict[str, str]  # every field of `config`: where its value came from (one of SOURCES)


def resolve(algo: str, env: str = "", dataset: str = "", preset: str | None = None,
            overrides: Mapping[str, Any] | None = None, flags: Iterable[str] | None = ()) -> Resolved:
    """The config of `algo` and where each of its values came from: the one place a run's values are decided.

    The layers, in order (a later one wins): the family's dataclass defaults < the algorithm's values (`ALGOS`) <
    the per-env values (`ENV_DEFAULTS` for `env` and `dataset`) < `preset`'s values (`PRESETS`) < `overrides`
    (None values ignored), of which those named in `flags` were given on the command line and the rest by the
    study (`flags` None: not recorded, each a "variant" value).  `env` is a short name ("hopper"), or "" for no
    env: then the config is the dataclass defaults plus the algorithm's, preset's and overrides' values."""
    config_cls = family_of(algo).config
    if not isinstance(env, str) or (env and env not in ENVS):
        raise ValueError(f"unknown env {env!r}; valid: {', '.join(ENVS)}")
    fields = {f.name for f in dataclasses.fields(config_cls)}
    given = {k: v for k, v in (overrides or {}).items() if v is not None}
    if unknown := sorted(set(given) - fields):
        raise ValueError(f"'{unknown[0]}' is not a hyper-parameter of {algo}; valid: {', '.join(sorted(fields))}")
    flagged = None if flags is None else set(flags)
    layers = [("algo", dict(ALGOS[algo].values)), ("per-env", env_defaults(algo, env, dataset)),
              ("preset", preset_values(preset, algo)),
              ("study", {k: v for k, v in given.items() if flagged is not None and k not in flagged}),
              ("flag", {k: v for k, v in given.items() if flagged is not None and k in flagged}),
              ("variant", given if flagged is None else {})]
    values: dict[str, Any] = {}
    sources = {name: "default" for name in fields}
    for source, layer in layers:
        values |= layer
        sources |= dict.fromkeys(layer, source)
    return Resolved(config_cls(**values), {f.name: sources[f.name] for f in dataclasses.fields(config_cls)})


def make_config(algo: str, env: str = "", dataset: str = "", preset: str | None = None, **overrides: Any) -> Config:
    """Config for `algo` (`resolve`'s, without the sources)."""
    return resolve(algo, env, dataset, preset, overrides).config


def saved_config(algo: str, values: Mapping[str, Any]) -> Config:
    """The config a run recorded (config.json's `resolved` values for a variant of `algo`), checked as any other; a
    field the family does not have is refused."""
    config_cls = family_of(algo).config
    fields = {f.name for f in dataclasses.fields(config_cls)}
    if unknown := sorted(set(values) - fields):
        raise ValueError(f"'{unknown[0]}' is not a hyper-parameter of {algo}; valid: {', '.join(sorted(fields))}")
    return config_cls(**values)


def make_algorithm(config: Config, obs_dim: int, act_dim: int, num_transitions: int):
    """The algorithm object for a config from `make_config`: its family's class."""
    for family in FAMILIES.values():
        if type(config) is family.config:
            return family.algorithm(config, obs_dim, act_dim, num_transitions)
    raise ValueError(f"{type(config).__name__} is no registered family's config; register it in FAMILIES")


__all__ = ["ALGOS", "Algo", "Config", "ENV_DEFAULTS", "FAMILIES", "FAMILY_FILES", "Family", "PRESETS", "Phase",
           "Resolved", "SOURCES", "env_defaults", "family_of", "make_algorithm", "make_config", "preset_values",
           "register", "resolve", "saved_config"]
