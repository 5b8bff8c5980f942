"""First imitate, then improve -- online: the offline phases of a family as the main job runs them, then an online
phase of --online-steps env steps per seed in the same run, on the same member axis (`offrl_jax.online.loop`).

Arms (--arms; each a variant, all with the same env steps and, but for online-rl, the same offline updates):
  pretrained      BC + MC critic pre-training, then offline RL, then online (the paper's method, continued)
  scratch         offline RL from scratch, then online
  pretrain-only   pre-training for the whole offline budget (--pretrain-updates sets the other arms'), no
                  offline RL, then online (imitate, then improve in the environment)
  online-rl       no offline phase: online RL from its initialisation with the dataset in its replay, the family
                  without its behaviour terms (TD3+BC's BC weight 0, ReBRAC's penalties 0; RLPD's recipe without
                  its ensemble): whether the offline phases were worth it

Default (no arguments): hopper-medium, TD3+BC (alpha 2.5, as the main job), the four arms, 5 seeds, 40k offline
updates (10k of them pre-training), then 50k online env steps: blocks of 1,000 env steps, each followed by 1,000
updates (utd 1), evaluation every 2.5k updates offline and every 5k env steps online.  curves.csv has an env_steps
column for the online rows and the training episodes' mean score (train_score).

How each family fine-tunes (its config fields, shown by --dry-run with their sources): minibatches half offline,
half online (replay mix, online-mix 0.5: Cal-QL, CORL's ReBRAC), IQL's rows appended to the dataset (replay append:
CORL's IQL); TD3+BC and ReBRAC explore with Gaussian noise on their action (explore-noise: TD3's 0.1, CORL's ReBRAC
0), SAC-N/EDAC, CQL, Cal-QL and IQL's Gaussian policy with a sample; Cal-QL bounds the push-down by each finished
online episode's return (--calibration-online episode, the authors' code) or drops the bound online (off, CORL's);
ReBRAC drops its critic penalty and decays its actor penalty to half over the online phase (CORL); TD3+BC keeps its
alpha (the behaviour term still tracks the data the minibatches mix in).  A run stopped inside its online phase
resumes at its last online evaluation, envs and buffers restored exactly (checkpoints/<variant>.online.msgpack;
docs/online.md).

    python -m experiments.finetune
    python -m experiments.finetune --env hopper --online-steps 2000 --online-block 500 --online-eval-every 1000 \\
        --updates 2000 --pretrain-updates 1000 --seeds 2 --max-transitions 20000          # a tiny run
    python -m experiments.finetune --algo rebrac --replay online-only --warmup-steps 5000   # WSRL's recipe
    python -m experiments.finetune --algo rebrac --env door --level cloned     # CORL's door values (docs/online.md)
    python -m experiments.finetune --from runs/mujoco_medium/RUN --variant pretrained      # fine-tune a finished run
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

from offrl_jax.algos import ALGOS, make_algorithm
from offrl_jax.algos.config import ONLINE_FIELDS
from offrl_jax.app.command import run_command
from offrl_jax.app.outputs import saved_studies
from offrl_jax.app.studies import HPARAM_DESTS, given, make_study, parser, study_variants
from offrl_jax.envs.registry import get_env_spec
from offrl_jax.online.config import OnlineConfig
from offrl_jax.run.results import read_curves, short_curves
from offrl_jax.run.study import Study, reference_label
from offrl_jax.system.cli import UsageError, int_at_least, positive_int

# the online loop flags' defaults: OnlineConfig's own
ONLINE_DEFAULTS = {f.name: f.default for f in dataclasses.fields(OnlineConfig) if f.default is not dataclasses.MISSING}

ARMS = {"pretrained": {"pretrain": "actor+critic"}, "scratch": {"pretrain": "none"},
        "pretrain-only": {"pretrain": "actor+critic"},  # pre-training takes the offline budget
        "online-rl": {"pretrain": "none", "offline_updates": 0}}  # no offline phase; the algorithm without its
# behaviour terms (its `without_behaviour` values, in its family's file: RLPD's recipe without its ensemble, online RL
# with the data in its replay); algorithms that have no such form (IQL) have no online-rl arm
ONLINE_FLAGS = {"online_steps": "steps", "online_block": "block", "utd": "utd", "warmup_steps": "warmup",
                "buffer_capacity": "capacity", "online_eval_every": "eval_every"}


def build(args) -> Study:
    if args.from_run is not None:
        return check_online_flags(from_run(args, online_config(args)), given(args))
    if args.variant is not None:
        raise UsageError("--variant chooses among the variants of a finished run given with --from; without it "
                         "the variants are --arms")
    if args.algo == "bc":
        raise UsageError("--algo bc: behaviour cloning has no offline-RL phase and no critic to fine-tune online "
                         "(the pretrain-only arm is imitation, then improvement online)")
    online = online_config(args)
    if args.arms is None:
        args.arms = [arm for arm in ARMS if arm != "online-rl" or ALGOS[args.algo].without_behaviour is not None]
    if "pretrain-only" in args.arms and (getattr(args, "pretrain_updates", None) or {}).get("pretrain_auto"):
        raise UsageError("--pretrain-updates auto: the pretrain-only arm pre-trains for the whole offline budget "
                         "(--updates); give a number, or leave that arm out (--arms pretrained scratch)")
    without = {name: algo.without_behaviour for name, algo in ALGOS.items() if algo.without_behaviour is not None}
    if "online-rl" in args.arms and args.algo not in without:
        raise UsageError(f"--arms online-rl: {args.algo} has no form without its behaviour terms (online-rl runs "
                         f"with --algo {', '.join(without)}); leave that arm out")
    own = {arm: ARMS[arm] | (dict(without[args.algo]) if arm == "online-rl" else {}) for arm in args.arms}
    whole = {"pretrain_updates": args.updates}  # pretrain-only's, whatever --pretrain-updates gives the others
    variants = tuple(v for arm in args.arms for v in study_variants(
        arm, args.algo, own[arm], args, fixed=whole if arm == "pretrain-only" else None))
    return check_online_flags(make_study(args.env, args.algo, args.level, args, extra={"online": online},
                                         variants=variants, reference="scratch" if "scratch" in args.arms else None),
                              given(args))


def check_online_flags(study: Study, values: dict) -> Study:
    """`study`, unless an online flag given (`values`) does nothing for one of its variants: --online-mix where the
    replay does not mix (online-only, append), --explore-noise where the actor explores with a sample,
    --calibration-online where no variant calibrates (Cal-QL's online-rl arm has no bound: its form without the
    penalty)."""
    if "calibration_online" in values and not any(getattr(study.config(v.label), "calibration", False)
                                                   for v in study.variants):
        raise UsageError(f"--calibration-online: no variant of {study.name} bounds its CQL penalty by the returns "
                         "(--algo calql does)")
    for v in study.variants:
        config = study.config(v.label)
        if "online_mix" in values and config.replay != "mix":
            raise UsageError(f"--online-mix: {v.label} draws its minibatches with replay {config.replay}, which "
                             "does not mix (the mix is the online share of each minibatch with --replay mix)")
        if "explore_noise" in values and samples(config, study.env):
            raise UsageError(f"--explore-noise: {v.label}'s actor is stochastic and explores with a sample of its "
                             "policy; the noise is added only to a deterministic actor's action")
    return study


def samples(config, env: str) -> bool:
    """Whether a variant's actor explores with a sample (its family's `Algorithm.explore` gives an action, not the
    default None), traced abstractly: nothing is computed."""
    import jax
    import jax.numpy as jnp

    spec = get_env_spec(env)
    algo = make_algorithm(config, spec.obs_dim, spec.act_dim, 1)
    state = jax.eval_shape(algo.init, jax.random.PRNGKey(0))
    obs = jax.ShapeDtypeStruct((spec.obs_dim,), jnp.float32)
    return jax.eval_shape(algo.explore, state, obs, jax.random.PRNGKey(0)) is not None


def online_config(args) -> OnlineConfig:
    values = {field: getattr(args, flag) for flag, field in ONLINE_FLAGS.items()}
    typed = set(getattr(args, "typed", ()))
    if "online_block" not in typed and values["steps"] < values["block"]:  # fewer steps than the default block:
        # the block shrinks to fit them (and the warm-up and evaluation interval given), evaluating at the end
        if "online_eval_every" not in typed:
            values["eval_every"] = values["steps"]
        given_steps = [values["steps"], values["eval_every"], values["warmup"]]
        values["block"] = math.gcd(*given_steps)
    try:
        return OnlineConfig(**values)
    except ValueError as e:
        raise UsageError(str(e)) from None


FROM_FLAGS = {"from_run", "variant", "out", "overwrite", "parallel", "no_progress", "logger", "dry_run"}


def from_run(args, online: OnlineConfig) -> Study:
    """The online phase of a finished offline run: its study (variants, seeds, data, budget) with `online`, the
    online fields given, and `start_from` its directory, whose checkpoints the runner starts from."""
    run = args.from_run
    if args.variant is not None and len(set(args.variant)) != len(args.variant):
        raise UsageError(f"--variant {' '.join(args.variant)}: a variant is named twice (each is fine-tuned once)")
    typed = set(getattr(args, "typed", ())) - FROM_FLAGS - set(ONLINE_FLAGS) - ONLINE_FIELDS
    if typed:
        names = ", ".join(sorted("--" + t.replace("_", "-") for t in typed))
        raise UsageError(f"--from keeps {run}'s settings, so {names} cannot be given with it (online flags can)")
    if not (run / "config.json").is_file():
        what = "does not exist" if not run.exists() else "is not a directory" if not run.is_dir() else \
            "holds no config.json"
        raise UsageError(f"--from {run}: it {what}; --from takes the directory of a finished offline run (e.g. "
                         "runs/mujoco_medium/RUN)")
    if args.out is not None and Path(args.out).resolve() == run.resolve():
        raise UsageError(f"--out {args.out} is the run given with --from: fine-tuning writes a new run and keeps "
                         "that one; give another --out")
    saved = saved_studies(run)
    if isinstance(saved, list):
        raise UsageError(f"--from {run}: it holds several studies; give one of its sub-directories")
    if saved.online is not None:
        raise UsageError(f"--from {run}: that run has an online phase already (--resume it to finish it)")
    labels = args.variant or [v.label for v in saved.variants]
    unknown = sorted(set(labels) - {v.label for v in saved.variants})
    if unknown:
        raise UsageError(f"--variant {' '.join(unknown)}: {run} has {', '.join(v.label for v in saved.variants)}")
    for group, _ in saved.groups():  # a sweep trained as one program has one checkpoint: all of it or none
        chosen = [v.label for v in group if v.label in labels]
        if chosen and len(chosen) < len(group):
            raise UsageError(f"--variant: {', '.join(v.label for v in group)} were trained as one program (one "
                             "checkpoint); give all of them")
    unfinished(run, saved, labels)
    values = {k: v for k, v in given(args).items() if k in ONLINE_FIELDS}
    variants = tuple(v.with_values(values) for v in saved.variants if v.label in labels)
    reference = saved.reference if any(reference_label(saved, v.label) in labels for v in variants) else None
    return dataclasses.replace(saved, variants=variants, online=online, reference=reference,
                               start_from=str(run.resolve()))


def unfinished(run: Path, saved: Study, labels: list[str]) -> None:
    """Refuse (before anything is written) a --from run whose chosen variants' curves end before their offline
    budget: it was stopped, and starts no online phase until it is finished (the runner checks its checkpoints)."""
    try:
        rows = read_curves(run / "curves.csv") if (run / "curves.csv").is_file() else []
    except (OSError, ValueError) as e:
        raise UsageError(f"--from {run}: {e}") from None
    short = short_curves(rows, {label: saved.config(label).budget(saved.updates) for label in labels})
    if short:
        label, update = next(iter(short.items()))
        at = "has no evaluation yet" if update is None else f"stopped at update {update:,}"
        raise UsageError(f"--from {run}: {label} {at} of {saved.config(label).budget(saved.updates):,}, so its "
                         f"offline phases are not finished: finish them first (--resume {run})")


def make_parser():
    p = parser("experiments.finetune", __doc__, updates=40_000, eval_every=2_500, seeds=5, eval_episodes=5,
               omit=("pretrain",), default_preset="published", online=True, adroit=True)
    g = p.add_argument_group("online phase")
    g.add_argument("--arms", nargs="+", choices=tuple(ARMS), default=None,
                   help="the variants to compare (default: all four, or the first three for a family without an "
                        "online-rl form)")
    g.add_argument("--online-steps", type=positive_int, default=50_000,
                   help="env steps per seed after the offline phases (default %(default)s)")
    g.add_argument("--online-block", type=positive_int, default=ONLINE_DEFAULTS["block"],
                   help="env steps collected between two scans of updates; the online steps, the warm-up and the "
                        "online evaluation interval are multiples of it (default %(default)s; fewer --online-steps "
                        "than that: the block shrinks to fit them, and the phase is evaluated at its end)")
    g.add_argument("--utd", type=positive_int, default=ONLINE_DEFAULTS["utd"],
                   help="updates per env step (default %(default)s)")
    g.add_argument("--warmup-steps", type=int_at_least(0), default=ONLINE_DEFAULTS["warmup"],
                   help="env steps collected with the hand-over policy before the first online update (WSRL: "
                        "5000; default %(default)s)")
    g.add_argument("--buffer-capacity", type=int_at_least(0), default=ONLINE_DEFAULTS["capacity"],
                   help="online buffer rows per seed; 0: every online step, nothing overwritten (default)")
    g.add_argument("--from", dest="from_run", type=Path, default=None, metavar="RUN_DIR",
                   help="fine-tune the variants of this finished offline run (its checkpoints, settings, seeds and "
                        "data) instead of training them again; only online flags may be given with it")
    g.add_argument("--variant", nargs="+", default=None,
                   help="with --from: the variants to fine-tune (default: all)")
    g.add_argument("--online-eval-every", type=positive_int, default=ONLINE_DEFAULTS["eval_every"],
                   help="env steps between online evaluations (default %(default)s)")
    return p


def main(argv=None) -> int:
    return run_command(build, make_parser(), argv, hparams=given, hparam_dests=HPARAM_DESTS)


if __name__ == "__main__":
    from offrl_jax.system.cli import run_main

    run_main(main)
