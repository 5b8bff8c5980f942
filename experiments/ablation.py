"""Appendix C: ablation of actor and critic pre-training — actor-only vs critic-only vs actor+critic vs none.

Default (sized for a 2-core CPU): TD3+BC on hopper-medium, 3 seeds, 30k updates per variant, evaluation every 2.5k
(4 variants: ~40 min on 2 cores).  The paper: 1M updates.  RESULTS.md's ablations ran 5 seeds, 40k updates and alpha
2.5 (results/ablation/*/README.md has each command).

    python -m experiments.ablation [--env walker2d] [--algo edac] [--updates N]
"""

from offrl_jax.algos import ALGOS
from offrl_jax.app.command import run_command
from offrl_jax.app.studies import PRETRAIN, make_study, parser, pretrain_variants
from offrl_jax.system.cli import UsageError


def build(args):
    if args.algo == "bc":
        raise UsageError("--algo bc: the ablation compares pre-training modes, and the BC baseline has none to "
                         "compare (every update is a BC update); choose one of "
                         + ", ".join(a for a in ALGOS if a != "bc"))
    return make_study(args.env, args.algo, args.level, args, variants=pretrain_variants(args.algo, PRETRAIN, args),
                      reference="scratch", name=f"ablation-{args.env}-{args.level}-{args.algo}")


def make_parser():
    return parser("experiments.ablation", __doc__, updates=30_000, eval_every=2_500, omit=("pretrain",))


def main(argv=None) -> int:
    return run_command(build, make_parser(), argv)


if __name__ == "__main__":
    from offrl_jax.system.cli import run_main

    run_main(main)
