"""Algorithm registry: name -> (family, config overrides), and the paper's per-env defaults in one table.

    bc          TD3BC family, actor pre-training (MSE) for the whole budget
    td3bc       TD3+BC
    td3bc_cql   TD3+BC + balanced uniform-action CQL penalty on the critic (the paper's hybrid)
    edac        EDAC (eta > 0);  sacn = EDAC with eta = 0
    edac_bc     EDAC + balanced MSE BC term on the actor (the paper's hybrid)
    cql         CQL (CORL form) on the SAC family with twin critics
"""
from __future__ import annotations

import dataclasses
from typing import Any

from offrl_jax.algos.common import Phase
from offrl_jax.algos.edac import EDAC, EDACConfig
from offrl_jax.algos.td3bc import TD3BC, TD3BCConfig
from offrl_jax.envs import ENVS

ALGOS: dict[str, tuple[type, dict[str, Any]]] = {
    "bc": (TD3BCConfig, {"bc_only": True, "pretrain": "actor"}),
    "td3bc": (TD3BCConfig, {}),
    "td3bc_cql": (TD3BCConfig, {"cql_weight": 10.0}),
    "edac": (EDACConfig, {}),
    "sacn": (EDACConfig, {"eta": 0.0}),
    "edac_bc": (EDACConfig, {"bc_weight": 1.0}),
    # the authors' CQL configs (CORL): cql_min_q_weight 10, policy_lr 3e-5, no entropy in the backup
    "cql": (EDACConfig, {"num_critics": 2, "eta": 0.0, "cql_alpha": 10.0, "backup_entropy": False,
                         "pretrain": "none", "actor_lr": 3e-5, "simultaneous_update": True}),
}

# Presets: named sets of config values, applied after the per-env defaults and before explicit overrides.
# "authors": the authors' code (AdamJelley/EfficientOfflineRL, a CORL fork) switch by switch; docs/fidelity.md has
# the table (what the paper says, what their code and CORL do, our default, the flag).
_AUTHORS_COMMON = {"layer_norm_affine": False, "layer_norm_eps": 1e-5, "init": "torch", "balance": "signed",
                   "timeouts": "stop"}
PRESETS: dict[str, dict[str, dict[str, Any]]] = {
    "authors": {
        "td3bc": _AUTHORS_COMMON | {"actor_hidden": (256, 256, 256), "q_scale_eps": 0.0, "bc_target_updates": False},
        "edac": _AUTHORS_COMMON | {"hidden_bias": 0.1, "tanh_log_det": "eps", "log_alpha_bound": 10.0},
        # CORL's cql.py as the authors ran it: orthogonal init, log-std offset -1 within [-20, 2], temperature
        # learning rate = policy learning rate, terminals only in the TD target, no EDAC-style output init
        "cql": _AUTHORS_COMMON | {"init": "orthogonal", "out_init": False, "log_std_bounds": (-20.0, 2.0),
                                  "log_std_offset": -1.0, "alpha_lr": 3e-5, "timeouts": "bootstrap"},
    },
}


def preset_values(preset: str | None, algo: str) -> dict[str, Any]:
    """The config values `preset` sets for `algo` ({} for no preset)."""
    if preset is None:
        return {}
    if preset not in PRESETS:
        raise ValueError(f"unknown preset '{preset}'; valid: {', '.join(PRESETS)}")
    family = "cql" if algo == "cql" else ("td3bc" if ALGOS[algo][0] is TD3BCConfig else "edac")
    return dict(PRESETS[preset][family])


# The paper's / authors' per-env hyper-parameters (Section 5, Appendix G Table 3), keyed by (family, env): the
# family's entry for "*" applies to every env, then the env's own.  Adroit's TD3+BC alpha is the paper's Table 3
# value (0.1; the authors' door config has 1.0, see docs/fidelity.md).  A key (family, "env:dataset-part") applies
# when the dataset name contains that part (pen-cloned's EDAC eta).
ENV_DEFAULTS: dict[tuple[str, str], dict[str, Any]] = {
    ("td3bc", "*"): {"alpha": 0.1, "pretrain_updates": 10_000},
    ("td3bc", "hopper"): {"alpha": 10.0},
    ("td3bc", "halfcheetah"): {"alpha": 20.0, "lam": 0.1},
    ("td3bc", "walker2d"): {"alpha": 5.0},
    ("td3bc", "door"): {"pretrain_updates": 200_000},
    ("td3bc", "hammer"): {"pretrain_updates": 200_000},
    ("td3bc", "relocate"): {"pretrain_updates": 200_000},
    ("td3bc", "pen"): {"alpha": 1.0, "pretrain_updates": 200_000},
    ("td3bc_cql", "pen"): {"cql_weight": 1.0},
    ("edac", "*"): {"num_critics": 50, "eta": 200.0, "pretrain_updates": 20_000},
    ("edac", "hopper"): {"num_critics": 50, "eta": 1.0},
    ("edac", "halfcheetah"): {"num_critics": 10, "eta": 1.0, "lam": 0.1},
    ("edac", "walker2d"): {"num_critics": 10, "eta": 1.0, "lam": 0.1},
    ("edac", "door"): {"pretrain_updates": 200_000},
    ("edac", "hammer"): {"pretrain_updates": 200_000},
    ("edac", "relocate"): {"pretrain_updates": 200_000},
    ("edac", "pen"): {"num_critics": 20, "eta": 1000.0, "pretrain_updates": 200_000},
    ("edac", "pen:cloned"): {"eta": 10.0},
}
# which of the family's per-env values an algorithm takes (the rest of its config comes from ALGOS)
_ENSEMBLE_FIELDS = {"edac": ("num_critics", "eta"), "edac_bc": ("num_critics", "eta"), "sacn": ("num_critics",),
                    "cql": ()}


def env_defaults(algo: str, env: str, dataset: str = "") -> dict[str, Any]:
    """The per-env values `ENV_DEFAULTS` gives `algo` on `env` (and `dataset`): the family's "*" entry, its env
    entry, a matching dataset entry, then the algorithm's own env entry."""
    family = "td3bc" if ALGOS[algo][0] is TD3BCConfig else "edac"
    parts = [(family, "*"), (family, env)]
    parts += [k for k in ENV_DEFAULTS if k[0] == family and k[1].startswith(f"{env}:") and k[1][len(env) + 1:] in
              dataset]
    parts += [(algo, env)] if algo != family else []
    d: dict[str, Any] = {}
    for key in parts:
        d |= ENV_DEFAULTS.get(key, {})
    if family == "edac":  # the ensemble values only where the algorithm uses them
        keep = _ENSEMBLE_FIELDS.get(algo, ("num_critics", "eta"))
        d = {k: v for k, v in d.items() if k not in ("num_critics", "eta") or k in keep}
    return d


def make_config(algo: str, env: str = "", dataset: str = "", preset: str | None = None, **overrides: Any):
    """Config for `algo` with registry settings, then per-env defaults, then `preset`'s values, then `overrides`
    (None values ignored).  `env` is a short name ("hopper"), or "" for no env (no per-env defaults)."""
    if not isinstance(algo, str) or algo not in ALGOS:
        raise ValueError(f"unknown algorithm {algo!r}; valid: {', '.join(ALGOS)}")
    if not isinstance(env, str) or (env and env not in ENVS):
        raise ValueError(f"unknown env {env!r}; valid: {', '.join(ENVS)}")
    config_cls, fixed = ALGOS[algo]
    fields = {f.name for f in dataclasses.fields(config_cls)}
    values = fixed | env_defaults(algo, env, dataset) | preset_values(preset, algo)
    for key, value in overrides.items():
        if value is None:
            continue
        if key not in fields:
            raise ValueError(f"'{key}' is not a hyper-parameter of {algo}; valid: {', '.join(sorted(fields))}")
        values[key] = value
    return config_cls(**values)


def make_algorithm(config, obs_dim: int, act_dim: int, num_transitions: int):
    """The algorithm object for a config from `make_config`."""
    if isinstance(config, TD3BCConfig):
        return TD3BC(config, obs_dim, act_dim)
    return EDAC(config, obs_dim, act_dim, num_transitions)


__all__ = ["ALGOS", "EDAC", "EDACConfig", "PRESETS", "Phase", "TD3BC", "TD3BCConfig", "env_defaults",
           "make_algorithm", "make_config", "preset_values"]
