"""The BC level of a study's variants: what behaviour cloning alone scores, the level offline RL's improvement is
measured from (`offrl_jax.run.summary` records it in summary.json, prints it and adds its thresholds).

- A variant that pre-trains its actor (`pretrain` "actor" or "actor+critic") and then runs offline RL has a
  hand-over: its last evaluation before offline RL (`results.pretrain_ends_of`), where its actor is the BC actor
  and no RL update has been made.  Its BC level, per seed, is its score there.
- A BC arm, a variant with a pre-trained actor that is evaluated in pre-training only (the `bc` algorithm), has its
  final score as its BC level.
- A comparison (the variants measured against the same reference, `study.reference_label`; all of a study without
  one) has the BC level of its first BC arm, else of its first variant with a hand-over, else the study's first of
  either.  A variant without a level of its own (from scratch, critic pre-training only) is measured from it, seed i
  against seed i.  The BC-relative thresholds are the comparison's, the same for every variant it compares: BC + 50 %
  and BC + 90 % of the way from the level's mean over seeds to the best seed-mean evaluation of any variant.
- The improvement over BC: per seed the final score minus the BC level (none for a BC arm: it is its own level).

A study with no such variant has no BC level, and nothing here is printed for it.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from offrl_jax.run import stats
from offrl_jax.run.study import Study, reference_label

FRACTIONS = (0.5, 0.9)  # the BC-relative thresholds: this far from the BC level to the best score
ACTOR_PRETRAINING = ("actor", "actor+critic")


@dataclasses.dataclass(frozen=True)
class BCLevel:
    """Per seed (S,) the BC level, whose variant it is (`source`) and at which update: the hand-over, or None for a
    BC arm's final score."""
    source: str
    scores: np.ndarray
    update: int | None

    @property
    def mean(self) -> float:
        finite = self.scores[np.isfinite(self.scores)]
        return float(finite.mean()) if len(finite) else float("nan")

    def to_json(self) -> dict:
        return {"source": self.source, "update": self.update, "scores": self.scores.tolist(), "mean": self.mean,
                "iqm": stats.interval([self.scores], stats.iqm).to_json()}


def own_levels(study: Study, curves: dict[str, tuple], finals: dict[str, np.ndarray],
               pretrain_ends: dict[str, int]) -> dict[str, BCLevel]:
    """{label: its own BC level} of the variants with a hand-over or that are BC arms; `curves` holds each
    variant's (updates, seconds, scores), `finals` its final scores per seed."""
    levels = {}
    for v in study.variants:
        updates, _, scores = curves[v.label]
        end = pretrain_ends.get(v.label, 0)
        if getattr(study.config(v.label), "pretrain", "none") not in ACTOR_PRETRAINING or not end or not len(updates):
            continue
        before = updates[updates <= end]
        if not len(before):  # pre-training ended before its first evaluation: nothing scored the BC actor
            continue
        if updates[-1] > end:
            levels[v.label] = BCLevel(v.label, stats.score_at(updates, scores, int(before[-1])), int(before[-1]))
        else:
            levels[v.label] = BCLevel(v.label, np.asarray(finals[v.label], dtype=float), None)
    return levels


def comparison_levels(study: Study, own: dict[str, BCLevel]) -> dict[str, BCLevel]:
    """{label: the BC level of its comparison} for every variant, where the study has any BC level."""
    def first(labels):
        hand_overs = [own[x] for x in labels if x in own and own[x].update is not None]
        arms = [own[x] for x in labels if x in own and own[x].update is None]
        return (arms + hand_overs or [None])[0]

    every = [v.label for v in study.variants]
    found = {}
    for label in every:
        group = [x for x in every if reference_label(study, x) == reference_label(study, label)]
        level = first(group) or first(every)
        if level is not None:
            found[label] = level
    return found


def improvement(finals: np.ndarray, level: BCLevel) -> np.ndarray:
    """Per seed the final score minus the BC level (seed i against seed i)."""
    return np.asarray(finals, dtype=float) - level.scores


def thresholds(level: BCLevel | None, best: float | None) -> list[tuple[str, float]]:
    """[(name, score)]: BC + 50 % and + 90 % of the way from the level's mean to `best`; none where there is no
    level, no best, or the best is not above the level (there is no way from BC to go)."""
    if level is None or best is None or not np.isfinite(level.mean) or not best > level.mean:
        return []
    return [(threshold_name(f), stats.way_from(level.mean, best, f)) for f in FRACTIONS]


def threshold_name(fraction: float) -> str:
    return f"BC + {fraction:.0%} to best"


def by_bc_actor(reach: np.ndarray, censored: np.ndarray, level: BCLevel | None, label: str) -> list[bool] | None:
    """Per seed whether the variant `label` reached a threshold by its BC actor (at or before its own hand-over,
    before any RL update); None for a variant without a hand-over of its own."""
    if level is None or level.source != label or level.update is None:
        return None
    return stats.reached_by(reach, censored, level.update).tolist()


# ------------------------------------------------------------------------------------------------------- text
def _finite(x) -> bool:
    return isinstance(x, (int, float)) and np.isfinite(x)


def _where(level: dict, variant: str | None = None) -> str:
    """Whose BC level it is, seen from `variant` ('its' where it is the variant's own)."""
    whose = "its" if level["source"] == variant else f"{level['source']}'s"
    if level["update"] is None:
        return f"{whose} final score (a BC arm)"
    return f"{whose} actor at the hand-over, update {level['update']:,}"


def table(summary: list[dict]) -> list[str]:
    """The lines of the BC-level table of a study's summary (none where no variant has a BC level)."""
    if not any(s.get("bc_level") for s in summary):
        return []
    cell = lambda d: stats.Estimate.from_json(d).text() if d else "n/a"  # noqa: E731
    seeds = lambda xs: " ".join("–" if x is None or x != x else f"{x:.0f}" for x in xs)  # noqa: E731
    lines = ["", "BC level: the pre-trained actor's score at the hand-over (its last evaluation before any RL update) "
                 "or a BC arm's final score; a variant without one is measured from its comparison's BC level "
                 "(named). Improvement over BC: final score minus BC level, per seed (seed i against seed i).", "",
             "| variant | BC level | BC level per seed | from | improvement over BC | improvement per seed |",
             "|---|--:|--:|---|--:|--:|"]
    for s in summary:
        level = s.get("bc_level")
        if not level:
            continue
        gain = s.get("improvement_over_bc")
        lines.append(f"| {s['variant']} | {cell(level['iqm'])} | {seeds(level['scores'])} | "
                     f"{_where(level, s['variant'])} | {cell(s.get('improvement_iqm')) if gain else 'n/a (BC)'} | "
                     f"{seeds(gain) if gain else ''} |")
    return lines


def threshold_note(variant: dict) -> str:
    """The caption's words on a comparison's BC-relative thresholds and its BC actor ('' where it has neither)."""
    level, best = variant.get("comparison_bc_level"), variant.get("best_score")
    note = ""
    if any(r["threshold"] == threshold_name(FRACTIONS[0]) for r in variant["reach"]) and level:
        note += (f"; BC + x % to best: x % of the way from the BC level ({level['mean']:.1f}, "
                 f"{_where(level)}) to "
                 f"the best seed-mean evaluation ({best:.1f})")
    if any("by_bc_actor" in r for r in variant["reach"]):
        note += "; 'by the BC actor': reached at or before the hand-over, before any RL update"
    return note


def figure_lines(summary: list[dict]) -> list[tuple[float, str]]:
    """[(score, legend label)]: the BC level of every comparison of a study (seed mean), for a figure's
    horizontal line; none for a summary without one (or written before BC levels were recorded)."""
    found = {}
    for s in summary:
        level = s.get("comparison_bc_level")
        if level and _finite(level.get("mean")):
            where = "final, a BC arm" if level["update"] is None else f"at {level['update']:,}"
            found[(level["source"], level["update"])] = (level["mean"],
                                                         f"BC level: {level['source']} {where} ({level['mean']:.1f})")
    return list(found.values())


def flag(reach: dict) -> str:
    """' (k of n by the BC actor)' for a threshold that k seeds reached at or before their hand-over."""
    hits = reach.get("by_bc_actor")
    return f" ({sum(hits)} of {len(hits)} by the BC actor)" if hits and any(hits) else ""


def claim_cells(variant: dict) -> list[str]:
    """The claims table's BC cells of a variant compared with its reference: the comparison's BC level (seed
    mean), and the speed-up to BC + 50 % and + 90 % to best, each flagged where the BC actor reached it."""
    vs, level = variant.get("vs_reference") or {}, variant.get("comparison_bc_level")
    if not level or not vs or not _finite(level.get("mean")):
        return ["n/a"] * (1 + len(FRACTIONS))
    cells = [f"{level['mean']:.1f} ({level['source']}"
             + (", a BC arm)" if level["update"] is None else f" at {level['update']:,})")]
    found = {x["threshold"]: x for x in vs["speedup"]}
    return cells + [speedup_text(found[threshold_name(f)]) if threshold_name(f) in found else "n/a"
                    for f in FRACTIONS]


CLAIMS_NOTE = ("BC level: the comparison's BC level, mean over seeds (whose: a BC arm's final score, or a pre-trained "
               "actor's at its hand-over, the update named); "
               "a from-scratch variant is measured from it too. 'k of n by the BC actor': k of the variant's n seeds "
               "reached the threshold at or before the hand-over, before any RL update: that much of the speed-up is "
               "the BC actor's.")


def ratio_text(estimate: dict | None, censored: int, reference_censored: int) -> str:
    """A speed-up (reference / this variant, a censored seed counted at the budget) as '≥ 4.21x [2.67, 8.00]': '≥'
    where only the reference has censored seeds (its true updates are more: the ratio can only be larger), '≤' where
    only this variant has (only smaller), '(both censored)' where both have (no bound either way)."""
    text = stats.Estimate.from_json(estimate).text(".2f", "x") if estimate else "n/a"
    if text == "n/a" or not (censored or reference_censored):
        return text
    return text + " (both censored)" if censored and reference_censored else ("≤ " if censored else "≥ ") + text


def speedup_text(x: dict) -> str:
    """A speed-up entry of `compare` as '≥ 4.21x [2.67, 8.00] (5 of 5 by the BC actor)' (`ratio_text`)."""
    ratio = ratio_text(x["updates"], x.get("censored", 0), x.get("reference_censored", 0))
    hits = x.get("by_bc_actor")
    return ratio + (f" ({hits} of {x['seeds']} by the BC actor)" if hits else "")
