"""A study's summary (`summary.json`, one object per variant) and its printed tables, from curves.csv's rows.

Every measure is per seed first (`offrl_jax.run.stats`), then aggregated with a stratified-bootstrap 95 % interval:
- the final score (per seed the mean of the last 10 % of evaluations, or of those inside `final_window`), the last
  evaluation's score (never the best), and the mean score over the run (the area under the curve), each as IQM;
- per threshold, each seed's updates and seconds (pre-training included) to first reach it, a seed that never
  does censored at the budget; the thresholds: the behaviour data's score, 80/90/95 % of the best seed-mean
  evaluation of any variant, and 80/90/95 % of the from-scratch final where that is an asymptote (the interval of
  its change over the last 20 % of evaluations within +-5 % of their mean, `stats.trend_is_flat`);
- the BC level (`offrl_jax.run.bc_level`: the pre-trained actor's score at the hand-over, or a BC arm's final) and
  per seed the improvement over it, with BC + 50 % and BC + 90 % of the way to the best score as thresholds too, and
  per threshold the seeds that reached it by the BC actor, before any RL update;
- against the from-scratch reference: the speed-up (reference's mean updates / this variant's) with its interval,
  the probability of improvement of the final score, and whether the paper's claim (fewer updates) holds at the
  headline threshold: 90 % of the asymptote where there is one, else 90 % of the best score;
- the paper's own measure (`offrl_jax.run.claim`): each seed's sustained reach of 90 % and 95 % of the asymptote
  (its running mean there), and whether the speed-up's interval lies above 2x (under 1/2 of the updates, as the
  paper says), with how the plateau was found.
"""
from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np

from offrl_jax.run import bc_level, claim, stats
from offrl_jax.run.online_summary import online_table, summarize_online
from offrl_jax.run.results import (
    all_nan_expected,
    check_curve_algos,
    check_curve_seeds,
    pretrain_ends_of,
    read_curves,
    score_matrix,
)
from offrl_jax.run.study import Study, reference_label

FRACTIONS = (0.8, 0.9, 0.95)


def final_mask(study: Study, updates: np.ndarray) -> np.ndarray:
    """(E,) bool: the evaluations of `updates` (E,) the final score averages: those in `final_window`, or the last
    10 % of them (at least 1)."""
    if study.final_window:
        return (updates >= study.final_window[0]) & (updates <= study.final_window[1])
    return np.arange(len(updates)) >= len(updates) - max(1, int(round(0.1 * len(updates))))


def final_scores(study: Study, updates: np.ndarray, scores: np.ndarray) -> np.ndarray:
    """Per seed, the mean of its evaluations in `final_mask`; NaN for a seed that diverged before or inside the
    window (not the mean of its evaluations before it diverged)."""
    keep = final_mask(study, updates)
    return scores[:, keep].mean(axis=1) if keep.any() else np.full(len(scores), np.nan)


def behaviour_score(dataset) -> float | None:
    """The dataset's behaviour score: its episodes' mean D4RL-normalised return (None where it has no episode or
    no normalisation)."""
    from offrl_jax.envs.registry import normalized_score

    try:
        returns = dataset.episode_returns()
        score = float(np.mean(normalized_score(dataset.env, returns))) if len(returns) else float("nan")
    except (KeyError, ValueError, TypeError, AttributeError):
        return None
    return score if np.isfinite(score) else None


def summarize(study: Study, rows: list[dict], pretrain_ends: dict[str, int],
              behaviour: float | None = None) -> list[dict]:
    """One dict per variant (see the module doc); `behaviour` is the dataset's behaviour score, if known."""
    with all_nan_expected():
        summary = _summarize(study, rows, pretrain_ends, behaviour)
    if study.online is not None:  # the online phase's own measures (`offrl_jax.run.online_summary`)
        online = {o["variant"]: o for o in summarize_online(rows, [v.label for v in study.variants], study.seeds,
                                                            study.online.steps, behaviour)}
        for entry in summary:
            if entry["variant"] in online:
                entry["online"] = online[entry["variant"]]
    return summary


def _summarize(study: Study, rows: list[dict], pretrain_ends: dict[str, int], behaviour: float | None) -> list[dict]:
    curves = {v.label: score_matrix(rows, v.label, study.seeds) for v in study.variants}  # rows: the study's seeds
    finals = {label: final_scores(study, u, s) if len(u) else np.full(len(study.seeds), np.nan)
              for label, (u, _, s) in curves.items()}
    means = [np.nanmean(s, axis=0) for u, _, s in curves.values() if len(u)]
    best = max((float(np.nanmax(m)) for m in means if np.isfinite(m).any()), default=None)
    own = bc_level.own_levels(study, curves, finals, pretrain_ends)
    shared = bc_level.comparison_levels(study, own)
    summary = []
    for v in study.variants:
        updates, seconds, scores = curves[v.label]
        reference = reference_label(study, v.label)
        ref_curve = curves[reference][2] if reference and len(curves[reference][0]) else None
        found = claim.plateau(finals.get(reference), ref_curve)  # the reference's final, an asymptote where flat
        asymptote, trend, flat = found.level, found.trend, found.flat
        # the paper's measure: sustained reach over as many evaluations as the reference's level averages
        window = claim.window(int(final_mask(study, curves[reference][0]).sum())) if ref_curve is not None else 0
        thresholds = ([("behaviour data", behaviour)] if behaviour is not None else []) + [
            (f"{f:.0%} of best", stats.fraction_of(best, f)) for f in FRACTIONS if best is not None] + [
            (claim.threshold_name(f), stats.fraction_of(asymptote, f)) for f in FRACTIONS if flat] + (
            bc_level.thresholds(shared.get(v.label), best))
        config = study.config(v.label)
        mean_curve = np.nanmean(scores, axis=0) if len(updates) else np.array([np.nan])
        peak = int(np.nanargmax(mean_curve)) if np.isfinite(mean_curve).any() else None
        last = scores[:, -1] if len(updates) else np.full(len(study.seeds), np.nan)
        # the mean over the run; a diverged seed (final NaN) has none: left out, as from the finals
        auc = (np.where(np.isfinite(finals[v.label]), np.nanmean(scores, axis=1), np.nan) if len(updates)
               else np.full(len(study.seeds), np.nan))
        reach = []
        for name, value in thresholds if len(updates) else ():
            at, censored = stats.first_reach(updates, scores, value)
            reach.append({"threshold": name, "score": value, "updates": at.tolist(),
                          "seconds": [float(seconds[np.searchsorted(updates, u)]) for u in at],
                          "censored": censored.tolist()})
            if (by_bc := bc_level.by_bc_actor(at, censored, own.get(v.label), v.label)) is not None:
                reach[-1]["by_bc_actor"] = by_bc  # per seed: reached at or before the hand-over
        level = own.get(v.label) or shared.get(v.label)
        is_bc_arm = level is not None and level.source == v.label and level.update is None
        gain = bc_level.improvement(finals[v.label], level) if level is not None and not is_bc_arm else None
        summary.append({
            "variant": v.label, "env": study.env, "dataset": study.dataset, "algo": v.algo,
            "pretrain": getattr(config, "pretrain", "none"), "seeds": list(study.seeds), "updates": study.updates,
            "pretrain_updates": pretrain_ends.get(v.label, 0), "behaviour_score": behaviour,
            # per seed: what every aggregate below is computed from (and what a later aggregate across runs reads)
            "final_scores": finals[v.label].tolist(), "last_scores": last.tolist(), "auc_scores": auc.tolist(),
            "final_iqm": stats.interval([finals[v.label]], stats.iqm).to_json(),
            "final_mean": stats.interval([finals[v.label]], stats.mean).to_json(),
            "last_iqm": stats.interval([last], stats.iqm).to_json(),
            "auc_iqm": stats.interval([auc], stats.iqm).to_json(),
            "final_score_mean": float(np.nanmean(finals[v.label])),
            "asymptote": asymptote,  # the reference's mean final score
            # its mean change over the last 20 % of evaluations (against the 20 % before), and whether its interval
            # lies within +-5 % of their mean: only a flat one is an asymptote the thresholds may be fractions of
            "asymptote_trend": trend.to_json() if trend is not None else None, "asymptote_flat": flat,
            # the test's evaluations a side and margin; the paper's measure reads an asymptote only where it is flat
            # on at least claim.MIN_PER_SIDE a side, and each seed's sustained reach of 90 % and 95 % of it
            "asymptote_per_side": found.per_side, "asymptote_margin": found.margin, "paper_asymptote": found.paper,
            "sustained_reach": claim.sustained_reach(updates, scores, found, window, own.get(v.label), v.label),
            "best_score": best, "reach": reach,
            # the BC level this variant's improvement is measured from, the one its comparison's thresholds are
            # measured from (the same for most), and per seed the final score minus the first
            "bc_level": level.to_json() if level else None,
            "comparison_bc_level": shared[v.label].to_json() if v.label in shared else None,
            "improvement_over_bc": gain.tolist() if gain is not None else None,
            "improvement_iqm": stats.interval([gain], stats.iqm).to_json() if gain is not None else None,
            # the seed-mean curve's best evaluation, and how far the final score is below it (the paper's
            # stability question: does a variant stay up?)
            "peak_score_mean": float(mean_curve[peak]) if peak is not None else float("nan"),
            "peak_update": int(updates[peak]) if peak is not None else None,
            "fall_from_peak": float(mean_curve[peak] - np.nanmean(finals[v.label])) if peak is not None
            else float("nan"),
            # seeds whose final score is not finite (diverged and stopped): the aggregates leave them out
            "seeds_diverged": [seed for seed, f in zip(study.seeds, finals[v.label]) if not np.isfinite(f)],
            "overrides": v.given(),
            "config": dataclasses.asdict(config),
        })
    by_label = {s["variant"]: s for s in summary}
    for s in summary:
        reference = reference_label(study, s["variant"])
        if reference and reference != s["variant"]:
            s["vs_reference"] = compare(s, by_label[reference])
    return summary


def compare(mine: dict, ref: dict) -> dict:
    """This variant against its from-scratch reference: per threshold the speed-up in updates and in seconds
    (reference / this, censored seeds at the budget), the probability that its final score and its mean over
    the run are higher, and the verdict on the paper's claim at the headline threshold."""
    speedups = []
    for a, b in zip(mine["reach"], ref["reach"]):
        assert a["threshold"] == b["threshold"], (a["threshold"], b["threshold"])
        speedups.append({"threshold": a["threshold"], "score": a["score"],
                         "updates": stats.speedup(np.array(b["updates"]), np.array(a["updates"])).to_json(),
                         "seconds": stats.speedup(np.array(b["seconds"]), np.array(a["seconds"])).to_json(),
                         "censored": sum(a["censored"]), "reference_censored": sum(b["censored"]),
                         "by_bc_actor": sum(a.get("by_bc_actor") or []), "seeds": len(a["censored"])})
    names = [s["threshold"] for s in speedups]
    headline = claim.threshold_name(0.9) if claim.threshold_name(0.9) in names else (
        "90% of best" if "90% of best" in names else None)
    return {"reference": ref["variant"], "speedup": speedups, "headline": headline,
            "verdict": claim.verdict(speedups[names.index(headline)] if headline else None, len(mine["seeds"])),
            # the paper's measure: sustained reach of 90 % and 95 % of the asymptote in under 1/2 of the updates?
            "paper": claim.paper_measure(mine.get("sustained_reach") or [], ref.get("sustained_reach") or [],
                                         len(mine["seeds"])),
            "poi_final": stats.probability_of_improvement(np.array(mine["final_scores"], float),
                                                          np.array(ref["final_scores"], float)).to_json(),
            "poi_auc": stats.probability_of_improvement(np.array(mine["auc_scores"], float),
                                                        np.array(ref["auc_scores"], float)).to_json()}


def summary_json(summary: list[dict]) -> str:
    """summary.json text: NaN (no asymptote, every seed diverged) becomes null, which JSON has and NaN is not."""
    def clean(x):
        if isinstance(x, float) and not math.isfinite(x):
            return None
        if isinstance(x, dict):
            return {k: clean(v) for k, v in x.items()}
        return [clean(v) for v in x] if isinstance(x, list) else x
    return json.dumps(clean(summary), indent=2)


def _est(d: dict | None, fmt: str = ".1f", suffix: str = "") -> str:
    return stats.Estimate.from_json(d).text(fmt, suffix) if d else "n/a"


def _k(u: int) -> str:
    return f"{u / 1000:g}k" if u >= 1000 else str(u)


def _per_seed(reach: dict) -> str:
    """'10k 10k >40k 15k' (a censored seed as >budget) and the censored count."""
    cells = [f">{_k(u)}" if c else _k(u) for u, c in zip(reach["updates"], reach["censored"])]
    return " ".join(cells) + (f" ({sum(reach['censored'])} censored)" if any(reach["censored"]) else "")


def summary_table(summary: list[dict]) -> str:
    """The printed result of a study: per variant its final, last and over-the-run scores (IQM [95 % CI] over
    seeds), and per variant compared with its reference the updates to each threshold per seed and the speed-up."""
    first = summary[0]
    n = len(first["seeds"])
    online = next((s["online"]["online_steps"] for s in summary if s.get("online")), None)
    budget = f"{first['updates']:,} updates per variant" + (
        "" if online is None else f", then {online:,} online env steps (this table's updates count both)")
    head = (f"{first['dataset']}, {n} seed{'s' if n != 1 else ''}, {budget}; "
            "IQM over seeds" + (" [stratified-bootstrap 95 % CI]" if n > 1 else " (one seed: no interval)"))
    if _known(first.get("behaviour_score")):
        head += f"; behaviour data {first['behaviour_score']:.1f}"
    lines = [head, "", "| variant | final score | last evaluation | mean over the run | final per seed | "
             "pre-training updates | peak (fall to final) |", "|---|--:|--:|--:|--:|--:|--:|"]
    for s in summary:
        gone = s.get("seeds_diverged") or []
        variant = s["variant"] + (f" ({len(gone)} seed(s) diverged, left out)" if gone else "")
        per_seed = " ".join("–" if not _known(x) else f"{x:.0f}" for x in s["final_scores"])
        peak = s.get("peak_score_mean")
        peak = f"{peak:.1f} at {s['peak_update']:,} ({s['fall_from_peak']:.1f})" if _known(peak) else "n/a"
        lines.append(f"| {variant} | {_est(s['final_iqm'])} | {_est(s['last_iqm'])} | {_est(s['auc_iqm'])} | "
                     f"{per_seed} | {s['pretrain_updates']:,} | {peak} |")
    lines += bc_level.table(summary)
    by_label = {s["variant"]: s for s in summary}
    for s in summary:
        vs = s.get("vs_reference")
        if not vs:
            continue
        ref = by_label[vs["reference"]]
        trend = ref.get("asymptote_trend")
        lines += ["", f"{s['variant']} vs {ref['variant']}: updates to each threshold per seed (pre-training "
                      f"included; a censored seed never reached it and counts at the budget); speed-up = mean "
                      f"updates of {ref['variant']} / of {s['variant']} [95 % CI]; ≥ where only {ref['variant']} has "
                      f"censored seeds, ≤ where only {s['variant']} has, no bound where both have"
                      f"{bc_level.threshold_note(s)}. "
                      f"{ref['variant']}'s final "
                      + (f"{ref['final_score_mean']:.1f}" if _known(ref["final_score_mean"]) else "n/a")
                      + (f", its trend {_est(trend, '+.1f')} over the last 20 % of evaluations: "
                         + ("flat, an asymptote" if ref.get("asymptote_flat") else "not flat, no asymptote")
                         if trend else ""),
                  "",
                  f"| threshold | score | {s['variant']} | {ref['variant']} | speed-up (updates) "
                  "| speed-up (seconds) |",
                  "|---|--:|--:|--:|--:|--:|"]
        for sp, a, b in zip(vs["speedup"], s["reach"], ref["reach"]):
            mark = " (headline)" if sp["threshold"] == vs["headline"] else ""
            lines.append(f"| {sp['threshold']}{mark} | {sp['score']:.1f} | {_per_seed(a)}{bc_level.flag(a)} | "
                         f"{_per_seed(b)}{bc_level.flag(b)} | "
                         f"{bc_level.ratio_text(sp['updates'], sp['censored'], sp['reference_censored'])} | "
                         f"{bc_level.ratio_text(sp['seconds'], sp['censored'], sp['reference_censored'])} |")
        lines += ["", f"Probability that {s['variant']} beats {ref['variant']}: final score "
                      f"{_est(vs['poi_final'], '.2f')}, mean over the run {_est(vs['poi_auc'], '.2f')}. "
                      f"{s['variant']} needs fewer updates than {ref['variant']} to reach "
                      f"{vs['headline'] or 'a threshold'}: "
                      f"{claim.VERDICT_WORDS.get(vs['verdict'], vs['verdict'])}."]
        lines += claim.lines(s, ref)
    lines += online_table([s["online"] for s in summary if s.get("online")])
    return "\n".join(lines)


def _known(x) -> bool:
    """A number summary.json has (null, or NaN, where there is none)."""
    return x is not None and x == x


def print_table(summary: list[dict]) -> None:
    print(summary_table(summary))


def resummarize(run_dir: Path, behaviour: float | None = None) -> list[dict]:
    """The summary of a run directory recomputed from its config.json and curves.csv (with today's statistics);
    the behaviour score from its summary.json where it recorded one, else `behaviour`."""
    study = Study.from_json((run_dir / "config.json").read_text())
    rows = read_curves(run_dir / "curves.csv")
    check_curve_seeds(run_dir / "curves.csv", rows, study.seeds)
    check_curve_algos(run_dir / "curves.csv", rows, study)
    if (run_dir / "summary.json").is_file():
        try:
            saved = json.loads((run_dir / "summary.json").read_text())
            behaviour = next((s["behaviour_score"] for s in saved if s.get("behaviour_score") is not None),
                             behaviour)
        except (json.JSONDecodeError, TypeError, AttributeError):
            pass
    return summarize(study, rows, pretrain_ends_of(rows), behaviour)
