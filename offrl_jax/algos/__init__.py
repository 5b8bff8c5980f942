"""The algorithm registry: families, the algorithms made from them, their per-env defaults and their presets.

A family is a config dataclass (extending `offrl_jax.algos.config.Config`) and the algorithm class built from it,
in a file of its own: `td3bc.py` (a deterministic actor, TD3's critics), `sacn.py` (a tanh-Gaussian actor, N
critics, a learned temperature), `rebrac.py` (TD3 with behaviour penalties in the actor and the critic's
target) and `iql.py` (implicit Q-learning).  An algorithm is a family plus the config values that make it that
algorithm:

    bc          td3bc family, actor pre-training (MSE) for the whole budget
    td3bc       TD3+BC
    td3bc_cql   TD3+BC + balanced uniform-action CQL penalty on the critic (the paper's hybrid)
    edac        sacn family with the ensemble-diversity loss (eta > 0)
    sacn        SAC-N (eta = 0)
    edac_bc     EDAC + balanced MSE BC term on the actor (the paper's hybrid)
    cql         CQL (CORL form) on the sacn family with twin critics
    rebrac      ReBRAC (Tarasov et al. 2023)
    iql         IQL (Kostrikov et al. 2022)

A new family is its file, one `FAMILIES` line and an `ALGOS` line per algorithm (docs/extending.md).
"""
from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Mapping
from typing import Any

from offrl_jax.algos.common import Phase
from offrl_jax.algos.config import Config
from offrl_jax.algos.iql import IQL, IQLConfig
from offrl_jax.algos.rebrac import ReBRAC, ReBRACConfig
from offrl_jax.algos.sacn import SACN, SACNConfig
from offrl_jax.algos.td3bc import TD3BC, TD3BCConfig
from offrl_jax.envs.registry import ENVS


@dataclasses.dataclass(frozen=True)
class Family:
    config: type  # a frozen dataclass extending `Config`
    algorithm: type  # algorithm(config, obs_dim, act_dim, num_transitions) with init / phases / act


@dataclasses.dataclass(frozen=True)
class Algo:
    family: str  # a key of FAMILIES
    values: Mapping[str, Any] = dataclasses.field(default_factory=dict)  # the config values that make it this one
    # the ENV_DEFAULTS sections it reads after its family's and before its own, and the values of those it skips
    sections: tuple[str, ...] = ()
    skip: tuple[str, ...] = ()


FAMILIES: dict[str, Family] = {
    "td3bc": Family(TD3BCConfig, TD3BC),
    "sacn": Family(SACNConfig, SACN),
    "rebrac": Family(ReBRACConfig, ReBRAC),
    "iql": Family(IQLConfig, IQL),
}

ALGOS: dict[str, Algo] = {
    "bc": Algo("td3bc", {"bc_only": True, "pretrain": "actor"}),
    "td3bc": Algo("td3bc"),
    "td3bc_cql": Algo("td3bc", {"cql_weight": 10.0}),
    "edac": Algo("sacn"),
    "sacn": Algo("sacn", {"eta": 0.0}, sections=("edac",), skip=("eta",)),  # EDAC's ensemble sizes
    "edac_bc": Algo("sacn", {"bc_weight": 1.0}, sections=("edac",)),
    # the authors' CQL configs (their CORL fork's configs/cql/door): cql_min_q_weight 10, policy_lr 3e-5, no entropy in
    # the backup (CORL's own door/pen configs, added later: cql_alpha 1, policy_lr 1e-4)
    "cql": Algo("sacn", {"num_critics": 2, "eta": 0.0, "cql_alpha": 10.0, "backup_entropy": False,
                         "pretrain": "none", "actor_lr": 3e-5, "simultaneous_update": True}),
    "rebrac": Algo("rebrac"),
    "iql": Algo("iql"),
}

# Presets: named sets of config values, applied after the per-env defaults and before explicit overrides, keyed by
# algorithm or, for the rest, by family.
# "authors": the authors' code (AdamJelley/EfficientOfflineRL, a CORL fork) switch by switch; docs/fidelity.md has
# the table (what the paper says, what their code and CORL do, our default, the flag).
_AUTHORS_COMMON = {"layer_norm_affine": False, "layer_norm_eps": 1e-5, "init": "torch", "balance": "signed",
                   "timeouts": "stop"}
# "published": TD3+BC's own published alpha (Fujimoto & Gu 2021), the main job's default (experiments.mujoco_medium):
# with it the from-scratch baseline learns on our data; with the paper's per-env alphas (hopper 10) it does not.
PRESETS: dict[str, dict[str, dict[str, Any]]] = {
    "published": {"td3bc": {"alpha": 2.5}},
    "authors": {
        "td3bc": _AUTHORS_COMMON | {"actor_hidden": (256, 256, 256), "q_scale_eps": 0.0, "bc_target_updates": False},
        "sacn": _AUTHORS_COMMON | {"hidden_bias": 0.1, "tanh_log_det": "eps", "log_alpha_bound": 10.0,
                                   "pretrain_extra": 1000, "soft_entropy_at": "observations", "critic_fan": "out"},
        # CORL's cql.py as the authors ran it: orthogonal init of every layer, log-std offset -1 within [-20, 2],
        # temperature learning rate = policy learning rate, terminals only in the TD target, no EDAC-style output init
        "cql": _AUTHORS_COMMON | {"init": "orthogonal_all", "out_init": False, "log_std_bounds": (-20.0, 2.0),
                                  "log_std_offset": -1.0, "alpha_lr": 3e-5, "timeouts": "bootstrap"},
    },
}

# The paper's / authors' per-env hyper-parameters (Section 5, Appendix G Table 3), keyed by (section, env): a section
# is a family or an algorithm.  A section's entry for "*" applies to every env, then the env's own; a key
# (section, "env:dataset-part") applies when the dataset name contains that part (pen-cloned's EDAC eta).  Adroit's
# TD3+BC alpha is the paper's Table 3 value (0.1; the authors' door config has 1.0, see docs/fidelity.md).  A
# family's own pre-training length (10k updates, EDAC's 20k) is its config's default; Adroit's is the paper's 200k.
ENV_DEFAULTS: dict[tuple[str, str], dict[str, Any]] = {
    ("td3bc", "*"): {"alpha": 0.1},
    ("td3bc", "hopper"): {"alpha": 10.0},
    ("td3bc", "halfcheetah"): {"alpha": 20.0, "lam": 0.1},
    ("td3bc", "walker2d"): {"alpha": 5.0},
    ("td3bc", "door"): {"pretrain_updates": 200_000},
    ("td3bc", "hammer"): {"pretrain_updates": 200_000},
    ("td3bc", "relocate"): {"pretrain_updates": 200_000},
    ("td3bc", "pen"): {"alpha": 1.0, "pretrain_updates": 200_000},
    ("td3bc_cql", "pen"): {"cql_weight": 1.0},
    ("sacn", "halfcheetah"): {"lam": 0.1},
    ("sacn", "walker2d"): {"lam": 0.1},
    ("sacn", "door"): {"pretrain_updates": 200_000},
    ("sacn", "hammer"): {"pretrain_updates": 200_000},
    ("sacn", "relocate"): {"pretrain_updates": 200_000},
    ("sacn", "pen"): {"pretrain_updates": 200_000},
    ("edac", "*"): {"num_critics": 50, "eta": 200.0},
    ("edac", "hopper"): {"num_critics": 50, "eta": 1.0},
    ("edac", "halfcheetah"): {"num_critics": 10, "eta": 1.0},
    ("edac", "walker2d"): {"num_critics": 10, "eta": 1.0},
    ("edac", "pen"): {"num_critics": 20, "eta": 1000.0},
    ("edac", "pen:cloned"): {"eta": 10.0},
    # ReBRAC's published betas for the medium datasets (CORL's configs/offline/rebrac/<env>/medium_v2.yaml)
    ("rebrac", "hopper"): {"actor_beta": 0.01, "critic_beta": 0.01},
    ("rebrac", "halfcheetah"): {"actor_beta": 0.001, "critic_beta": 0.01},
    ("rebrac", "walker2d"): {"actor_beta": 0.05, "critic_beta": 0.1},
    # door (CORL's configs/offline/rebrac/door/<level>_v1.yaml, the same in configs/finetune/rebrac/door/cloned_v1.yaml)
    ("rebrac", "door"): {"actor_beta": 0.01, "critic_beta": 0.1, "actor_lr": 3e-4, "critic_lr": 3e-4},
    ("rebrac", "door:human"): {"actor_beta": 0.1},
    # IQL (CORL's configs/offline/iql/<env>/medium_v2.yaml: expectile 0.7, beta 3 everywhere); hopper's also scales
    # the rewards by 1000 / (max - min episode return)
    ("iql", "hopper"): {"deterministic": True, "tau": 0.001, "normalize_reward": True},
    ("iql", "door"): {"expectile": 0.8},  # configs/{offline,finetune}/iql/door/*_v1.yaml (no actor dropout here)
}


def family_of(algo: str) -> Family:
    """The family `algo` is made from."""
    if not isinstance(algo, str) or algo not in ALGOS:
        raise ValueError(f"unknown algorithm {algo!r}; valid: {', '.join(ALGOS)}")
    return FAMILIES[ALGOS[algo].family]


def preset_values(preset: str | None, algo: str) -> dict[str, Any]:
    """The config values `preset` sets for `algo` ({} for no preset)."""
    if preset is None:
        return {}
    if preset not in PRESETS:
        raise ValueError(f"unknown preset '{preset}'; valid: {', '.join(PRESETS)}")
    values = PRESETS[preset]
    return dict(values[algo] if algo in values else values.get(ALGOS[algo].family, {}))


def env_defaults(algo: str, env: str, dataset: str = "") -> dict[str, Any]:
    """The per-env values `ENV_DEFAULTS` gives `algo` on `env` (and `dataset`): for its family's section, then its
    `sections`, then its own, the section's "*" entry, its env entry and a matching dataset entry."""
    entry = ALGOS[algo]
    sections = list(dict.fromkeys((entry.family, *entry.sections, algo)))
    d: dict[str, Any] = {}
    for section in sections:
        keys = [(section, "*"), (section, env)] + [
            k for k in ENV_DEFAULTS if k[0] == section and k[1].startswith(f"{env}:") and k[1][len(env) + 1:] in
            dataset]
        for key in keys:
            d |= {k: v for k, v in ENV_DEFAULTS.get(key, {}).items()
                  if section in (entry.family, algo) or k not in entry.skip}
    return d


# Where a resolved value came from, in the order `resolve` applies them (a later one wins):
#   default   the family's config dataclass
#   algo      the values that make the algorithm (`ALGOS`, e.g. td3bc_cql's cql_weight)
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
    """The config of `algo` and where each of its values came from, in one order (a later layer wins): the family's
    dataclass defaults < the algorithm's values (`ALGOS`) < the per-env values (`ENV_DEFAULTS` for `env` and
    `dataset`) < `preset`'s values < `overrides` (None values ignored), of which those named in `flags` were given
    on the command line and the rest by the study (`flags` None: not recorded, each a "variant" value).  `env` is a
    short name ("hopper"), or "" for no env (of the per-env values only those for every env, "*")."""
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
    """Config for `algo` (`resolve`'s, without the sources): the registry's values, then per-env defaults, then
    `preset`'s values, then `overrides` (None values ignored)."""
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


__all__ = ["ALGOS", "Algo", "Config", "FAMILIES", "Family", "IQL", "IQLConfig", "PRESETS", "Phase", "ReBRAC",
           "ReBRACConfig", "SACN",
           "SACNConfig", "TD3BC",
           "TD3BCConfig", "Resolved", "SOURCES", "env_defaults", "family_of", "make_algorithm", "make_config",
           "preset_values", "resolve", "saved_config"]
