"""How faithful a generated MuJoCo dataset is to D4RL's: its behaviour score, behaviour cloning's score and TD3+BC's
from scratch, each beside D4RL's / CORL's published value (`offrl_jax.data.generate.reference`).

Two studies on one dataset, as CORL runs them: BC without LayerNorm (`--bc-updates`, default 20k: BC's score
settles within that on this data) and TD3+BC from scratch with alpha 2.5 and no LayerNorm (`--td3bc-updates`,
default 50k, about 20 minutes on one CPU core; CORL's scores are after 1M, so TD3+BC is compared at a twentieth of
CORL's budget).  5 seeds each; the score of a study is the IQM of its seeds' final scores with a stratified-
bootstrap 95 % interval.  Each study goes to a sub-directory of the run directory; `fidelity.json` there holds the
table, which the command prints.

    python -m experiments.fidelity                                   # hopper-medium
    python -m experiments.fidelity --env walker2d --td3bc-updates 0  # behaviour and BC only
    python -m experiments.fidelity --dataset-path my-hopper.hdf5     # a file of your own, against hopper's reference
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from offrl_jax.app.command import run_command
from offrl_jax.app.flags import FLAG_FIELDS
from offrl_jax.app.studies import dataset_of, make_study, parser
from offrl_jax.data.generate.reference import CORL_UPDATES, D4RL_V2, target_band
from offrl_jax.run.study import Variant
from offrl_jax.system.checkpoint import atomic_write_text
from offrl_jax.system.cli import UsageError, int_at_least, positive_int

UPDATES, EVAL_EVERY = 20_000, 5_000  # the run flags' defaults, never used: build() sets each study's own budget
BC = dict(pretrain="actor", actor_layer_norm=False)  # the variants' own values, on the study's env
TD3BC = dict(pretrain="none", alpha=2.5, actor_layer_norm=False, critic_layer_norm=False)


def build(args):
    if args.updates != UPDATES or args.eval_every != EVAL_EVERY:
        raise UsageError("the fidelity command sets each study's budget itself: give --bc-updates / --td3bc-updates "
                         "instead of --updates / --eval-every")
    on = dict(env=args.env, dataset=dataset_of(args.env, args))
    studies = [make_study(args.env, "bc", args.level, args, variants=(Variant.make("BC", "bc", values=BC, **on),),
                          extra={"updates": args.bc_updates, "eval_every": args.bc_updates // 4}, name="bc")]
    if args.td3bc_updates:
        td3bc = Variant.make("TD3+BC from scratch", "td3bc", values=TD3BC, **on)
        studies.append(make_study(args.env, "td3bc", args.level, args, variants=(td3bc,),
                                  extra={"updates": args.td3bc_updates, "eval_every": args.td3bc_updates // 10},
                                  name="td3bc"))
    return studies


def make_parser():
    # the measure is CORL's settings: no hyper-parameter flags (a flag the variants' fixed values would override)
    p = parser("experiments.fidelity", __doc__, updates=UPDATES, eval_every=EVAL_EVERY, seeds=5, eval_episodes=10,
               omit=("algo", "pretrain", "pretrain_updates", "updates", "eval_every", "preset", *FLAG_FIELDS))
    p.add_argument("--bc-updates", type=positive_int, default=20_000, help="BC's updates (default %(default)s)")
    p.add_argument("--td3bc-updates", type=int_at_least(0), default=50_000,
                   help="TD3+BC's updates; 0 leaves TD3+BC out (default %(default)s)")
    return p


def row(name: str, summary: dict, reference) -> dict:
    """One measure: ours (IQM [low, high]) beside the reference and whether it falls in the target band."""
    iqm = summary["final_iqm"]
    low, high = target_band(reference)
    return {"measure": name, "ours": iqm["value"], "low": iqm["low"], "high": iqm["high"],
            "reference": reference, "band": [low, high], "within": low <= iqm["value"] <= high}


def table(out: Path, env: str, level: str) -> dict:
    """The fidelity rows of a finished run directory (`fidelity.json`'s content)."""
    ref = D4RL_V2.get(f"{env}-{level}", {})
    bc = json.loads((out / "bc" / "summary.json").read_text())[0]
    behaviour = bc["behaviour_score"]
    b_low, b_high = target_band(ref["normalized_score"]) if ref else (None, None)
    rows = [{"measure": "behaviour data", "ours": behaviour, "reference": ref.get("normalized_score"),
             "band": [b_low, b_high], "within": None if not ref else b_low <= behaviour <= b_high}]
    if ref:
        rows.append(row(f"BC, {bc['updates']:,} updates", bc, ref["bc"]))
        if (out / "td3bc" / "summary.json").exists():
            td3 = json.loads((out / "td3bc" / "summary.json").read_text())[0]
            rows.append(row(f"TD3+BC from scratch, {td3['updates']:,} updates", td3, ref["td3bc"]))
    return {"dataset": bc["dataset"], "env": env, "seeds": len(bc["seeds"]), "reference_updates": CORL_UPDATES,
            "rows": rows}


def print_table(result: dict) -> None:
    print(f"\n{result['dataset']}: ours (IQM of {result['seeds']} seeds' final scores, 95 % CI) beside D4RL's "
          f"behaviour score and CORL's last scores ({result['reference_updates'] // 1000}k updates, mean ± std)\n")
    print("| measure | ours | D4RL / CORL | target | within |")
    print("|---|--:|--:|--:|:-:|")
    for r in result["rows"]:
        ours = f"{r['ours']:.1f}" + (f" [{r['low']:.1f}, {r['high']:.1f}]" if r.get("low") is not None else "")
        ref = r["reference"]
        ref_text = "—" if ref is None else (f"{ref[0]:.1f} ± {ref[1]:.1f}" if isinstance(ref, (list, tuple))
                                           else f"{ref:.1f}")
        band = "—" if r["band"][0] is None else f"{r['band'][0]:.1f} – {r['band'][1]:.1f}"
        within = {True: "yes", False: "no", None: "—"}[r["within"]]
        print(f"| {r['measure']} | {ours} | {ref_text} | {band} | {within} |")


def main(argv=None) -> int:
    p = make_parser()
    args, _ = p.parse_known_args(argv)
    argv = list(argv) if argv is not None else sys.argv[1:]
    out = args.resume or args.out
    if out is None and args.config is None and not any(a in argv for a in ("-h", "--help")):
        out = Path("runs") / "fidelity" / f"{Path(args.dataset_path).stem if args.dataset_path else args.env}-" \
                                          f"{time.strftime('%Y%m%d-%H%M%S')}"
        argv += ["--out", str(out)]
    rc = run_command(build, p, argv)
    if rc == 0 and out is not None and (Path(out) / "bc" / "summary.json").exists():
        result = table(Path(out), args.env, args.level)
        atomic_write_text(Path(out) / "fidelity.json", json.dumps(result, indent=1))
        print_table(result)
    return rc


if __name__ == "__main__":
    from offrl_jax.system.cli import run_main

    run_main(main)
