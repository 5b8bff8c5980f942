"""What the MuJoCo studies share: their flags (`parser`), the variants a command line asks for (`given`,
`sweep_variants`, `pretrain_variants`) and the study they make (`make_study`).  Each `experiments/<name>.py` is a
declaration on top of these: its defaults, the variants it compares and the flags it leaves out.

A study's default config preset (`parser(default_preset=...)`: the main job's "published", TD3+BC's own alpha) is
declared, not written into the parsed flags: it applies to the variants a study builds when no --preset is given,
under every hyper-parameter flag, and is not part of the flags --config replays.
"""
from __future__ import annotations

import argparse
import re
from pathlib import Path

from offrl_jax.algos import ALGOS, PRESETS
from offrl_jax.algos.config import ONLINE_FIELDS
from offrl_jax.app.flags import FLAG_FIELDS, add_config_flags, config_values, run_args, sweepable_fields
from offrl_jax.data.catalogue import KNOWN
from offrl_jax.data.dataset import LOCOMOTION_ENVS, LOCOMOTION_LEVELS
from offrl_jax.data.readers import FILE_SUFFIXES
from offrl_jax.run.study import Study, Variant
from offrl_jax.system.cli import OneLineParser, UsageError, positive_int

ENVS, LEVELS = LOCOMOTION_ENVS, LOCOMOTION_LEVELS  # the generated locomotion datasets
# the Adroit datasets a study with `adroit=True` offers: the catalogue's door datasets (human, cloned)
ADROIT_LEVELS = {"door": tuple(n.removeprefix("door-") for n in KNOWN if re.fullmatch(r"door-[a-z]+", n))}
PRETRAIN = ("actor+critic", "actor", "critic", "none")
LABELS = {"actor+critic": "pretrained", "none": "scratch", "actor": "actor-only", "critic": "critic-only"}


def parser(prog: str, doc: str, updates: int = 100_000,
           eval_every: int = 5_000, env: str = "hopper", omit: tuple[str, ...] = (),
           seeds: int = 3, eval_episodes: int = 10, default_preset: str | None = None,
           online: bool = False, adroit: bool = False) -> argparse.ArgumentParser:
    """The flags every MuJoCo study shares; studies pass their own defaults, leave out the flags they set
    themselves (`omit`: destinations, e.g. ("pretrain", "lam")); `default_preset` names the config preset the study
    applies when no --preset is given; the config
    fields only an online phase reads (`ONLINE_FIELDS`) are flags of a study with one (`online`); a study with
    `adroit` also takes door-human and door-cloned (`--env door --level human|cloned`; `check_level`).  Each
    hyper-parameter's stated default is the study's own, read from what it builds when its help is shown
    (`offrl_jax.app.dry_run.state_defaults`)."""
    p = OneLineParser(prog=prog, description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    group = p.add_argument_group("what to compare")

    def add(flag: str, **kw) -> None:  # omitted flags are not offered: a study never accepts a flag it would ignore
        if flag[2:].replace("-", "_") not in omit:
            group.add_argument(flag, **kw)

    envs, levels = ENVS, LEVELS
    if adroit:
        envs, levels = envs + tuple(ADROIT_LEVELS), levels + tuple(dict.fromkeys(sum(ADROIT_LEVELS.values(), ())))
    add("--env", choices=envs, default=env,
        help="task: trains on <env>-<level> (or --dataset-path) and evaluates there (default %(default)s)")
    add("--level", choices=levels, default="medium",
        help="dataset level (default %(default)s" + ("; door: human, the default there, or cloned)" if adroit else ")"))
    add("--algo", choices=tuple(ALGOS), default="td3bc", help="(default %(default)s)")
    add("--pretrain", nargs="+", choices=PRETRAIN, default=["actor+critic", "none"],
        help="pre-training modes to compare, one variant each (default: actor+critic none)")
    add("--pretrain-updates", type=pretrain_budget, default=None,
        help="N, or auto[:CAP] to end each pre-training phase when its supervised losses improve by less than 1 %% "
             "per 1k updates (every seed; capped at CAP or the default; the rest goes to offline RL; --eval-every "
             "must then be a multiple of 1000, e.g. 5000); it differs per algorithm and env (the default "
             "--algo's below; --dry-run shows another's).  Default: per algorithm and env")
    help_authors = ("authors: the authors' code switch by switch (LayerNorm without scale/bias and eps 1e-5, "
                    "PyTorch init, a 3x256 TD3+BC actor, no bootstrap at time-outs, x/sg(x) loss balancing, the "
                    "paper's per-env alphas, EDAC's 10k + 11k pre-training; docs/fidelity.md); flags given with it "
                    "override single values")
    help_default = (f"published: TD3+BC's published alpha ({PRESETS['published']['td3bc']['alpha']}) instead of the "
                    "paper's per-env values.  " if "published" in PRESETS else "")
    help_default += (f"Default: {default_preset}" if default_preset else
                     "Default: none (each value is the per-env table's or the config's)")
    add("--preset", nargs=1, choices=tuple(PRESETS), default=None,
        help="a table of values for every variant.  " + help_authors + ".  " + help_default)
    p.set_defaults(default_preset=default_preset)
    add_config_flags(p, tuple(omit) + (() if online else tuple(ONLINE_FIELDS)))
    run_args(p, updates=updates, eval_every=eval_every, seeds=seeds, eval_episodes=eval_episodes)
    return p


def pretrain_budget(text: str) -> dict:
    """--pretrain-updates: "N" -> N updates, not self-ending (also over a replayed run's auto); "auto" or
    "auto:CAP" -> self-ending pre-training."""
    if text == "auto" or text.startswith("auto:"):
        cap = positive_int(text[5:]) if text.startswith("auto:") else None
        return {"pretrain_auto": True} | ({"pretrain_updates": cap} if cap else {})
    return {"pretrain_updates": positive_int(text), "pretrain_auto": False}


def overrides(args) -> dict:
    """Config overrides from the flags (a flag not given, or omitted by the study, is left out)."""
    return config_values(args, FLAG_FIELDS) | (getattr(args, "pretrain_updates", None) or {})


HPARAM_DESTS = FLAG_FIELDS | {"pretrain_updates"}  # the flags that set one hyper-parameter each
SWEPT = tuple(sorted(sweepable_fields()))  # flags that take several values (a sweep)


def given(args) -> dict:
    """The hyper-parameters set on the command line (the rest take the per-env defaults); a swept flag given one
    value is that value, given several it stays a list (see `sweep_variants`)."""
    preset = getattr(args, "preset", None)  # nargs=1: a list of one name, or None
    return overrides(args) | ({"preset": preset[0]} if preset else {})


def chosen(args) -> dict:
    """`given(args)` under the study's declared default preset when no --preset was given: what its variants get."""
    default = getattr(args, "default_preset", None)
    return ({"preset": default} if default and not getattr(args, "preset", None) else {}) | given(args)


def sweep_variants(label: str, algo: str, fixed: dict, flags: frozenset[str] = frozenset(), env: str = "",
                   dataset: str = "") -> tuple[Variant, ...]:
    """One variant, or one per value of a swept flag (labels "pretrained alpha=2.5", ...), resolved on `env` and
    `dataset`; the runner trains a sweep's variants as one program.  A "preset" entry of `fixed` is the variants'
    config preset, applied under the other entries; the entries named in `flags` were given on the command line (the
    rest are the study's own)."""
    fixed = dict(fixed)
    preset = fixed.pop("preset", None)
    swept = [k for k in SWEPT if isinstance(fixed.get(k), list)]
    if len(swept) > 1:
        raise ValueError(f"sweep one hyper-parameter at a time, got several values for {' and '.join(swept)}")
    points = [(f"{label} {swept[0]}={value:g}", fixed | {swept[0]: value}) for value in fixed[swept[0]]] \
        if swept else [(label, fixed)]
    return tuple(Variant.make(name, algo, env, dataset, preset, values, flags) for name, values in points)


def study_variants(label: str, algo: str, own: dict, args, fixed: dict | None = None, env: str | None = None,
                   drop: tuple[str, ...] = ()) -> tuple[Variant, ...]:
    """`sweep_variants` of the study's own values `own` under the flags given (`chosen(args)`, which win, but those
    named in `drop`), and `fixed`, values of the study's that no flag changes (they win over the flags); on `env`
    (default --env) and the dataset the study trains on there (`dataset_of`)."""
    fixed, env = fixed or {}, env or args.env
    flags = {k: v for k, v in chosen(args).items() if k not in drop}
    return sweep_variants(label, algo, own | flags | fixed, frozenset(overrides(args)) - fixed.keys() - set(drop),
                          env, dataset_of(env, args))


def pretrain_variants(algo: str, modes, args, env: str | None = None, own: dict | None = None,
                      drop: tuple[str, ...] = ()) -> tuple[Variant, ...]:
    """One variant per pre-training mode (`study_variants`; `own`: the study's other values for them)."""
    return tuple(v for mode in modes for v in study_variants(LABELS[mode], algo, (own or {}) | {"pretrain": mode},
                                                             args, env=env, drop=drop))


def dataset_of(env: str, args) -> str:
    """The dataset a study on `env` trains on: --dataset-path, or <env>-<level> (`check_level`)."""
    return args.dataset_path or f"{env}-{check_level(env, getattr(args, 'level', 'medium'), args)}"


def make_study(env: str, algo: str, level: str, args, extra: dict | None = None,
               variants: tuple[Variant, ...] | None = None, reference: str | None = None, name: str = "") -> Study:
    if variants is None:
        variants = pretrain_variants(algo, args.pretrain, args, env)
        reference = LABELS["none"] if "none" in args.pretrain else None
    fields = study_fields(args) | (extra or {})
    if args.dataset_path and "level" in getattr(args, "typed", ()):  # flags that would be ignored are refused
        raise UsageError("--level names a generated dataset (<env>-<level>), and --dataset-path gives the data: "
                         "leave one out")
    level = check_level(env, level, args)
    dataset = args.dataset_path or f"{env}-{level}"
    data_name = dataset_label(args.dataset_path) if args.dataset_path else f"{env}-{level}"
    study = Study(name=name or f"{data_name}-{algo}", dataset=dataset, env=env, variants=variants,
                  reference=reference, **fields)
    for v in study.variants:
        auto_only = sorted({"pretrain_auto_window", "pretrain_auto_tol"} & v.given().keys())
        if auto_only and not study.config(v.label).pretrain_auto:
            raise UsageError(f"{', '.join('--' + f.replace('_', '-') for f in auto_only)} applies only to "
                             "--pretrain-updates auto[:CAP]; give that too, or leave it out")
    return study


def check_level(env: str, level: str, args) -> str:
    """The level of `env` the study trains on: `level`, or an Adroit env's first when --level was not given; an env
    and level that name no dataset (door-medium, hopper-cloned) are refused."""
    valid = ADROIT_LEVELS.get(env, LEVELS)
    if env in ADROIT_LEVELS and "level" not in getattr(args, "typed", ()):
        level = valid[0]
    if level not in valid and not args.dataset_path:
        raise UsageError(f"--env {env} --level {level}: there is no {env}-{level}; {env}'s levels: {', '.join(valid)}")
    return level


def dataset_label(dataset_path: str) -> str:
    """A user dataset's part of a study's name: the file's or folder's name without its suffix ("my-hopper.npz":
    "my-hopper"), a Minari id with - for / ("mujoco/hopper/medium-v0": "mujoco-hopper-medium-v0")."""
    path = Path(dataset_path)
    name = path.stem if path.suffix.lower() in FILE_SUFFIXES else (path.name if path.exists() else dataset_path)
    return re.sub(r"[^A-Za-z0-9._+=-]+", "-", name).strip("-.") or "dataset"


def study_fields(args) -> dict:
    """Study fields from the run flags (a study without --updates / --eval-every sets those itself)."""
    fields = dict(seeds=tuple(range(args.seed_offset, args.seed_offset + args.seeds)),
                  eval_episodes=args.eval_episodes, batch_size=args.batch_size,
                  checkpoint_every=args.checkpoint_every, keep_checkpoints=args.keep_checkpoints,
                  max_transitions=args.max_transitions,
                  clip_actions=args.clip_actions)
    return fields | {k: getattr(args, k) for k in ("updates", "eval_every") if hasattr(args, k)}
