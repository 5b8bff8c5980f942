"""Adroit door (Tables 2 and 5, door-human and door-cloned rows): BC, CQL, TD3+BC, EDAC and the paper's hybrids
TD3+BC+CQL and EDAC+BC, the hybrids with and without pre-training.

The paper's protocol: 300k updates (200k of pre-training for the pre-trained hybrids), evaluation every 10k updates,
10 episodes each, with the 300-step time limit and the re-computed random score (-84.52); the reported score is the
mean of the evaluations between 200k and 300k updates (both ends included: 11 evaluations, the first at the end
of pre-training), over 4 seeds (mean +- std).  `--scale` shrinks every update count by the same factor for a CPU
(default 0.1: 30k updates, 20k pre-training, window 20k-30k, evaluation every 1k); `--scale 1` is the paper's
protocol.  EDAC(+BC) uses the paper's 50 critics and eta 200 unless told otherwise.  TD3+BC's alpha is the
paper's 0.1 (Table 3), also with `--preset authors`; `--preset published` gives TD3+BC's published 2.5, and the
authors' door config has 1.0 (`--alpha 1`).

    python -m experiments.adroit_door [--dataset door-human] [--variants BC "pre-trained TD3+BC+CQL"] [--scale 1]
        [--seeds 4]
"""
import argparse

from offrl_jax.algos import PRESETS, env_defaults
from offrl_jax.app.command import run_command
from offrl_jax.app.flags import run_args
from offrl_jax.app.studies import study_fields
from offrl_jax.losses import BALANCES
from offrl_jax.run.study import Study, Variant
from offrl_jax.system.cli import OneLineParser, number, positive_int

# label -> (algorithm, pre-training)
VARIANTS = {
    "BC": ("bc", None),
    "CQL": ("cql", "none"),
    "TD3+BC": ("td3bc", "none"),
    "EDAC": ("edac", "none"),
    "TD3+BC+CQL": ("td3bc_cql", "none"),
    "pre-trained TD3+BC+CQL": ("td3bc_cql", "actor+critic"),
    "EDAC+BC": ("edac_bc", "none"),
    "pre-trained EDAC+BC": ("edac_bc", "actor+critic"),
    # beyond the paper's table: the fine-tuning baselines of the Adroit benchmarks, with and without pre-training
    "Cal-QL": ("calql", "none"),
    "pre-trained Cal-QL": ("calql", "actor+critic"),
    "AWAC": ("awac", "none"),
    "pre-trained AWAC": ("awac", "actor+critic"),
}
PAPER_VARIANTS = list(VARIANTS)[:8]  # Table 2's rows


def build(args) -> Study:
    s = args.scale
    # the paper's protocol, scaled: 300k updates, evaluation every 10k, the score over the last 100k; pre-training
    # as long as the paper's per-env value (`offrl_jax.algos.ENV_DEFAULTS`: 200k on door)
    # (a family without a door value, AWAC: the hybrids')
    paper = env_defaults("td3bc_cql", "door")["pretrain_updates"]
    scaled = lambda algo: int(env_defaults(algo, "door").get("pretrain_updates", paper) * s)  # noqa: E731
    updates, pretrain, every = int(300_000 * s), scaled("td3bc_cql"), max(1, int(10_000 * s))
    variants = []
    for label in args.variants:
        algo, mode = VARIANTS[label]
        kw = {} if mode is None else {"pretrain": mode} | ({"pretrain_updates": scaled(algo)} if mode != "none" else {})
        flags = {}  # the flags that reach this variant
        if algo.startswith("edac") and args.num_critics:
            flags["num_critics"] = args.num_critics
        if args.alpha is not None and algo in ("td3bc", "td3bc_cql"):
            flags["alpha"] = args.alpha
        if args.balance is not None and algo in ("td3bc_cql", "edac_bc"):
            flags["balance"] = args.balance
        variants.append(Variant.make(label, algo, "door", args.dataset_path or args.dataset, args.preset, kw | flags,
                                     tuple(flags)))
    fields = study_fields(args) | {"updates": updates, "eval_every": every}
    return Study(name=f"adroit-{args.dataset}", dataset=args.dataset_path or args.dataset, env="door",
                 variants=tuple(variants), final_window=(pretrain, updates), **fields)


def make_parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog="experiments.adroit_door", description=__doc__,
                      formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--dataset", choices=("door-human", "door-cloned"), default="door-human",
                   help="the Adroit door dataset (default %(default)s); --dataset-path reads it from a file instead")
    p.add_argument("--variants", nargs="+", choices=tuple(VARIANTS), default=PAPER_VARIANTS,
                   help="the algorithms to compare, one variant each (default: the paper's eight; Cal-QL and AWAC, "
                        "with and without pre-training, on request)")
    p.add_argument("--scale", type=number(0, 10, low_open=True), default=0.1,
                   help="fraction of the paper's update counts, in (0, 10] (default 0.1)")
    p.add_argument("--num-critics", type=positive_int, default=None, help="EDAC(+BC) ensemble size (paper: 50)")
    p.add_argument("--alpha", type=number(0), default=None,
                   help="TD3+BC(+CQL) alpha (default: the paper's 0.1, or 2.5 with --preset published; the authors' "
                        "door config: 1.0)")
    p.add_argument("--balance", choices=BALANCES, default=None,
                   help="the hybrids' loss balancing: x/sg|x| (abs, default) or the authors' x/sg(x) (signed)")
    p.add_argument("--preset", choices=tuple(PRESETS), default=None,
                   help="authors: the authors' code switch by switch (docs/fidelity.md)")
    run_args(p, updates=None, eval_every=None, seeds=4)  # --scale sets both
    return p


def main(argv=None) -> int:
    return run_command(build, make_parser(), argv)


if __name__ == "__main__":
    from offrl_jax.system.cli import run_main

    run_main(main)
