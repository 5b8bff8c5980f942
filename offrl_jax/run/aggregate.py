"""Across studies (tasks): aggregate scores with stratified-bootstrap intervals, the probability of improvement,
performance profiles and sample-efficiency curves (Agarwal et al. 2021), from the studies' summaries and curves.

Each study is one task and every variant label one arm; an arm is aggregated over the studies that all have it.
Every (task, arm) is a stratum of the bootstrap: its seeds are resampled on their own, so tasks may have different
numbers of seeds.  The per-seed numbers come from summary.json (`final_scores`, `auc_scores`), the curves from
curves.csv.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from offrl_jax.run import bc_level, stats
from offrl_jax.run.results import all_nan_expected, score_matrix, write_figure


def arms(summaries: list[list[dict]]) -> list[str]:
    """The variant labels every study has, in the first study's order."""
    common = set.intersection(*({s["variant"] for s in summary} for summary in summaries))
    return [s["variant"] for s in summaries[0] if s["variant"] in common]


def not_poolable(summaries: list[list[dict]], names: list[str], starts: list[str | None] | None = None
                 ) -> str | None:
    """Why the studies' common arms cannot be pooled, or None: an arm that is a different algorithm in two studies
    (a "scratch" of TD3+BC beside one of EDAC), an arm fine-tuned online in one study and not in another (its final
    score is another measure), the same seeds' offline phases in two studies (`starts`: the run directory each
    study fine-tuned with `--from`, resolved, or None; `names` then resolved too), or the same runs in two studies (a
    run and a merge holding it: its seeds' final scores all equal)."""
    for i, start in enumerate(starts or []):
        if start is None:
            continue
        if start in names:
            return f"{names[i]} fine-tunes the runs of {start} (the same seeds' offline phases)"
        if (j := next((j for j in range(i) if (starts or [])[j] == start), None)) is not None:
            return f"{names[j]} and {names[i]} both fine-tune the runs of {start} (the same seeds' offline phases)"
    for arm in arms(summaries):
        mine = [next(s for s in summary if s["variant"] == arm) for summary in summaries]
        if len(algos := {s.get("algo") for s in mine}) > 1:
            return f"'{arm}' is {', '.join(sorted(map(str, algos)))} in different studies"
        online = [name for name, s in zip(names, mine) if s.get("online")]
        if online and len(online) < len(mine):
            offline = next(name for name, s in zip(names, mine) if not s.get("online"))
            return (f"'{arm}' is fine-tuned online in {online[0]} and not in {offline} (its final score is after "
                    "the online phase in one, the offline phases in the other)")
        seen: dict[tuple, str] = {}
        for name, s in zip(names, mine):
            key = tuple(s["final_scores"])
            if key in seen:
                return f"{seen[key]} and {name} hold the same runs of '{arm}'"
            seen[key] = name
    return None


def comparisons(summaries: list[list[dict]]) -> list[tuple[str, str]]:
    """(variant, reference) pairs that every study compares (its `vs_reference`)."""
    pairs = None
    for summary in summaries:
        mine = {(s["variant"], s["vs_reference"]["reference"]) for s in summary if s.get("vs_reference")}
        pairs = mine if pairs is None else pairs & mine
    order = [(s["variant"], s["vs_reference"]["reference"]) for s in summaries[0] if s.get("vs_reference")]
    return [p for p in order if p in (pairs or set())]


def aggregate(summaries: list[list[dict]]) -> dict:
    """{arm: {"final_iqm", "final_mean", "auc_iqm"}: Estimate json} and {"variant vs reference": poi json}."""
    per = [{s["variant"]: s for s in summary} for summary in summaries]
    out: dict = {"tasks": len(summaries), "arms": {}, "poi": {}}
    for arm in arms(summaries):
        finals = [np.array(p[arm]["final_scores"], dtype=float) for p in per]
        aucs = [np.array(p[arm]["auc_scores"], dtype=float) for p in per]
        out["arms"][arm] = {"seeds": [len(f) for f in finals],
                            "final_iqm": stats.interval(finals, stats.pooled(stats.iqm)).to_json(),
                            "final_mean": stats.interval(finals, stats.pooled(stats.mean)).to_json(),
                            "auc_iqm": stats.interval(aucs, stats.pooled(stats.iqm)).to_json()}
    for variant, reference in comparisons(summaries):
        pairs = [(np.array(p[variant]["final_scores"], float), np.array(p[reference]["final_scores"], float))
                 for p in per]
        out["poi"][f"{variant} vs {reference}"] = stats.aggregate_poi(pairs).to_json()
    return out


def aggregate_table(result: dict) -> str:
    est = lambda d, fmt=".1f": stats.Estimate.from_json(d).text(fmt)  # noqa: E731
    lines = [f"Across {result['tasks']} studies (each a task; IQM and mean of every run of every task, "
             "stratified-bootstrap 95 % CI)", "", "| variant | runs | final score IQM | final score mean | "
             "mean over the run IQM |", "|---|--:|--:|--:|--:|"]
    for arm, a in result["arms"].items():
        lines.append(f"| {arm} | {sum(a['seeds'])} | {est(a['final_iqm'])} | {est(a['final_mean'])} | "
                     f"{est(a['auc_iqm'])} |")
    if result["poi"]:
        lines += ["", "| probability of improvement (final score, averaged over tasks) | P [95 % CI] |", "|---|--:|"]
        lines += [f"| {pair} | {est(p, '.2f')} |" for pair, p in result["poi"].items()]
    return "\n".join(lines)


def claims_table(summaries: list[list[dict]], names: list[str]) -> str:
    """One row per comparison of every study (`names`: how to call each): seeds, the headline threshold, the
    speed-up with its interval (`bc_level.ratio_text`: ≥, ≤ or no bound for censored seeds), the probability of
    improvement of the final score, the verdict, and the BC level with the speed-ups to the BC-relative thresholds
    (`bc_level.claim_cells`); a speed-up whose threshold the BC actor reached is flagged."""
    lines = ["| study | variant vs reference | seeds | headline threshold | speed-up (updates) | P(final better) | "
             "fewer updates? | BC level (seed mean) | speed-up to BC + 50 % to best | speed-up to BC + 90 % to best |",
             "|---|---|--:|---|--:|--:|---|--:|--:|--:|"]
    for name, summary in zip(names, summaries):
        for s in summary:
            vs = s.get("vs_reference")
            if not vs:
                continue
            head = next((x for x in vs["speedup"] if x["threshold"] == vs["headline"]), None)
            ratio = "n/a" if head is None else bc_level.speedup_text(head)
            threshold = "n/a" if head is None else f"{vs['headline']} ({head['score']:.1f})"
            verdict = {"holds": "yes", "does not hold": "no"}.get(vs["verdict"], vs["verdict"])
            lines.append(f"| {name} | {s['variant']} vs {vs['reference']} | {len(s['seeds'])} | {threshold} | "
                         f"{ratio} | {stats.Estimate.from_json(vs['poi_final']).text('.2f')} | {verdict} | "
                         + " | ".join(bc_level.claim_cells(s)) + " |")
    return "\n".join(lines + ["", bc_level.CLAIMS_NOTE])


def common_updates(curves: list[list[dict]], arm: str) -> np.ndarray:
    """The evaluation updates that every study's `arm` has."""
    grids = [set(score_matrix(rows, arm)[0].tolist()) for rows in curves]
    return np.array(sorted(set.intersection(*grids))) if grids else np.array([])


@all_nan_expected()
def plot_aggregate(summaries: list[list[dict]], curves: list[list[dict]], path: Path,
                   resamples: int = 2000) -> list[Path]:
    """Three panels, written as `path` (PNG) and its PDF: final-score IQM per arm with its interval, performance
    profiles (fraction of runs above each score) of the final score, and IQM sample-efficiency curves over the
    evaluations all studies share."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    result = aggregate(summaries)
    names = list(result["arms"])
    fig, (bars, profile, efficiency) = plt.subplots(1, 3, figsize=(14, 4))
    for i, arm in enumerate(names):
        e = stats.Estimate.from_json(result["arms"][arm]["final_iqm"])
        err = None if e.low is None else [[e.value - e.low], [e.high - e.value]]
        bars.barh(i, e.value, xerr=err, color=f"C{i}", capsize=4)
        finals = np.concatenate([[x for x in next(s for s in summary if s["variant"] == arm)["final_scores"]
                                  if x is not None] for summary in summaries]).astype(float)
        taus = np.linspace(min(0.0, np.nanmin(finals)), max(100.0, np.nanmax(finals)), 101)
        profile.plot(taus, stats.performance_profile(finals[np.isfinite(finals)], taus), color=f"C{i}", label=arm)
        updates = common_updates(curves, arm)
        if len(updates):
            per_task = []
            for rows in curves:
                u, _, scores = score_matrix(rows, arm)
                per_task.append(scores[:, np.isin(u, updates)])
            found = [stats.interval([t[:, j] for t in per_task], stats.pooled(stats.iqm), resamples=resamples)
                     for j in range(len(updates))]
            middle = np.array([f.value for f in found])
            efficiency.plot(updates, middle, color=f"C{i}", label=arm)
            efficiency.fill_between(updates, [f.value if f.low is None else f.low for f in found],
                                    [f.value if f.high is None else f.high for f in found], color=f"C{i}", alpha=0.2)
    bars.set_yticks(range(len(names)), names)
    bars.set_xlabel("final score, IQM over all runs (95 % CI)")
    profile.set_xlabel("score τ")
    profile.set_ylabel("fraction of runs with final score > τ")
    efficiency.set_xlabel("updates (pre-training included)")
    efficiency.set_ylabel("IQM score")
    for ax in (profile, efficiency):
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:  # the curves' panel is empty where the studies share no evaluation
            ax.legend(fontsize=8)
    fig.suptitle(f"{result['tasks']} studies; intervals: stratified bootstrap over each study's seeds", fontsize=9)
    fig.tight_layout()
    return write_figure(fig, path, dpi=110, pdf=True)
