"""A run's results: curves.csv IO, the per-variant summary (final score, asymptote, updates and seconds to 90 %,
peak and fall), its confidence intervals, the plot and the printed table, and merging runs of one study.
"""
from __future__ import annotations

import contextlib
import csv
import dataclasses
import io
import json
import math
import warnings
from pathlib import Path

import numpy as np

from offrl_jax.algos import make_config
from offrl_jax.checkpoint import atomic_write_bytes, atomic_write_text
from offrl_jax.study import Study, reference_label

CURVE_COLUMNS = ("variant", "algo", "seed", "phase", "update", "seconds", "score")  # then each metric logged


def write_curves(path: Path, rows: list[dict]) -> None:
    columns = list(dict.fromkeys([*CURVE_COLUMNS, *(k for row in rows for k in row)]))  # a header even without rows
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=columns, restval="")
    writer.writeheader()
    writer.writerows(rows)
    atomic_write_text(path, buffer.getvalue())


def read_curves(path: Path) -> list[dict]:
    """A curves.csv back as rows: seed and update as ints, text columns as text, the rest as floats; empty cells
    (a metric another variant logs) are left out."""
    ints, texts = {"seed", "update"}, {"variant", "algo", "phase"}
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        rows = []
        try:
            for row in reader:
                if None in row or None in row.values():  # more or fewer cells than the header: cut or edited
                    cells = sum(v is not None for k, v in row.items() if k is not None) + len(row.get(None, []))
                    raise ValueError(f"line {reader.line_num} has {cells} cells for "
                                     f"{len(reader.fieldnames or [])} columns (a truncated or edited file?)")
                rows.append({k: v if k in texts else int(v) if k in ints else float(v) for k, v in row.items()
                             if v != ""})
        except (ValueError, TypeError) as e:
            raise ValueError(f"{path}: not a curves.csv of this project ({e})") from None
    seeds: dict[str, set] = {}  # every evaluation holds every seed of its variant: a file cut at a line is refused
    at: dict[tuple, set] = {}
    for r in rows:
        if "variant" in r and "seed" in r and "update" in r:
            if r["seed"] in at.get((r["variant"], r["update"]), ()):
                raise ValueError(f"{path}: {r['variant']} seed {r['seed']} has two rows at update {r['update']} "
                                 "(rows of two runs mixed?)")
            seeds.setdefault(r["variant"], set()).add(r["seed"])
            at.setdefault((r["variant"], r["update"]), set()).add(r["seed"])
    for (variant, update), have in at.items():
        if seeds[variant] - have:
            raise ValueError(f"{path}: {variant} at update {update} has no row for seed(s) "
                             f"{', '.join(map(str, sorted(seeds[variant] - have)))} (a truncated or edited file?)")
    return rows


def check_curve_seeds(path: Path, rows: list[dict], seeds) -> None:
    """Raise ValueError (one line) if a variant of curves.csv rows holds other seeds than its run's `seeds`."""
    for variant in sorted({r["variant"] for r in rows if "variant" in r}):
        found = {r["seed"] for r in rows if r.get("variant") == variant and "seed" in r}
        if found != set(seeds):
            raise ValueError(f"{path}: {variant} has seeds {', '.join(map(str, sorted(found)))} where its run has "
                             f"{', '.join(map(str, seeds))} (rows of another run?)")


def short_curves(rows: list[dict], budgets: dict[str, int]) -> dict[str, int | None]:
    """The variants whose evaluations in curves.csv `rows` end before their budget of updates (TD3 may trim an odd
    budget by 1): {variant: its last evaluated update, None when it has none}."""
    last = {label: max((r["update"] for r in rows if r.get("variant") == label and "update" in r), default=None)
            for label in budgets}
    return {label: u for label, u in last.items() if u is None or u < budgets[label] - 1}


def pretrain_ends_of(rows: list[dict]) -> dict[str, int]:
    """Per variant, the last evaluation before offline RL (0 if none): what `run_study` records as its
    pre-training end (for BC, whose whole run is actor pre-training, the last evaluation)."""
    ends: dict[str, int] = {}
    for r in rows:
        ends.setdefault(r["variant"], 0)
        if r.get("phase", "offline_rl") != "offline_rl":
            ends[r["variant"]] = max(ends[r["variant"]], r["update"])
    return ends


def merge_runs(run_dirs: list[Path], out_dir: Path) -> list[dict]:
    """One study from runs of it that each trained some of its variants (say one process per variant on a GPU):
    their variants and curves side by side in `out_dir` (config.json, curves.csv, summary.json, curves.png),
    re-summarised, so that the from-scratch asymptote and the updates to 90 % of it reach every variant.  The runs
    must agree on everything but their variants (and checkpoint interval); `out_dir` must not hold a run yet."""
    if (out_dir / "config.json").exists():
        raise FileExistsError(f"{out_dir} already holds a run; merge into a new directory")
    studies = []
    for d in run_dirs:
        if not (d / "config.json").exists() or not (d / "curves.csv").exists():
            raise FileNotFoundError(f"{d}: not a run directory (config.json and curves.csv expected)")
        try:
            studies.append(Study.from_json((d / "config.json").read_text()))
        except ValueError as e:
            raise ValueError(f"{d / 'config.json'}: {e}") from None
    own = ("variants", "reference", "checkpoint_every", "keep_checkpoints")
    shared = [{k: v for k, v in dataclasses.asdict(s).items() if k not in own} for s in studies]
    for d, fields in zip(run_dirs[1:], shared[1:]):
        if differ := [k for k in fields if fields[k] != shared[0][k]]:
            raise ValueError(f"{d} is not the same study as {run_dirs[0]}: {', '.join(differ)} differ")
    variants = tuple(v for s in studies for v in s.variants)
    # a run without the from-scratch variant names no reference; the one that trained it does
    references = sorted({s.reference for s in studies if s.reference is not None})
    if len(references) > 1:
        raise ValueError(f"the runs name different reference variants: {', '.join(references)}")
    reference = references[0] if references else None
    study = dataclasses.replace(studies[0], variants=variants, reference=reference)  # checks labels are unique
    rows = []
    for d, s in zip(run_dirs, studies):
        mine = read_curves(d / "curves.csv")
        check_curve_seeds(d / "curves.csv", mine, s.seeds)
        short = short_curves(mine, {v.label: s.updates for v in s.variants})
        if short:
            raise ValueError(f"{d / 'curves.csv'}: ends before the run's {s.updates:,} updates ("
                             f"{', '.join(f'{label} at {u or 0:,}' for label, u in short.items())}); merge finished "
                             "runs")
        rows += mine
    ends = pretrain_ends_of(rows)
    summary = summarize(study, rows, ends)
    out_dir.mkdir(parents=True, exist_ok=True)
    records = [r for d in run_dirs for r in json.loads((d / "config.json").read_text()).get("runs", [])]
    atomic_write_text(out_dir / "config.json", study.record_json(previous=json.dumps({"runs": records})))
    write_curves(out_dir / "curves.csv", rows)
    atomic_write_text(out_dir / "summary.json", summary_json(summary))
    plot_curves(out_dir / "curves.png", study, rows, ends)
    return summary


T95 = {1: 12.706, 2: 4.303, 3: 3.182, 4: 2.776, 5: 2.571, 6: 2.447, 7: 2.365, 8: 2.306, 9: 2.262, 10: 2.228}


def t975(df: int) -> float:
    """Student-t 97.5 % quantile: exact table to df = 10, then the Cornish-Fisher expansion (error < 0.1 %)."""
    if df in T95:
        return T95[df]
    z = 1.959964
    return z + (z**3 + z) / (4 * df) + (5 * z**5 + 16 * z**3 + 3 * z) / (96 * df**2)


def ci95(values: np.ndarray) -> float:
    """Half-width of the 95 % t-interval of the mean of the finite values (0 for a single value)."""
    values = values[np.isfinite(values)]
    if len(values) < 2:
        return 0.0
    return float(t975(len(values) - 1) * values.std(ddof=1) / math.sqrt(len(values)))


def score_matrix(rows: list[dict], label: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(updates (E,), seconds (E,), scores (S, E)) of one variant."""
    mine = [r for r in rows if r["variant"] == label]
    updates = np.array(sorted({r["update"] for r in mine}))
    seeds = sorted({r["seed"] for r in mine})
    scores = np.full((len(seeds), len(updates)), np.nan)
    seconds = np.zeros(len(updates))
    for r in mine:
        j = int(np.searchsorted(updates, r["update"]))
        scores[seeds.index(r["seed"]), j] = r["score"]
        seconds[j] = r["seconds"]
    return updates, seconds, scores


def summarize(study: Study, rows: list[dict], pretrain_ends: dict[str, int]) -> list[dict]:
    """Per variant: final score (per seed, the mean of the last 10 % of evaluations, or of those inside
    `final_window`; then mean and 95 % CI over seeds), the from-scratch asymptote, and the first evaluation at which
    the seed-mean reaches 90 % of it (in a sweep: of the reference with the same swept value)."""
    with all_nan_expected():
        return _summarize(study, rows, pretrain_ends)


@contextlib.contextmanager
def all_nan_expected():
    """No RuntimeWarning for the NaN means of all-NaN data (no reference, every seed diverged there): a NaN in a
    summary, a gap in a curve."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        yield


def _summarize(study: Study, rows: list[dict], pretrain_ends: dict[str, int]) -> list[dict]:
    finals = {}
    for v in study.variants:
        updates, _, scores = score_matrix(rows, v.label)
        if study.final_window:
            keep = (updates >= study.final_window[0]) & (updates <= study.final_window[1])
        else:
            keep = np.arange(len(updates)) >= len(updates) - max(1, int(round(0.1 * len(updates))))
        # a seed that diverged before or inside the window has NaN there, so its final is NaN (not the mean of
        # its evaluations before it diverged): it is left out of the mean and listed in seeds_diverged
        finals[v.label] = scores[:, keep].mean(axis=1) if keep.any() else np.full(len(study.seeds), np.nan)
    summary = []
    for v in study.variants:
        reference = reference_label(study, v.label)
        asymptote = float(np.nanmean(finals[reference])) if reference else float("nan")
        trend = _trend(np.nanmean(score_matrix(rows, reference)[2], axis=0)) if reference else None
        updates, seconds, scores = score_matrix(rows, v.label)
        threshold = asymptote - 0.1 * abs(asymptote)  # 90 % of a positive asymptote; below a negative one too
        reached = np.flatnonzero(np.nanmean(scores, axis=0) >= threshold) if len(updates) else []
        config = make_config(v.algo, study.env, study.dataset, **dict(v.overrides))
        mean_curve = np.nanmean(scores, axis=0) if len(updates) else np.array([np.nan])
        peak = int(np.nanargmax(mean_curve)) if np.isfinite(mean_curve).any() else None
        summary.append({
            "variant": v.label, "env": study.env, "dataset": study.dataset, "algo": v.algo,
            "pretrain": getattr(config, "pretrain", "none"), "seeds": list(study.seeds), "updates": study.updates,
            "final_score_mean": float(np.nanmean(finals[v.label])), "final_score_ci95": ci95(finals[v.label]),
            "final_score_std": float(np.nanstd(finals[v.label], ddof=1)) if len(study.seeds) > 1 else 0.0,
            "asymptote": asymptote,
            # seed-mean of the reference over its last 20 % of evaluations minus the 20 % before: far from 0 means
            # the "asymptote" is not one yet (the budget ended while the reference was still moving)
            "asymptote_trend": trend,
            "updates_to_90pct": int(updates[reached[0]]) if len(reached) else None,
            # training wall-clock of the program that trained this variant: in a vmapped sweep, the whole group's
            "seconds_to_90pct": float(seconds[reached[0]]) if len(reached) else None,
            "pretrain_updates": pretrain_ends.get(v.label, 0),
            # the seed-mean curve's best evaluation, and how far the final score is below it (the paper's
            # stability question: does a variant stay up?)
            "peak_score_mean": float(mean_curve[peak]) if peak is not None else float("nan"),
            "peak_update": int(updates[peak]) if peak is not None else None,
            "fall_from_peak": float(mean_curve[peak] - np.nanmean(finals[v.label])) if peak is not None
            else float("nan"),
            # seeds whose final score is not finite (diverged and stopped): the mean and CI above leave them out
            "seeds_diverged": [seed for seed, f in zip(study.seeds, finals[v.label]) if not np.isfinite(f)],
            "overrides": dict(v.overrides),
            "config": dataclasses.asdict(config),
        })
    return summary


def summary_json(summary: list[dict]) -> str:
    """summary.json text: NaN (no asymptote, every seed diverged) becomes null, which JSON has and NaN is not."""
    def clean(x):
        if isinstance(x, float) and not math.isfinite(x):
            return None
        if isinstance(x, dict):
            return {k: clean(v) for k, v in x.items()}
        return [clean(v) for v in x] if isinstance(x, list) else x
    return json.dumps(clean(summary), indent=2)


def _trend(curve: np.ndarray) -> float | None:
    k = max(1, int(round(0.2 * len(curve))))
    if len(curve) < 2 * k or not np.isfinite(curve[-2 * k:]).any():
        return None
    return float(np.nanmean(curve[-k:]) - np.nanmean(curve[-2 * k:-k]))


@all_nan_expected()
def plot_curves(path: Path, study: Study, rows: list[dict], pretrain_ends: dict[str, int]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for i, v in enumerate(study.variants):
        updates, _, scores = score_matrix(rows, v.label)
        if not len(updates):
            continue
        mean = np.nanmean(scores, axis=0)
        half = np.array([ci95(scores[:, j]) for j in range(len(updates))])
        line, = ax.plot(updates, mean, label=v.label, color=f"C{i}")
        ax.fill_between(updates, mean - half, mean + half, alpha=0.2, color=f"C{i}")
        if pretrain_ends.get(v.label):
            ax.axvline(pretrain_ends[v.label], color=line.get_color(), ls=":", lw=1)
    ax.set_xlabel("updates (pre-training included; dotted: end of pre-training)")
    ax.set_ylabel("D4RL-normalised score")
    ax.set_title(f"{study.name}: {study.dataset}, {len(study.seeds)} seeds, mean and 95% CI")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=120)
    plt.close(fig)
    atomic_write_bytes(path, buffer.getvalue())


def summary_table(summary: list[dict]) -> str:
    """One markdown table.  In a sweep each variant has its own reference (the scratch run with the same swept
    value), so when the asymptotes differ they get a column instead of the header."""
    first = summary[0]
    known = [s for s in summary if _known(s["asymptote"])]
    asymptotes = {round(s["asymptote"], 6) for s in known}
    per_variant = len(asymptotes) > 1
    head = f"{first['dataset']}, {len(first['seeds'])} seeds, {first['updates']:,} updates per variant"
    if per_variant:
        head += "; asymptote (final of the from-scratch run with the same swept value) per variant"
    elif not asymptotes:
        head += "; no from-scratch asymptote (no reference variant, or every seed of it diverged)"
    else:
        trend = known[0].get("asymptote_trend")
        head += (f"; asymptote (from-scratch final) {known[0]['asymptote']:.1f}"
                 + (f", its trend over the last 20 % of evaluations {trend:+.1f}" if trend is not None else ""))
    cols = "| variant | final score | updates to 90 % | seconds to 90 % | pre-training updates | peak (fall to final) |"
    rule = "|---|--:|--:|--:|--:|--:|"
    if per_variant:
        cols, rule = cols + " asymptote (trend) |", rule + "--:|"
    lines = [head, "", cols, rule]
    for s in summary:
        u = "never" if s["updates_to_90pct"] is None else f"{s['updates_to_90pct']:,}"
        t = "never" if s["seconds_to_90pct"] is None else f"{s['seconds_to_90pct']:.0f}"
        gone = s.get("seeds_diverged") or []  # older summaries lack the key
        variant = s["variant"] + (f" ({len(gone)} seed(s) diverged, not in the mean)" if gone else "")
        final = f"{s['final_score_mean']:.1f} ± {s['final_score_ci95']:.1f}" if _known(s["final_score_mean"]) else "n/a"
        peak = s.get("peak_score_mean")  # older summaries lack it
        peak = (f"{peak:.1f} at {s['peak_update']:,} ({s['fall_from_peak']:.1f})" if _known(peak) else "n/a")
        row = (f"| {variant} | {final} | {u} | {t} | "
               f"{s['pretrain_updates']:,} | {peak} |")
        if per_variant:
            tr = s.get("asymptote_trend")
            row += (f" {s['asymptote']:.1f}" if _known(s["asymptote"]) else " n/a") + (
                f" ({tr:+.1f})" if tr is not None else "") + " |"
        lines.append(row)
    return "\n".join(lines)


def _known(x) -> bool:
    """A number summary.json has (null, or NaN in older files, where there is none)."""
    return x is not None and x == x


def print_table(summary: list[dict]) -> None:
    print(summary_table(summary))
