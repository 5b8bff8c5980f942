"""The paper's central claim on D4RL-style MuJoCo data: offline RL with actor+critic pre-training versus without.

Default (no arguments): hopper-medium (regenerated from the shipped behaviour policy and cached), TD3+BC with
actor+critic pre-training (10k updates) vs from scratch, 5 seeds (the member axis of one program), 40k updates each
(pre-training included), evaluated every 2.5k updates (5 episodes, deterministic policy, D4RL-normalised); the two
variants train at once (`--parallel 2`).  That budget is what fits five seeds, the fewest a reviewer accepts, in 30
minutes on 2 idle CPU cores with the dataset generated first (23 min of training; 10 seeds take about twice as
long: `--seeds 10`).  The final table gives every seed's updates to each threshold, the speed-up with its
bootstrap interval and IQM scores (`offrl_jax.summary`).  TD3+BC's alpha is 2.5 here (TD3+BC's published default,
with which the from-scratch baseline learns on this data); the paper's per-env alphas (hopper 10) come with
`--preset authors` or `--alpha 10`.  See RESULTS.md for the measured wall-clock time and for what happens with
longer budgets (`--updates 300000`).

    python -m experiments.mujoco_medium
    python -m experiments.mujoco_medium --alpha 2.5 10                                   # both alphas, one program
    python -m experiments.mujoco_medium --preset authors                                 # the authors' code's setup
    python -m experiments.mujoco_medium --env walker2d --algo edac --updates 50000
    python -m experiments.mujoco_medium --pretrain actor critic actor+critic none      # Appendix C ablation
    python -m experiments.mujoco_medium --preset paper                                   # 3 envs x TD3+BC/EDAC, 1M
"""
from __future__ import annotations

import argparse

from experiments.common import OneLineParser, UsageError, main_guard, positive_int, study_fields
from experiments.flags import FLAG_FIELDS, add_config_flags, config_values, run_args, sweepable_fields
from offrl_jax.algos import ALGOS, PRESETS, SACNConfig, preset_values
from offrl_jax.study import Study, Variant

ENVS = ("hopper", "halfcheetah", "walker2d")
LEVELS = ("medium", "medium-replay", "full-replay", "medium-expert", "expert", "random")
PRETRAIN = ("actor+critic", "actor", "critic", "none")
LABELS = {"actor+critic": "pretrained", "none": "scratch", "actor": "actor-only", "critic": "critic-only"}


def parser(prog: str = "experiments.mujoco_medium", doc: str = __doc__, updates: int = 100_000,
           eval_every: int = 5_000, env: str = "hopper", edac_pretrain: dict | None = None, omit: tuple[str, ...] = (),
           preset: bool = False, num_critics: str = "per env", seeds: int = 3,
           eval_episodes: int = 10) -> argparse.ArgumentParser:
    """The flags every MuJoCo study shares; studies pass their own defaults (`edac_pretrain`: the study's EDAC
    `pretrain_updates` / `actor_pretrain_fraction`, and `num_critics`, for the help text), leave out the flags
    they set themselves (`omit`: destinations, e.g. ("pretrain", "lam")), and only the main job has `--preset`."""
    edac = {f: getattr(SACNConfig, f) for f in ("pretrain_updates", "actor_pretrain_fraction")} | (edac_pretrain or {})
    p = OneLineParser(prog=prog, description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    group = p.add_argument_group("what to compare")

    def add(flag: str, **kw) -> None:  # omitted flags are not offered: a study never accepts a flag it would ignore
        if flag[2:].replace("-", "_") not in omit:
            group.add_argument(flag, **kw)

    add("--env", choices=ENVS, default=env)
    add("--level", choices=LEVELS, default="medium", help="dataset level (default %(default)s)")
    add("--algo", choices=tuple(ALGOS), default="td3bc", help="(default %(default)s)")
    add("--pretrain", nargs="+", choices=PRETRAIN, default=["actor+critic", "none"],
        help="pre-training modes to compare, one variant each (default: actor+critic none)")
    add("--pretrain-updates", type=pretrain_budget, default=None,
        help=f"N, or auto[:CAP] to end each pre-training phase when its supervised losses improve by less than 1 %% "
             f"per 1k updates (every seed; capped at CAP or the default; the rest goes to offline RL; --eval-every "
             f"must then be a multiple of 1000, e.g. 5000).  "
             f"Default: 10k TD3+BC, {edac['pretrain_updates'] // 1000}k EDAC")
    help_authors = ("authors: the authors' code switch by switch (LayerNorm without scale/bias and eps 1e-5, "
                    "PyTorch init, a 3x256 TD3+BC actor, no bootstrap at time-outs, x/sg(x) loss balancing, the "
                    "paper's per-env alphas; docs/fidelity.md); flags given with it override single values")
    if preset:
        add("--preset", nargs="+", choices=("paper", *PRESETS), default=None,
            help="paper: 3 envs x {td3bc, edac} medium x --seeds seeds x 1M updates (evaluation every 10k), "
                 "each in its own sub-directory; --env/--algo/--level/--updates/--eval-every other than their "
                 "defaults are refused.  " + help_authors + ".  Both may be given")
    else:
        add("--preset", nargs=1, choices=tuple(PRESETS), default=None, help=help_authors)
    add_config_flags(p, omit)
    for action in p._actions:  # this study's defaults where they differ from the configs'
        if action.dest == "num_critics":
            action.help = f"EDAC/SAC-N ensemble size. Default: {num_critics}"
        if action.dest == "actor_pretrain_fraction":
            action.help = (f"EDAC: share of --pretrain-updates spent on soft BC, the rest on the critic. Default: "
                           f"{edac['actor_pretrain_fraction']}")
        if action.dest == "alpha" and preset:
            action.help = (f"TD3+BC's actor regularisation. Default: {MAIN_JOB_ALPHA} without a preset, else per env "
                           "(hopper 10, halfcheetah 20, walker2d 5); several values = a sweep, vmapped in one "
                           "program")
    run_args(p, updates=updates, eval_every=eval_every, seeds=seeds, eval_episodes=eval_episodes)
    return p


def pretrain_budget(text: str) -> dict:
    """--pretrain-updates: "N" -> {pretrain_updates: N}; "auto" or "auto:CAP" -> self-ending pre-training."""
    if text == "auto" or text.startswith("auto:"):
        cap = positive_int(text[5:]) if text.startswith("auto:") else None
        return {"pretrain_auto": True} | ({"pretrain_updates": cap} if cap else {})
    return {"pretrain_updates": positive_int(text)}


def overrides(args) -> dict:
    """Config overrides from the flags (a flag not given, or omitted by the study, is left out)."""
    return config_values(args, FLAG_FIELDS) | (getattr(args, "pretrain_updates", None) or {})


HPARAM_DESTS = FLAG_FIELDS | {"pretrain_updates"}  # the flags that set one hyper-parameter each
PRESET_FIXED = ("env", "algo", "level", "updates", "eval_every")  # what --preset paper sets itself


MAIN_JOB_ALPHA = 2.5  # the main job's TD3+BC alpha unless --alpha or a preset is given (see the module doc)


def build(args) -> Study | list[Study]:
    presets = args.preset or []
    if "paper" in presets:
        defaults = make_parser()
        changed = [f"--{d.replace('_', '-')}" for d in PRESET_FIXED if getattr(args, d) != defaults.get_default(d)]
        if changed:
            raise UsageError(f"--preset paper sets {', '.join(changed)} itself; leave them out")
        return [make_study(env, algo, "medium", args, dict(updates=1_000_000, eval_every=10_000))
                for env in ENVS for algo in ("td3bc", "edac")]
    if args.alpha is None and not presets and ALGOS[args.algo].family == "td3bc":
        args.alpha = [MAIN_JOB_ALPHA]
    return make_study(args.env, args.algo, args.level, args)


SWEPT = tuple(sorted(sweepable_fields()))  # flags that take several values (a sweep)


def given(args) -> dict:
    """The hyper-parameters set on the command line (the rest take the per-env defaults); a swept flag given one
    value is that value, given several it stays a list (see `sweep_variants`)."""
    values = overrides(args)
    config_presets = [p for p in getattr(args, "preset", None) or [] if p in PRESETS]
    return values | ({"preset": config_presets[0]} if config_presets else {})


def sweep_variants(label: str, algo: str, fixed: dict) -> tuple[Variant, ...]:
    """One variant, or one per value of a swept flag (labels "pretrained alpha=2.5", ...); the runner trains a
    sweep's variants as one vmapped program.  A "preset" entry of `fixed` is expanded into its values for `algo`
    (every value is then recorded in the variant), under the other entries."""
    fixed = dict(fixed)
    fixed = preset_values(fixed.pop("preset", None), algo) | fixed
    return _sweep_variants(label, algo, fixed)


def _sweep_variants(label: str, algo: str, fixed: dict) -> tuple[Variant, ...]:
    swept = [k for k in SWEPT if isinstance(fixed.get(k), list)]
    if not swept:
        return (Variant.of(label, algo, **fixed),)
    if len(swept) > 1:
        raise ValueError(f"sweep one hyper-parameter at a time, got several values for {' and '.join(swept)}")
    name = swept[0]
    return tuple(Variant.of(f"{label} {name}={value:g}", algo, **(fixed | {name: value})) for value in fixed[name])


def pretrain_variants(algo: str, modes, args) -> tuple[Variant, ...]:
    return tuple(v for mode in modes for v in sweep_variants(LABELS[mode], algo, {"pretrain": mode} | given(args)))


def make_study(env: str, algo: str, level: str, args, extra: dict | None = None,
               variants: tuple[Variant, ...] | None = None, reference: str | None = None, name: str = "") -> Study:
    if variants is None:
        variants = pretrain_variants(algo, args.pretrain, args)
        reference = LABELS["none"] if "none" in args.pretrain else None
    fields = study_fields(args) | (extra or {})
    dataset = args.dataset_path or f"{env}-{level}"
    return Study(name=name or f"{env}-{level}-{algo}", dataset=dataset, env=env, variants=variants,
                 reference=reference, **fields)


def make_parser():  # the budget that fits 5 seeds in 30 minutes on 2 cores (module doc)
    return parser(updates=40_000, eval_every=2_500, seeds=5, eval_episodes=5, preset=True)


def main(argv=None) -> int:
    return main_guard(build, make_parser(), argv, hparams=given, hparam_dests=HPARAM_DESTS)


if __name__ == "__main__":
    from offrl_jax.cli import run_main

    run_main(main)
