"""Appendix D: the TD weight lambda in critic pre-training, lambda in {0, 0.1, 0.5, 1}, plus no pre-training.

Default (sized for a 2-core CPU): TD3+BC on halfcheetah-medium (where the paper finds lambda > 0 smooths the
hand-over), 3 seeds, 20k updates per variant (10k pre-training), evaluation every 2k: 5 variants, ~45 min
on one core.  The paper: 1M updates.  `--lambda-mode target` uses eq. 5 target mixing instead of the authors' loss
mixing.

    python -m experiments.lambda_sweep [--env hopper] [--lambdas 0 0.1 0.5 1] [--lambda-mode target]
"""

from offrl_jax.app.command import run_command
from offrl_jax.app.studies import make_study, parser, study_variants


def build(args):
    variants = tuple(v for lam in args.lambdas
                     for v in study_variants(f"lambda={lam:g}", args.algo, {"pretrain": "actor+critic", "lam": lam},
                                             args))
    variants += study_variants("scratch", args.algo, {"pretrain": "none"}, args)
    return make_study(args.env, args.algo, args.level, args, variants=variants, reference="scratch",
                      name=f"lambda-{args.env}-{args.level}-{args.algo}")


def make_parser():
    p = parser("experiments.lambda_sweep", __doc__, updates=20_000, eval_every=2_000, env="halfcheetah",
               omit=("pretrain", "lam"))
    p.add_argument("--lambdas", type=float, nargs="+", default=[0.0, 0.1, 0.5, 1.0],
                   help="TD weights of critic pre-training to compare, each in [0, 1] (0: pure MC), one pre-trained "
                        "variant each, besides the one from scratch (default: 0 0.1 0.5 1)")
    return p


def main(argv=None) -> int:
    return run_command(build, make_parser(), argv)


if __name__ == "__main__":
    from offrl_jax.system.cli import run_main

    run_main(main)
