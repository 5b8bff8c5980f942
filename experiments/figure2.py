"""Figure 2: hopper, halfcheetah, walker2d medium; TD3+BC and EDAC, each with and without pre-training.

CPU-sized defaults (the paper runs 1M updates on a GPU): TD3+BC 100k updates (10k pre-training) and EDAC with 10
critics for 30k updates (20k pre-training: 10k soft BC + 10k critic), 3 vmapped seeds.  EDAC's 10-critic updates run
at ~40/s on 2 CPU cores, which is what bounds its budget here.  Each (env, algo) pair goes to its own sub-directory.

    python -m experiments.figure2 [--envs hopper] [--algos td3bc] [--edac-updates 50000]
"""
import sys

from experiments.common import main_guard, positive_int
from experiments.mujoco_medium import ENVS, LABELS, make_study, parser, pretrain_variants
from offrl_jax.runner import Variant


def build(args):
    studies = []
    for env in args.envs:
        for algo in args.algos:
            variants, extra = pretrain_variants(algo, args.pretrain, args), {}
            if algo == "edac":  # 10 critics on a CPU unless --num-critics says otherwise
                n = args.num_critics or 10
                variants = tuple(Variant.of(v.label, v.algo, **(dict(v.overrides) | {"num_critics": n}))
                                 for v in variants)
                extra = {"updates": args.edac_updates}
            studies.append(make_study(env, algo, args.level, args, extra=extra, variants=variants,
                                      reference=LABELS["none"] if "none" in args.pretrain else None,
                                      name=f"figure2-{env}-{algo}"))
    return studies


def make_parser():
    p = parser("experiments.figure2", __doc__)
    p.add_argument("--envs", nargs="+", choices=ENVS, default=list(ENVS))
    p.add_argument("--algos", nargs="+", choices=("td3bc", "edac"), default=["td3bc", "edac"])
    p.add_argument("--edac-updates", type=positive_int, default=30_000)
    return p


def main(argv=None) -> int:
    return main_guard(build, make_parser(), argv)


if __name__ == "__main__":
    sys.exit(main())
