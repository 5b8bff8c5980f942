"""Markdown tables from finished runs' summary.json files (what RESULTS.md quotes).

    python -m experiments.report results/mujoco_medium/default results/figure2/*/

One table per run directory: variant, final score (mean ± 95 % CI over seeds), updates and seconds to 90 % of the
from-scratch asymptote, with the asymptote and its trend (see `offrl_jax.runner.summarize`).  A directory holding
several studies (sub-directories with a summary.json each) gives one table per study.  `--curves` adds the
seed-mean score at every evaluation (rows: variants, columns: updates) from the run's curves.csv.
"""
from __future__ import annotations

import csv
import json
import sys
from collections import defaultdict
from pathlib import Path

from experiments.common import OneLineParser


def summaries(path: Path) -> list[Path]:
    if (path / "summary.json").exists():
        return [path / "summary.json"]
    found = sorted(path.glob("*/summary.json"))
    if not found:
        raise FileNotFoundError(f"{path}: no summary.json here or in its sub-directories")
    return found


def table(summary: list[dict]) -> str:
    """One markdown table.  In a sweep each variant has its own reference (the scratch run with the same swept
    value), so when the asymptotes differ they get a column instead of the header."""
    first = summary[0]
    asymptotes = {round(s["asymptote"], 6) for s in summary if _known(s["asymptote"])}
    per_variant = len(asymptotes) > 1
    trend = first.get("asymptote_trend")
    head = f"{first['dataset']}, {len(first['seeds'])} seeds, {first['updates']:,} updates per variant"
    if per_variant:
        head += "; asymptote (final of the from-scratch run with the same swept value) per variant"
    elif not asymptotes:
        head += "; no from-scratch reference, so no asymptote"
    else:
        head += (f"; asymptote (from-scratch final) {first['asymptote']:.1f}"
                 + (f", its trend over the last 20 % of evaluations {trend:+.1f}" if trend is not None else ""))
    cols = "| variant | final score | updates to 90 % | seconds to 90 % | pre-training updates |"
    rule = "|---|--:|--:|--:|--:|"
    if per_variant:
        cols, rule = cols + " asymptote (trend) |", rule + "--:|"
    lines = [head, "", cols, rule]
    for s in summary:
        u = "never" if s["updates_to_90pct"] is None else f"{s['updates_to_90pct']:,}"
        t = "never" if s["seconds_to_90pct"] is None else f"{s['seconds_to_90pct']:.0f}"
        gone = s.get("seeds_diverged") or []  # older summaries lack the key
        variant = s["variant"] + (f" ({len(gone)} seed(s) diverged, not in the mean)" if gone else "")
        final = f"{s['final_score_mean']:.1f} ± {s['final_score_ci95']:.1f}" if _known(s["final_score_mean"]) else "n/a"
        row = (f"| {variant} | {final} | {u} | {t} | "
               f"{s['pretrain_updates']:,} |")
        if per_variant:
            tr = s.get("asymptote_trend")
            row += (f" {s['asymptote']:.1f}" if _known(s["asymptote"]) else " n/a") + (
                f" ({tr:+.1f})" if tr is not None else "") + " |"
        lines.append(row)
    return "\n".join(lines)


def _known(x) -> bool:
    """A number summary.json has (null, or NaN in older files, where there is none)."""
    return x is not None and x == x


def curve_table(curves: Path) -> str:
    """Seed-mean score per variant (rows) at every evaluation (columns) of a curves.csv."""
    scores: dict[str, dict[int, list[float]]] = defaultdict(lambda: defaultdict(list))
    with open(curves) as f:
        for row in csv.DictReader(f):
            if row["score"]:
                scores[row["variant"]][int(row["update"])].append(float(row["score"]))
    updates = sorted({u for per in scores.values() for u in per})
    label = lambda u: f"{u / 1000:g}k" if u >= 1000 else str(u)  # noqa: E731
    lines = ["| updates | " + " | ".join(label(u) for u in updates) + " |", "|---" * (len(updates) + 1) + "|"]
    for variant, per in scores.items():
        cells = [f"{sum(per[u]) / len(per[u]):.1f}" if per.get(u) else "" for u in updates]
        lines.append(f"| {variant} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = OneLineParser(prog="experiments.report", description=__doc__)
    p.add_argument("dirs", nargs="+", type=Path, help="run directories (or directories of studies)")
    p.add_argument("--curves", action="store_true", help="also the seed-mean score at every evaluation")
    args = p.parse_args(argv)
    try:
        for d in args.dirs:
            for path in summaries(d):
                print(f"### {path.parent}\n\n{table(json.loads(path.read_text()))}\n")
                if args.curves:
                    print(curve_table(path.parent / "curves.csv") + "\n")
    except (FileNotFoundError, json.JSONDecodeError, KeyError, IndexError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
