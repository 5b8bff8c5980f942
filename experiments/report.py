"""Markdown tables from finished runs (what RESULTS.md quotes), and their aggregate across studies.

    python -m experiments.report results/mujoco_medium/default results/figure2/*/

Per run directory, the study's tables (`offrl_jax.run.summary`): per variant the final score, the last evaluation and
the mean over the run as IQM over seeds with stratified-bootstrap 95 % intervals, the BC level and the improvement
over it (`offrl_jax.run.bc_level`); against the from-scratch variant,
every seed's updates to each threshold (censored seeds counted at the budget), the speed-up with its interval, the
probability of improvement and the verdict on the paper's claim; then the paper's own measure (`offrl_jax.run.claim`):
each seed's sustained reach of 90 % and 95 % of the from-scratch arm's plateau (the first update at which its
trailing mean over the plateau's window is there), the plateau test, the speed-up beside the paper's "less than 1/2
of the training steps" (a speed-up above 2x), with each arm's final, best and last scores, the BC level and the
improvement over it, one row per comparison of every study given.  A run with config.json and curves.csv is
re-summarised from them, so runs made before these statistics existed get them too.  A directory holding several
studies (sub-directories with a summary.json each) gives one table per study.  `--curves` adds the seed-mean score
at every evaluation (rows: variants, columns: updates) from the run's curves.csv.

Given several studies, a last table aggregates them, each a task (`offrl_jax.run.aggregate`): IQM and mean of the final
scores of every run with stratified-bootstrap intervals, and the probability of improvement of each variant over
its reference averaged over tasks; `--aggregate FIG.png` draws it (interval bars, performance profiles, IQM
sample-efficiency curves) as FIG.png and FIG.pdf:

    python -m experiments.report results/figure2/*-td3bc results/mujoco_medium/default --aggregate td3bc.png

`--merge OUT` first merges the given run directories (one study, each run training some of its variants, e.g. one
process per variant on a GPU) into OUT, re-summarised across them (`offrl_jax.run.merge.merge_runs`), and reports OUT:

    python -m experiments.report --merge runs/door-all runs/door-BC runs/door-CQL

With `--relabel`, the runs may be of different algorithms on the same data and budget (say fine-tuning runs of
`experiments.finetune --algo calql` and `--algo td3bc`, each with a `pretrained` arm): every variant is labelled
`<algorithm>-<label>` (`calql-scratch`, `td3bc-pretrained`), the from-scratch reference is the one run's that has
it, relabelled, and the runs' study names may differ (the merged study is named after the dataset and the
algorithms, `hopper-medium-calql+td3bc`).  Everything else must agree as without it (seeds, updates, evaluations,
online settings, the data), and one table then compares every arm, with one threshold for all of them:

    python -m experiments.report --merge runs/ft-all --relabel runs/ft-calql runs/ft-td3bc runs/ft-iql

`--plot FIG.png` draws every study given as one panel of one figure (and FIG.pdf beside it), laid out as the
paper's Figure 2 (rows: environments, columns: algorithms) when each (environment, algorithm) is one study, or all
in one panel with `--overlay` (`offrl_jax.run.figures`):

    python -m experiments.report results/figure2/*-td3bc results/figure2/*-edac --plot figure2.png

`--figures` redraws every committed figure under results/figures/ from the runs its sources.json names
(`experiments.figures`).
"""
from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from pathlib import Path

from experiments.report_runs import check_run, check_settled, current, listed_studies, read_summary, run_summary
from offrl_jax.app.outputs import RUN_FILES
from offrl_jax.run import claim
from offrl_jax.run.aggregate import aggregate, aggregate_table, arms, claims_table, not_poolable, plot_aggregate
from offrl_jax.run.figures import plot_studies
from offrl_jax.run.merge import merge_runs, merged_differences, relabelled
from offrl_jax.run.results import read_curves
from offrl_jax.run.study import Study
from offrl_jax.run.summary import summary_table as table
from offrl_jax.system.cli import OneLineParser, check_writable_dir, check_writable_file, print_error


def fine_tuned(study_dirs: list[Path]) -> list[str | None]:
    """Per study, the run directory it fine-tuned with `--from` (config.json's `start_from`; named as given when it
    is one of `study_dirs`), or None."""
    given = {str(d.resolve()): str(d) for d in study_dirs}
    starts = []
    for d in study_dirs:
        try:
            start = json.loads((d / "config.json").read_text()).get("start_from")
        except (OSError, ValueError, AttributeError):
            start = None
        starts.append(None if start is None else given.get(start, start))
    return starts


def curve_table(curves: Path) -> str:
    """Seed-mean score per variant (rows) at every evaluation (columns) of a curves.csv."""
    scores: dict[str, dict[int, list[float]]] = defaultdict(lambda: defaultdict(list))
    for row in read_curves(curves):
        if "score" in row:  # read_curves leaves empty cells out
            scores[row["variant"]][row["update"]].append(row["score"])
    updates = sorted({u for per in scores.values() for u in per})
    label = lambda u: f"{u / 1000:g}k" if u >= 1000 else str(u)  # noqa: E731
    lines = ["| updates | " + " | ".join(label(u) for u in updates) + " |", "|---" * (len(updates) + 1) + "|"]
    for variant, per in scores.items():
        cells = [f"{sum(per[u]) / len(per[u]):.1f}" if per.get(u) else "" for u in updates]
        lines.append(f"| {variant} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = OneLineParser(prog="experiments.report", description=__doc__,
                      formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("dirs", nargs="*", type=Path, help="run directories (or directories of studies)")
    p.add_argument("--figures", action="store_true",
                   help="redraw every figure of results/figures/sources.json from its runs (no directories)")
    p.add_argument("--curves", action="store_true", help="also the seed-mean score at every evaluation")
    p.add_argument("--merge", type=Path, metavar="OUT",
                   help="merge the run directories (one study, different variants) into OUT (a new directory)")
    p.add_argument("--relabel", action="store_true",
                   help="with --merge: runs of different algorithms (their study names may differ), each variant "
                        "labelled <algorithm>-<label> (td3bc-pretrained)")
    p.add_argument("--plot", type=Path, metavar="FIG.png", help="also draw every study as a panel of one figure")
    p.add_argument("--overlay", action="store_true", help="with --plot: every study in one panel")
    p.add_argument("--aggregate", type=Path, metavar="FIG.png",
                   help="also draw the aggregate of the studies given (IQM bars, performance profiles, IQM curves)")
    p.add_argument("--no-reference", action="store_true",
                   help="no behaviour-data score: no such threshold for a run that did not record it, no line in "
                        "--plot (finding it loads each cached dataset once)")
    p.add_argument("--overwrite", action="store_true",
                   help="let --plot / --aggregate replace figures that exist (their .png and .pdf)")
    args = p.parse_args(argv)
    try:
        if args.figures:
            if args.dirs or args.merge or args.plot or args.aggregate:
                raise ValueError("--figures draws the runs of results/figures/sources.json; give nothing else")
            from experiments import figures

            for path in figures.redraw(run_summary):
                print(f"figure: {path.relative_to(figures.ROOT)}", file=sys.stderr)
            return 0
        if not args.dirs:
            raise ValueError("give one or more run directories (or --figures)")
        seen = [d.resolve() for d in args.dirs]
        if len(set(seen)) < len(seen):
            twice = next(d for d, r in zip(args.dirs, seen) if seen.count(r) > 1)
            raise ValueError(f"{twice} is given twice (a study counts once)")
        if args.overlay and args.plot is None:
            raise ValueError("--overlay draws into the figure of --plot FIG.png; give --plot too")
        if args.relabel and not args.merge:
            raise ValueError("--relabel labels the variants of the runs --merge OUT joins; give --merge too")
        if args.merge:
            for d in args.dirs:
                check_settled(d)
        listed = [] if args.merge else listed_studies(args.dirs)
        if args.aggregate is not None:  # before any table is printed
            if args.merge:
                raise ValueError("--aggregate takes two or more studies (--merge makes one)")
            if len(listed) < 2:
                raise ValueError("--aggregate takes two or more studies")
            variants = [[s["variant"] for s in read_summary(path)] for path in listed]
            if not set.intersection(*map(set, variants)):
                raise ValueError("--aggregate: the studies have no variant in common, so nothing to aggregate ("
                                 + "; ".join(f"{path.parent}: {', '.join(v)}" for path, v in zip(listed, variants))
                                 + ")")
        if args.plot is not None and args.aggregate is not None and args.plot.resolve() == args.aggregate.resolve():
            raise ValueError(f"--plot and --aggregate both name {args.plot}: the second figure would replace the first")
        for flag, fig in (("--plot", args.plot), ("--aggregate", args.aggregate)):
            if fig is not None:
                if fig.suffix.lower() != ".png":
                    raise ValueError(f"{flag} {fig}: the name must end in .png")
                for path in (fig, fig.with_suffix(".pdf")):
                    if path.name in RUN_FILES and (path.parent / "config.json").is_file():
                        raise ValueError(f"{flag} {fig}: {path} is a run's own file; a report figure goes elsewhere "
                                         "(--overwrite replaces only a report's figures)")
                    if path.exists() and not args.overwrite:
                        raise FileExistsError(f"{flag}: {path} exists; pass --overwrite to replace it")
                    check_writable_file(path)
        if args.merge:
            if args.merge.is_dir() and any(args.merge.iterdir()):
                what = "already holds a run" if (args.merge / "config.json").exists() else "is not empty"
                raise FileExistsError(f"{args.merge} {what}; merge into a new directory")
            check_writable_dir(args.merge)
            merge_runs(args.dirs, args.merge, relabel=args.relabel)
            studies = [Study.from_json((d / "config.json").read_text()) for d in args.dirs]
            if differ := merged_differences([relabelled(s) for s in studies] if args.relabel else studies):
                print(f"warning: the merged variants differ in more than their pre-training: {'; '.join(differ)}",
                      file=sys.stderr)
            args.dirs = [args.merge]
            listed = listed_studies(args.dirs)
        study_dirs, found = [], []  # every study whose summary made a table: what --plot and the aggregate take
        for path in listed:
            try:
                summary = read_summary(path)
                partial = check_run(path, summary)
                summary = current(path, summary, reference=not args.no_reference, partial=partial is not None)
                text = table(summary)
            except (KeyError, TypeError, IndexError) as e:
                raise ValueError(f"{path}: not a run's summary (missing or empty {e})") from None
            print(f"### {path.parent}" + (f" ({partial})" if partial else "") + f"\n\n{text}\n")
            if args.curves:
                if not (path.parent / "curves.csv").is_file():
                    raise FileNotFoundError(f"{path.parent}: no curves.csv, which --curves reads")
                print(curve_table(path.parent / "curves.csv") + "\n")
            study_dirs.append(path.parent)
            found.append(summary)
        why = not_poolable(found, [str(d) for d in study_dirs], fine_tuned(study_dirs)) if len(found) > 1 else None
        if len(found) > 1:
            print(claims_table(found, [str(d) for d in study_dirs]) + "\n")
        if any(s.get("vs_reference") for summary in found for s in summary):  # the paper's measure, one row each
            print(claim.claims_table(found, [str(d) for d in study_dirs]) + "\n")
        if len(found) > 1:
            if arms(found) and why:
                print(f"No aggregate across these studies: {why}.\n")
            elif arms(found):
                print(aggregate_table(aggregate(found)) + "\n")
        if args.aggregate is not None:
            if why:
                raise ValueError(f"--aggregate: {why}; give studies whose arms are one algorithm and other runs")
            written = plot_aggregate(found, [read_curves(d / "curves.csv") for d in study_dirs], args.aggregate)
            print(f"aggregate figure: {', '.join(map(str, written))}", file=sys.stderr)
        if args.plot is not None:
            written = plot_studies(study_dirs, args.plot, reference=not args.no_reference, overlay=args.overlay,
                                   summaries=found)
            print(f"figure: {', '.join(map(str, written))}", file=sys.stderr)
    except (OSError, ValueError, KeyError, IndexError) as e:
        print_error(e)
        return 2
    return 0


if __name__ == "__main__":
    from offrl_jax.system.cli import run_main

    run_main(main)
