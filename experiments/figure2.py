"""Figure 2: hopper, halfcheetah, walker2d medium; TD3+BC and EDAC, each with and without pre-training.

CPU-sized defaults (the paper runs 1M updates on a GPU): TD3+BC 100k updates (10k pre-training) and EDAC with 10
critics for 30k updates (20k pre-training: 10k soft BC + 10k critic), 3 vmapped seeds.  EDAC's 10-critic updates run
at ~40/s on 2 CPU cores, which is what bounds its budget here.  Each (env, algo) pair goes to its own sub-directory.

    python -m experiments.figure2 [--envs hopper] [--algos td3bc] [--edac-updates 50000]
"""
import sys

from experiments.common import main_guard, positive_int
from experiments.mujoco_medium import ENVS, make_study, parser


def build(args):
    studies = []
    for env in args.envs:
        for algo in args.algos:
            if algo == "edac":
                args.num_critics = args.num_critics or 10
                extra = {"updates": args.edac_updates}
            else:
                extra = {}
            studies.append(make_study(env, algo, args.level, args, extra=extra, name=f"figure2-{env}-{algo}"))
    return studies


def main(argv=None) -> int:
    p = parser("experiments.figure2", __doc__)
    p.add_argument("--envs", nargs="+", choices=ENVS, default=list(ENVS))
    p.add_argument("--algos", nargs="+", choices=("td3bc", "edac"), default=["td3bc", "edac"])
    p.add_argument("--edac-updates", type=positive_int, default=30_000)
    return main_guard(build, p, argv)


if __name__ == "__main__":
    sys.exit(main())
