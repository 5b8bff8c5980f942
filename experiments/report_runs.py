"""The runs a report reads: the summary.json files that the given directories hold (`listed_studies`), each refused
while a process is writing its run (`check_settled`) or where the run's other files contradict it (`check_run`),
and its summary with today's statistics (`run_summary`, recomputed from config.json and curves.csv where both are
there).  `experiments.report` prints what these return; `experiments.figures` redraws from `run_summary`.
"""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

from offrl_jax.app.outputs import replaced_dir
from offrl_jax.run.figures import behaviour_score
from offrl_jax.run.provenance import recorded_data
from offrl_jax.run.results import check_curve_algos, check_curve_seeds, pretrain_ends_of, read_curves, short_curves
from offrl_jax.run.study import Study
from offrl_jax.run.summary import resummarize, summarize
from offrl_jax.system.cli import being_written


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
