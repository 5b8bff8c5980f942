"""Appendix B: LayerNorm in the actor only / critic only / both / neither (TD3+BC, no pre-training).

Default (sized for a 2-core CPU): TD3+BC on hopper-medium and halfcheetah-medium, 3 seeds, 20k updates per
variant, evaluation every 2k (8 runs in all: ~1 hour on 2 cores; pass --env to run one env).  The paper: 1M updates.

    python -m experiments.layernorm [--env hopper] [--updates N]
"""

from offrl_jax.app.command import run_command
from offrl_jax.app.studies import make_study, parser, study_variants

COMBOS = {"LN actor+critic": (True, True), "LN actor only": (True, False), "LN critic only": (False, True),
          "no LN": (False, False)}


def build(args):
    envs = [args.env] if args.env else ["hopper", "halfcheetah"]
    studies = []
    for env in envs:
        variants = tuple(v for label, (a, c) in COMBOS.items()
                         for v in study_variants(label, args.algo, {"pretrain": "none", "actor_layer_norm": a,
                                                                    "critic_layer_norm": c}, args, env=env))
        studies.append(make_study(env, args.algo, args.level, args, variants=variants, reference="LN actor+critic",
                                  name=f"layernorm-{env}-{args.level}-{args.algo}"))
    return studies if len(studies) > 1 else studies[0]


def make_parser():
    p = parser("experiments.layernorm", __doc__, updates=20_000, eval_every=2_000, env=None,
               omit=("pretrain", "actor_layer_norm", "critic_layer_norm"))
    for action in p._actions:
        if action.dest == "env":
            action.help = "run on this MuJoCo task only (default: hopper and halfcheetah, one study each)"
    return p


def main(argv=None) -> int:
    return run_command(build, make_parser(), argv)


if __name__ == "__main__":
    from offrl_jax.system.cli import run_main

    run_main(main)
