"""Appendix E: pre-training on the medium-replay and full-replay datasets (TD3+BC, with and without).

These datasets come from the SAC training runs (`python -m offrl_jax.datasets generate hopper-medium-replay`
trains SAC to the medium checkpoint first if it has not been run).  Default: hopper, both levels, 3 vmapped seeds,
100k updates per variant.

    python -m experiments.replay [--env walker2d] [--levels medium-replay]
"""
import sys

from experiments.common import main_guard
from experiments.mujoco_medium import make_study, parser


def build(args):
    return [make_study(args.env, args.algo, level, args, name=f"replay-{args.env}-{level}-{args.algo}")
            for level in args.levels]


def make_parser():
    p = parser("experiments.replay", __doc__)
    p.add_argument("--levels", nargs="+", choices=("medium-replay", "full-replay"),
                   default=["medium-replay", "full-replay"])
    return p


def main(argv=None) -> int:
    return main_guard(build, make_parser(), argv)


if __name__ == "__main__":
    sys.exit(main())
