"""Appendix F: the Q-Transformer objective max(MC, r + gamma Q') throughout training vs our actor+critic
pre-training vs neither (TD3+BC).

Default (sized for a 2-core CPU; RESULTS.md's run used it on hopper-medium v0, results/qtransformer/): hopper-medium,
3 seeds, 20k updates per variant, evaluation every 2k (~30 min on one core).  The paper: 1M updates.

    python -m experiments.qtransformer [--env walker2d] [--updates N]
"""

from offrl_jax.app.command import run_command
from offrl_jax.app.studies import make_study, parser, study_variants


def build(args):
    # the max(MC, Q) target is TD3+BC's (`TD3BCConfig.target`)
    variants = (study_variants("pretrained", "td3bc", {"pretrain": "actor+critic"}, args)
                + study_variants("max(MC,Q) target", "td3bc", {"pretrain": "none", "target": "max_mc"}, args)
                + study_variants("scratch", "td3bc", {"pretrain": "none"}, args))
    return make_study(args.env, "td3bc", args.level, args, variants=variants, reference="scratch",
                      name=f"qtransformer-{args.env}-{args.level}-td3bc")


def make_parser():
    return parser("experiments.qtransformer", __doc__, updates=20_000, eval_every=2_000, omit=("pretrain", "algo"))


def main(argv=None) -> int:
    return run_command(build, make_parser(), argv)


if __name__ == "__main__":
    from offrl_jax.system.cli import run_main

    run_main(main)
