"""The paper's claim as a measure: with pre-training, TD3+BC and EDAC "reach asymptotic performance in less than 1/2
of the training steps" (Section 6).  `offrl_jax.run.summary` records it in summary.json and prints it per study;
`claims_table` gives one row per comparison across studies (`experiments.report`, `results/claims.sh`).

- The asymptote (`plateau`): the from-scratch (reference) arm's final score (per seed the mean of its last 10 % of
  evaluations, or of the study's final window; averaged over seeds), and it counts as a plateau only where that
  arm's curve is flat (`stats.trend_is_flat`): per seed the mean of its last 20 % of evaluations minus the mean of
  the 20 % before, whose bootstrap interval over seeds lies within +-5 % of the level (at least 1 point).  On a
  500k-update run evaluated every 5k (100 evaluations) the level is each seed's mean over its last 10 evaluations
  (455k-500k), and flat means 400k-500k moved less than 5 % from 300k-400k, 20 evaluations a seed in each window.
  A curve still climbing has no asymptote, so no threshold of it, and the tables say so with its trend; so has one
  that swings so much between evaluations that the interval stays wider than the margin (no guess is made).
- Per seed, the updates (pre-training included) to first reach 90 % and 95 % of it (`stats.first_reach`): where a
  seed got there, the update itself; a seed that never does is censored at the budget, counted and marked.
- The speed-up (`stats.speedup`): mean updates from scratch / mean updates with pre-training, with its
  stratified-bootstrap interval.  The paper's "less than 1/2 of the training steps" is a speed-up above 2x
  (`PAPER_SPEEDUP`): "yes" only where the interval lies wholly above 2, "no" only where it lies wholly at or below
  2, undecided otherwise (`verdict`, whose censoring rules make a censored seed bound the ratio from one side only).
- Beside it in the claims table: each arm's final score, its best (the seed-mean curve's peak) and its last
  evaluation, the comparison's BC level (`offrl_jax.run.bc_level`) and each arm's improvement over it, with its
  interval.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from offrl_jax.run import bc_level, stats

PAPER_SPEEDUP = 2.0  # "in less than 1/2 of the training steps": a speed-up above 2x
PAPER_FRACTIONS = (0.9, 0.95)  # the fractions of the asymptote the paper's measure is read at


def threshold_name(fraction: float) -> str:
    """The name of a threshold `fraction` of the asymptote, as summary.json's reach lists it ('90% of asymptote')."""
    return f"{fraction:.0%} of asymptote"


@dataclasses.dataclass(frozen=True)
class Plateau:
    """The reference arm's plateau: its mean final score (`level`, NaN without a reference), the trend of its last
    evaluations (None: too few) and whether that trend is flat (only then is the level an asymptote)."""
    level: float
    trend: stats.Estimate | None
    flat: bool


def plateau(finals: np.ndarray | None, curve: np.ndarray | None) -> Plateau:
    """The plateau of the reference arm whose per-seed final scores are `finals` (S,) and scores `curve` (S, E)."""
    if curve is None or finals is None:
        return Plateau(float("nan"), None, False)
    trend, flat = stats.trend_is_flat(curve)
    finite = np.asarray(finals, dtype=float)
    finite = finite[np.isfinite(finite)]
    return Plateau(float(finite.mean()) if len(finite) else float("nan"), trend, flat)


def verdict(speedup: dict | None, seeds: int, bar: float = 1.0) -> str:
    """Whether a variant reaches a threshold more than `bar` times sooner than its reference (bar 1: in fewer
    updates; `PAPER_SPEEDUP`: in under 1/2 of the updates, the paper's claim): 'holds' when the speed-up's interval
    lies above `bar`, 'does not hold' when it lies at or below it, else 'undecided: <why>'.  A censored seed counts at
    the budget, so the ratio is a lower bound where only the reference has censored seeds (it may hold, never fail),
    an upper bound where only the variant has (it may fail, never hold), and neither where both have (undecided)."""
    if speedup is None:
        return "undecided: no threshold"
    if seeds < 2:
        return "undecided: one seed, no interval"
    ratio = stats.Estimate.from_json(speedup["updates"])
    mine, ref = speedup["censored"], speedup["reference_censored"]
    if mine == ref == seeds:
        return "undecided: neither arm reaches the threshold"
    if mine and ref:
        return "undecided: both arms have censored seeds"
    if ratio.low is None or ratio.high is None:
        return "undecided"
    if ratio.low > bar and not mine:
        return "holds"
    if ratio.high <= bar and not ref:
        return "does not hold"
    return (f"undecided: the interval holds {bar:g}" if ratio.low <= bar < ratio.high else
            "undecided: censored seeds bound the ratio from one side only")


VERDICT_WORDS = {"holds": "yes (the speed-up's interval lies above 1)",
                 "does not hold": "no (the speed-up's interval lies at or below 1)"}
SHORT = {"holds": "yes", "does not hold": "no"}


def paper_measure(speedups: list[dict], seeds: int) -> dict | None:
    """summary.json's "paper" entry of a comparison (`summary.compare`'s `speedups`, one per threshold): per
    fraction of the asymptote the verdict against `PAPER_SPEEDUP`; None where the reference has no asymptote."""
    found = {x["threshold"]: x for x in speedups}
    names = [threshold_name(f) for f in PAPER_FRACTIONS if threshold_name(f) in found]
    if not names:
        return None
    return {"speedup_above": PAPER_SPEEDUP,
            "verdicts": {name: verdict(found[name], seeds, PAPER_SPEEDUP) for name in names}}


# ------------------------------------------------------------------------------------------------------- text
def _number(x, fmt: str = ".1f") -> str:
    return f"{x:{fmt}}" if isinstance(x, (int, float)) and math.isfinite(x) else "n/a"


def plateau_text(variant: dict, reference: str) -> str:
    """How the plateau of `variant`'s reference (named `reference`) was found: "scratch's final 95.1, flat (trend +0.4
    [-1.2, 2.0] over the last 20 % of evaluations, within +-5 %): an asymptote", or why there is none."""
    trend = variant.get("asymptote_trend")
    head = f"{reference}'s final {_number(variant.get('asymptote'))}"
    if not trend:
        return head + ", too few evaluations to test for a plateau: no asymptote"
    change = stats.Estimate.from_json(trend).text("+.1f")
    if variant.get("asymptote_flat"):
        return head + f", flat (trend {change} over the last 20 % of evaluations, within +-5 %): an asymptote"
    return head + f", not flat (trend {change} over the last 20 % of evaluations): no asymptote"


def lines(variant: dict) -> list[str]:
    """The per-study paragraph and table of the paper's measure for `variant` against its reference."""
    vs = variant.get("vs_reference") or {}
    paper, reference = vs.get("paper"), vs.get("reference")
    head = (f"The paper's measure (Section 6: pre-training reaches the asymptote \"in less than 1/2 of the training "
            f"steps\", a speed-up above {PAPER_SPEEDUP:g}x): the asymptote is {reference}'s plateau, its final score "
            f"(mean over seeds) where its curve is flat; {plateau_text(variant, reference)}.")
    if not paper:
        return ["", head]
    found = {x["threshold"]: x for x in vs["speedup"]}
    out = ["", head + " Per-seed updates: the rows above.", "",
           "| threshold | score | speed-up (updates) | paper | under 1/2 of the updates? |", "|---|--:|--:|--:|---|"]
    for name, said in paper["verdicts"].items():
        x = found[name]
        out.append(f"| {name} | {x['score']:.1f} | {bc_level.speedup_text(x)} | > {PAPER_SPEEDUP:g}x | "
                   f"{SHORT.get(said, said)} |")
    return out


def _value(s: dict, key: str) -> float:
    """A number of summary.json: an Estimate's value (its IQM) or a plain float; NaN where there is none."""
    x = s.get(key)
    return stats.Estimate.from_json(x).value if isinstance(x, dict) else float("nan") if x is None else x


def _arms(variant: dict, ref: dict) -> str:
    """The cells final | best | last | improvement over BC, each 'variant / reference', as the study tables print
    them: IQMs over seeds, the best being the seed-mean curve's peak; the improvement with its interval."""
    cells = [" / ".join(_number(_value(s, key)) for s in (variant, ref))
             for key in ("final_iqm", "peak_score_mean", "last_iqm")]
    gains = [stats.Estimate.from_json(s["improvement_iqm"]).text("+.1f") if s.get("improvement_iqm") else "n/a"
             for s in (variant, ref)]
    return " | ".join(cells + [" / ".join(gains)])


def _plateau_cell(variant: dict) -> str:
    """'95.1 (86.2, 90.9)': the asymptote and its 90 % and 95 % thresholds where the reference's final is flat, else
    'none (43.8, trend +3.2 [1.0, 5.0])'."""
    level, trend = _number(variant.get("asymptote")), variant.get("asymptote_trend")
    if variant.get("asymptote_flat"):
        found = {r["threshold"]: r["score"] for r in variant["reach"]}
        return level + " (" + ", ".join(_number(found.get(threshold_name(f))) for f in PAPER_FRACTIONS) + ")"
    return f"none ({level}, trend {stats.Estimate.from_json(trend).text('+.1f')})" if trend else (
        "none (too few evaluations)")


PAPER_WORDS = f"< 1/2 of the updates (> {PAPER_SPEEDUP:g}x)"
CLAIMS_HEAD = ["| study | variant vs reference | seeds | asymptote (90 %, 95 % of it) | speed-up to 90 % | "
               "speed-up to 95 % | paper | holds at 90 % / 95 %? | final | best | last | improvement over BC | "
               "BC level (seed mean) |",
               "|---|---|--:|---|--:|--:|---|---|--:|--:|--:|--:|--:|"]
CLAIMS_NOTE = ("The paper's measure, per comparison, from every seed's updates (pre-training included; each study's "
               "table above lists them) to 90 % and 95 % of the asymptote: the reference (from-scratch) arm's "
               "plateau, the mean over its seeds of each seed's last 10 % of evaluations, an asymptote only where its "
               "curve is flat (the bootstrap interval of the change of its last 20 % of evaluations against the 20 % "
               "before within +-5 % of the level; else 'none', with that change). Speed-up = the reference's mean "
               "updates / the variant's [95 % CI], ≥ / ≤ / 'both censored' where seeds never reached the threshold "
               "(counted at the budget); the paper's \"less than 1/2 of the training steps\" is a speed-up above "
               f"{PAPER_SPEEDUP:g}x: yes / no only where the interval lies wholly above / at or below it. Variant / "
               "reference, as the study tables print them: final, last and improvement over BC (final minus the "
               "comparison's BC level, seed by seed, with its 95 % CI) as IQMs over seeds; best: the seed-mean "
               "curve's peak.")


def claims_rows(name: str, summary: list[dict]) -> list[str]:
    """The claims table's rows of one study (`name`): one per comparison."""
    by_label = {s["variant"]: s for s in summary}
    rows = []
    for s in summary:
        vs = s.get("vs_reference")
        if not vs:
            continue
        ref = by_label[vs["reference"]]
        found = {x["threshold"]: x for x in vs["speedup"]}
        verdicts = (vs.get("paper") or {}).get("verdicts", {})
        names = [threshold_name(f) for f in PAPER_FRACTIONS]
        ratios = [bc_level.speedup_text(found[n]) if n in found and n in verdicts else "n/a" for n in names]
        said = " / ".join(SHORT.get(verdicts[n], verdicts[n]) for n in names if n in verdicts) or "n/a"
        rows.append(f"| {name} | {s['variant']} vs {ref['variant']} | {len(s['seeds'])} | {_plateau_cell(s)} | "
                    + " | ".join(ratios) + f" | {PAPER_WORDS} | {said} | {_arms(s, ref)} | "
                    f"{bc_level.claim_cells(s)[0]} |")
    return rows


def claims_table(summaries: list[list[dict]], names: list[str]) -> str:
    """The paper's measure, one row per comparison of every study (`names`: how to call each)."""
    rows = [row for name, summary in zip(names, summaries) for row in claims_rows(name, summary)]
    return "\n".join(CLAIMS_HEAD + rows + ["", CLAIMS_NOTE])
