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

`--plot FIG.png` draws every study given as one panel of one figure (and FIG.pdf beside it), laid out as the
paper's Figure 2 (rows: environments, columns: algorithms) when each (environment, algorithm) is one study, or all
in one panel with `--overlay` (`offrl_jax.run.figures`):

    python -m experiments.report results/figure2/*-td3bc results/figure2/*-edac --plot figure2.png

`--figures` redraws every committed figure under results/figures/ from the runs its sources.json names
(`experiments.figures`).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from collections import defaultdict
from pathlib import Path

from offrl_jax.app.outputs import RUN_FILES, replaced_dir
from offrl_jax.run import claim
from offrl_jax.run.aggregate import aggregate, aggregate_table, arms, claims_table, not_poolable, plot_aggregate
from offrl_jax.run.figures import behaviour_score, plot_studies
from offrl_jax.run.merge import merge_runs, merged_differences
from offrl_jax.run.provenance import recorded_data
from offrl_jax.run.results import check_curve_algos, check_curve_seeds, pretrain_ends_of, read_curves, short_curves
from offrl_jax.run.study import Study
from offrl_jax.run.summary import resummarize, summarize, summary_table as table
from offrl_jax.system.cli import OneLineParser, being_written, check_writable_dir, check_writable_file, print_error


def summaries(path: Path) -> list[Path]:
    if (path / "summary.json").exists():
        return [path / "summary.json"]
    found = sorted(path.glob("*/summary.json"))
    if not found:
        raise FileNotFoundError(f"{path}: no summary.json here or in its sub-directories")
    return found


def check_settled(run: Path) -> None:
    """Refuse (ValueError, one line) a run directory that a process is writing now (a run, --resume or --overwrite;
    a study of a multi-study run is written under its parent's lock), or whose earlier run an interrupted
    --overwrite left aside: neither holds one run's finished results."""
    for d in (run, run.resolve().parent):
        if being_written(d):
            raise ValueError(f"{d} is being written by another process (a run, --resume or --overwrite); report it "
                             "once that ends")
    aside = replaced_dir(run.resolve())
    if aside.exists():
        raise ValueError(f"{run}: an --overwrite of it was stopped, and the run it was replacing is in {aside}; the "
                         f"next --resume or --overwrite of {run} gives it back (or removes it if the new run has a "
                         "checkpoint)")


def listed_studies(dirs: list[Path]) -> list[Path]:
    """Every summary.json that `dirs` hold (a run, or a directory of studies), each once: a study named twice,
    directly or inside a directory of studies also given, is refused."""
    seen: dict[Path, tuple[Path, Path]] = {}  # resolved -> (the directory given, the summary.json as found)
    for d in dirs:
        check_settled(d)
        for path in summaries(d):
            if path.parent != d:
                check_settled(path.parent)
            if path.resolve() in seen:
                raise ValueError(f"{path.parent} is given twice (in {seen[path.resolve()][0]} and in {d}; a study "
                                 "counts once)")
            seen[path.resolve()] = d, path
    return [path for _, path in seen.values()]


def read_summary(path: Path) -> list[dict]:
    """A summary.json: a list of one object per variant (anything else is refused with one line)."""
    try:
        summary = json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise ValueError(f"{path}: not valid JSON ({e})") from None
    if not isinstance(summary, list) or not summary or not all(isinstance(s, dict) and "variant" in s
                                                               for s in summary):
        raise ValueError(f"{path}: not a run's summary (a list of one object per variant expected)")
    return summary


def check_run(path: Path, summary: list[dict]) -> str | None:
    """Refuse (ValueError, one line) a summary.json that its run's other files contradict: a config.json that is not
    a saved study or lacks the summary's variants or seeds, a curves.csv that is cut or edited (`read_curves`),
    holds variants of another run, or ends before the summary's budget, or, for a partial run (its curves end
    before config.json's budget), runs past it.  A summary may cover some of the study's variants (a run stopped
    and summarised where it stopped): returned is what makes such a run partial, for its heading.  A summary.json
    alone (copied out of its run) is reported as it is."""
    run = path.parent
    variants = {s["variant"] for s in summary}
    known = variants
    if (run / "config.json").is_file():
        try:
            study = Study.from_json((run / "config.json").read_text())
        except (ValueError, KeyError, TypeError, AttributeError) as e:
            raise ValueError(f"{run / 'config.json'}: not a saved study ({e})") from None
        known = {v.label for v in study.variants}
        if variants - known:
            raise ValueError(f"{path} does not belong with {run / 'config.json'}: its variant(s) "
                             f"{', '.join(sorted(variants - known))} are not the study's")
        if any(list(s.get("seeds", study.seeds)) != list(study.seeds) for s in summary):
            raise ValueError(f"{path} does not belong with {run / 'config.json'}: other seeds")
        algos = {v.label: v.algo for v in study.variants}
        if other := next((s for s in summary if s.get("algo", algos[s["variant"]]) != algos[s["variant"]]), None):
            raise ValueError(f"{path} does not belong with {run / 'config.json'}: its {other['variant']} is "
                             f"{other['algo']}, the study's is {algos[other['variant']]}")
    if (run / "curves.csv").is_file():
        rows = read_curves(run / "curves.csv")
        if (run / "config.json").is_file():
            check_curve_seeds(run / "curves.csv", rows, study.seeds)
            check_curve_algos(run / "curves.csv", rows, study)
        extra = {r["variant"] for r in rows if "variant" in r} - known
        if extra:
            raise ValueError(f"{run / 'curves.csv'} holds variant(s) of another run: {', '.join(sorted(extra))}")
        budgets = {s["variant"]: s["updates"] if isinstance(s.get("updates"), int) else 0 for s in summary}
        for variant, last in short_curves(rows, budgets).items():
            if last is None:
                raise ValueError(f"{run / 'curves.csv'} has no evaluation of {variant}, which {path} reports")
            raise ValueError(f"{run / 'curves.csv'}: {variant}'s evaluations end at update {last}, before the "
                             f"{budgets[variant]} updates of {path} (a truncated file?)")
        if (run / "config.json").is_file() and (partial := short_curves(rows, dict.fromkeys(known, study.updates))):
            where = ", ".join(f"{label} {'has no evaluation' if u is None else f'stopped at update {u:,}'}"
                              for label, u in sorted(partial.items()))
            if any(last is not None and last > budgets[label] for label, last in _last(rows, budgets).items()):
                # evaluations past the summary's budget: a run stopped while --resume --updates N extended it
                raise ValueError(f"{run} is a partial run: {where}, of the {study.updates:,} updates in its "
                                 f"config.json (--resume {run} finishes it); its summary.json is of an earlier, "
                                 "shorter run")
            return f"partial: {where}, of {study.updates:,}; reported at the summary's budget"
    return None


def _last(rows: list[dict], budgets: dict[str, int]) -> dict[str, int | None]:
    """Each variant's last evaluated update in curves.csv `rows`."""
    return {label: max((r["update"] for r in rows if r.get("variant") == label and "update" in r), default=None)
            for label in budgets}


def run_summary(run: Path, dataset: str | None = None) -> list[dict]:
    """A run's summary with today's statistics, read and checked as the report reads it; a run that did not record
    its behaviour score gets the cached `dataset`'s (the version it trained on), not the current one's."""
    check_settled(run)
    summary = read_summary(run / "summary.json")
    if dataset and all(s.get("behaviour_score") is None for s in summary):
        summary = [s | {"behaviour_score": behaviour_score(dataset)} for s in summary]
    partial = check_run(run / "summary.json", summary)
    return current(run / "summary.json", summary, partial=partial is not None)


def current(path: Path, summary: list[dict], reference: bool = True, partial: bool = False) -> list[dict]:
    """The summary with today's statistics: recomputed from the run's config.json and curves.csv where both are
    there (the behaviour score as the run recorded it, else from the cached dataset), else summary.json as it is,
    if it has them (a summary.json copied out of its run)."""
    run = path.parent
    if (run / "config.json").is_file() and (run / "curves.csv").is_file():
        known = next((s["behaviour_score"] for s in summary if s.get("behaviour_score") is not None), None)
        if known is None and reference:
            known = recorded_behaviour(run, summary[0].get("dataset", ""))
        if partial:  # the variants and budget the summary was made for, not config.json's
            study, labels = Study.from_json((run / "config.json").read_text()), [s["variant"] for s in summary]
            study = dataclasses.replace(study, updates=max(s["updates"] for s in summary),
                                        variants=tuple(v for v in study.variants if v.label in labels),
                                        reference=study.reference if study.reference in labels else None)
            rows = [r for r in read_curves(run / "curves.csv") if r.get("variant") in labels]
            return summarize(study, rows, pretrain_ends_of(rows), known)
        return resummarize(run, known)
    if not all("final_iqm" in s for s in summary):
        raise ValueError(f"{path}: written before the interval statistics, and without its run's config.json and "
                         "curves.csv to recompute them")
    return summary


def recorded_behaviour(run: Path, dataset: str) -> float | None:
    """The behaviour score of the data a run trained on, for a run whose summary did not record it: the cached
    `dataset`'s where its fingerprint is the one the run's config.json recorded; None where the run recorded none
    (made before the records) or the cache now holds another version of it (a guess would set a false threshold)."""
    sha = recorded_data(run / "config.json")
    return None if sha is None else behaviour_score(dataset, sha)


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
            merge_runs(args.dirs, args.merge)
            if differ := merged_differences([Study.from_json((d / "config.json").read_text()) for d in args.dirs]):
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
