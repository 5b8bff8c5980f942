"""Appendix E: pre-training on the medium-replay and full-replay datasets (TD3+BC, with and without).

These datasets come from the SAC training runs (`python -m offrl_jax.data generate hopper-medium-replay`
trains SAC to the medium checkpoint first if it has not been run).  Default (sized for a 2-core CPU): hopper
medium-replay, 3 seeds, 30k updates per variant, evaluation every 2.5k.  full-replay is every transition of
the 1M-step SAC run that produced the shipped `<env>-expert` checkpoint: it needs that checkpoint, and reads the run
from the cache (or trains it first: hours on a CPU).

    python -m experiments.replay [--env walker2d] [--levels medium-replay full-replay]
"""

from offrl_jax.app.command import run_command
from offrl_jax.app.studies import make_study, parser


def build(args):
    return [make_study(args.env, args.algo, level, args, name=f"replay-{args.env}-{level}-{args.algo}")
            for level in args.levels]


def make_parser():
    p = parser("experiments.replay", __doc__, updates=30_000, eval_every=2_500, omit=("level",))
    p.add_argument("--levels", nargs="+", choices=("medium-replay", "full-replay"),
                   default=["medium-replay"],
                   help="default medium-replay; full-replay needs a shipped <env>-expert and its 1M-step SAC run")
    return p


def main(argv=None) -> int:
    return run_command(build, make_parser(), argv)


if __name__ == "__main__":
    from offrl_jax.system.cli import run_main

    run_main(main)
