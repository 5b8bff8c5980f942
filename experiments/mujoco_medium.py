"""The paper's central claim on D4RL-style MuJoCo data: offline RL with actor+critic pre-training versus without.

Default (no arguments): hopper-medium (regenerated from the shipped behaviour policy and cached), TD3+BC with
actor+critic pre-training (10k updates) vs from scratch, 5 seeds (the member axis of one program), 40k updates each
(pre-training included), evaluated every 2.5k updates (5 episodes, deterministic policy, D4RL-normalised); the two
variants train at once (`--parallel 2`).  That budget is what fits five seeds, the fewest a reviewer accepts, in 30
minutes on 2 idle CPU cores with the dataset generated first (23 min of training; 10 seeds take about twice as
long: `--seeds 10`).  The final table gives every seed's updates to each threshold, the speed-up with its
bootstrap interval and IQM scores (`offrl_jax.run.summary`).  TD3+BC's alpha is 2.5 here (the declared default preset
`published`: TD3+BC's published alpha, with which the from-scratch baseline learns on this data); the paper's
per-env alphas (hopper 10) come with `--preset authors` or `--alpha 10`.  The wall-clock time is measured in
results/mujoco_medium/default-5seeds/README.md; RESULTS.md says what happens with longer budgets (`--updates 300000`).

    python -m experiments.mujoco_medium
    python -m experiments.mujoco_medium --alpha 2.5 10                                   # both alphas, one program
    python -m experiments.mujoco_medium --preset authors                                 # the authors' code's setup
    python -m experiments.mujoco_medium --env walker2d --algo edac --updates 50000
    python -m experiments.mujoco_medium --pretrain actor critic actor+critic none      # Appendix C ablation
    python -m experiments.mujoco_medium --study paper                                    # 3 envs x TD3+BC/EDAC, 1M
"""
from __future__ import annotations

from offrl_jax.app.command import run_command
from offrl_jax.app.studies import ENVS, HPARAM_DESTS, given, make_study, parser
from offrl_jax.run.study import Study
from offrl_jax.system.cli import UsageError

PAPER_FIXED = ("env", "algo", "level", "updates", "eval_every")  # what --study paper sets itself


def build(args) -> Study | list[Study]:
    if args.study == "paper":
        defaults, typed = make_parser(), getattr(args, "typed", frozenset())  # typed: set by the command line
        changed = [f"--{d.replace('_', '-')}" for d in PAPER_FIXED
                   if d in typed or getattr(args, d) != defaults.get_default(d)]
        if changed:
            them = "them" if len(changed) > 1 else "it"
            raise UsageError(f"--study paper sets {', '.join(changed)} itself; leave {them} out")
        return [make_study(env, algo, "medium", args, dict(updates=1_000_000, eval_every=10_000))
                for env in ENVS for algo in ("td3bc", "edac")]
    return make_study(args.env, args.algo, args.level, args)


def make_parser():  # the budget that fits 5 seeds in 30 minutes on 2 cores (module doc)
    p = parser("experiments.mujoco_medium", __doc__, updates=40_000, eval_every=2_500, seeds=5, eval_episodes=5,
               default_preset="published")
    p.add_argument_group("a whole study").add_argument(
        "--study", choices=("paper",), default=None,
        help="paper: 3 envs x {td3bc, edac} medium x --seeds seeds x 1M updates (evaluation every 10k), each in its "
             "own sub-directory; --env/--algo/--level/--updates/--eval-every other than their defaults are refused; "
             "a --preset applies to all of them")
    return p


def main(argv=None) -> int:
    return run_command(build, make_parser(), argv, hparams=given, hparam_dests=HPARAM_DESTS)


if __name__ == "__main__":
    from offrl_jax.system.cli import run_main

    run_main(main)
