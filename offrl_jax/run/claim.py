"""The paper's claim as a measure: with pre-training, TD3+BC and EDAC "reach asymptotic performance in less than 1/2
of the training steps" (Section 6).  `offrl_jax.run.summary` records it in summary.json and prints it per study;
`claims_table` gives one row per comparison across studies (`experiments.report`, `results/claims.sh`).

- The asymptote (`plateau`): the from-scratch (reference) arm's final score (per seed the mean of its last 10 % of
  evaluations, or of the study's final window; averaged over seeds), and it counts as one only where that arm's
  curve is flat (`stats.trend_is_flat`): per seed the mean of its last 20 % of evaluations minus the mean of the
  20 % before, whose bootstrap interval over seeds lies within +-5 % of the last 20 %'s mean (at least 1 point)
  on at least `MIN_PER_SIDE` (10) evaluations a side, so at least 48 evaluations (`Plateau.paper`; the study
  tables' own asymptote thresholds take the test without that minimum).  On a 500k-update run evaluated every 5k (100
  evaluations) the level is each seed's mean over its last 10 evaluations (455k-500k), and flat means 400k-500k
  moved less than 5 % from 300k-400k, 20 evaluations a seed in each window.  A curve still climbing has no
  asymptote, nor has one that swings so much that the interval stays wider than the margin (no guess is made), nor
  one with too few evaluations; the tables print the change measured, its interval, the margin and the
  evaluations a side, so a reader sees why.
- Sustained reach (`sustained_reach`, `stats.sustained_reach`): per seed, the first update (pre-training included)
  at which the trailing mean of its evaluations over a window is at or above 90 % (95 %) of the asymptote.  The
  window is as many evaluations as the level averages (`window`: the last 10 %, at least `MIN_WINDOW`, 3): 10 on
  that 500k run, so the mean at 50k averages the evaluations 5k-50k.  Trailing, not centred, so the update counted
  is one the seed has been trained to, its score held over the evaluations before it, never helped by a later
  one.  The first window - 1 evaluations have no mean (too few before them), so no seed can count before the
  window's last evaluation (50k there), and no speed-up above budget / that update (10x) can be measured: both
  arms pay that floor and the window's lag, which pull the ratio towards 1, against the claim.  The last
  evaluation's mean is a full window like any other.  A seed whose mean never gets there (or diverged: NaN) is
  censored at its last update, counted and marked.  One lucky evaluation cannot make a reach: on noisy curves the
  first evaluation at the threshold (the study tables' reach) favours the claim.
- The speed-up (`stats.speedup`): mean sustained-reach updates from scratch / with pre-training, with its
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
MIN_PER_SIDE = 10  # evaluations in each window of the flatness test before the paper's measure calls a plateau flat
MIN_WINDOW = 3  # the fewest evaluations a sustained reach averages


def threshold_name(fraction: float) -> str:
    """The name of a threshold `fraction` of the asymptote, as summary.json's reach lists it ('90% of asymptote')."""
    return f"{fraction:.0%} of asymptote"


@dataclasses.dataclass(frozen=True)
class Plateau:
    """The reference arm's plateau: its mean final score (`level`, NaN without a reference), the trend of its last
    evaluations (None: too few), whether that trend is flat (the study tables' asymptote thresholds), the
    evaluations on each side of the test (`per_side`) and its margin (5 % of the mean of the last 20 % of
    evaluations, at least 1 point: `stats.flat_margin`)."""
    level: float
    trend: stats.Estimate | None
    flat: bool
    per_side: int = 0
    margin: float = float("nan")

    @property
    def paper(self) -> bool:
        """An asymptote for the paper's measure: flat, on at least `MIN_PER_SIDE` evaluations a side."""
        return self.flat and self.per_side >= MIN_PER_SIDE


def plateau(finals: np.ndarray | None, curve: np.ndarray | None) -> Plateau:
    """The plateau of the reference arm whose per-seed final scores are `finals` (S,) and scores `curve` (S, E)."""
    if curve is None or finals is None:
        return Plateau(float("nan"), None, False)
    trend, flat = stats.trend_is_flat(curve)
    finite = np.asarray(finals, dtype=float)
    finite = finite[np.isfinite(finite)]
    k = stats.trend_window(np.shape(curve)[1]) if trend is not None else 0
    level = float(finite.mean()) if len(finite) else float("nan")  # every seed diverged: no level, so not flat
    return Plateau(level, trend, flat and math.isfinite(level), k,
                   stats.flat_margin(curve, k) if k else float("nan"))


def window(final_evaluations: int) -> int:
    """The sustained reach's window: as many evaluations as the plateau level averages (`final_evaluations`, the
    last 10 % of them), at least `MIN_WINDOW`."""
    return max(MIN_WINDOW, int(final_evaluations))


def sustained_reach(updates: np.ndarray, scores: np.ndarray, found: Plateau, evaluations: int,
                    level: bc_level.BCLevel | None, label: str) -> list[dict]:
    """A variant's sustained reach of 90 % and 95 % of the asymptote `found` (none unless `found.paper`): per seed
    the updates (`stats.sustained_reach` over `evaluations`), censored seeds, the window and, where the variant has
    a BC level of its own, the seeds whose running mean got there by the hand-over."""
    if not found.paper or not len(updates):
        return []
    out = []
    for f in PAPER_FRACTIONS:
        score = stats.fraction_of(found.level, f)
        at, censored = stats.sustained_reach(updates, scores, score, evaluations)
        out.append({"threshold": threshold_name(f), "score": score, "window": evaluations, "updates": at.tolist(),
                    "censored": censored.tolist()})
        if (by_bc := bc_level.by_bc_actor(at, censored, level, label)) is not None:
            out[-1]["by_bc_actor"] = by_bc
    return out


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


def paper_measure(mine: list[dict], reference: list[dict], seeds: int) -> dict | None:
    """summary.json's "paper" entry of a comparison, from the variant's and the reference's `sustained_reach`: per
    threshold the speed-up (reference / variant, censored seeds at the budget) and its verdict against
    `PAPER_SPEEDUP`; None where the reference has no asymptote for the paper's measure."""
    if not mine or not reference:
        return None
    speedups = []
    for a, b in zip(mine, reference):
        assert a["threshold"] == b["threshold"], (a["threshold"], b["threshold"])
        speedups.append({"threshold": a["threshold"], "score": a["score"],
                         "updates": stats.speedup(np.array(b["updates"]), np.array(a["updates"])).to_json(),
                         "censored": sum(a["censored"]), "reference_censored": sum(b["censored"]),
                         "by_bc_actor": sum(a.get("by_bc_actor") or []), "seeds": len(a["censored"])})
    return {"speedup_above": PAPER_SPEEDUP, "window": mine[0]["window"], "speedup": speedups,
            "verdicts": {x["threshold"]: verdict(x, seeds, PAPER_SPEEDUP) for x in speedups}}


# ------------------------------------------------------------------------------------------------------- text
def _number(x, fmt: str = ".1f") -> str:
    return f"{x:{fmt}}" if isinstance(x, (int, float)) and math.isfinite(x) else "n/a"


def plateau_test(variant: dict) -> str:
    """The flatness test of `variant`'s reference as the paper's measure reads it: "flat: +0.4 [-1.2, +2.0] within
    +-4.8 (12 a side)", "not flat: +3.2 [+1.0, +5.0], not within +-2.2 (12 a side)" or "too few evaluations: 1 a side,
    10 needed (+3.2 [+1.0, +5.0], +-2.2)": the change of the last 20 % of evaluations against the 20 % before [95 %
    CI], the margin and the evaluations in each window."""
    trend, k = variant.get("asymptote_trend"), variant.get("asymptote_per_side") or 0
    if not trend:
        return "too few evaluations"
    change, margin = stats.Estimate.from_json(trend).text("+.1f"), f"±{_number(variant.get('asymptote_margin'))}"
    if k < MIN_PER_SIDE:
        return f"too few evaluations: {k} a side, {MIN_PER_SIDE} needed ({change}, {margin})"
    if variant.get("asymptote_flat"):
        return f"flat: {change} within {margin} ({k} a side)"
    return f"not flat: {change}, not within {margin} ({k} a side)"


def plateau_text(variant: dict, reference: str) -> str:
    """How the plateau of `variant`'s reference (named `reference`) was found: "scratch's final 95.1; flat: +0.4
    [-1.2, +2.0] within +-4.8 (12 a side): an asymptote", or why there is none."""
    return (f"{reference}'s final {_number(variant.get('asymptote'))}; {plateau_test(variant)}: "
            + ("an asymptote" if variant.get("paper_asymptote") else "no asymptote"))


def _per_seed(reach: dict) -> str:
    """'10k 10k >40k' (a censored seed as >budget) and the censored count."""
    k = lambda u: f"{u / 1000:g}k" if u >= 1000 else str(u)  # noqa: E731
    cells = [f">{k(u)}" if c else k(u) for u, c in zip(reach["updates"], reach["censored"])]
    return " ".join(cells) + (f" ({sum(reach['censored'])} censored)" if any(reach["censored"]) else "")


def lines(variant: dict, reference: dict) -> list[str]:
    """The per-study paragraph and table of the paper's measure for `variant` against its `reference`."""
    vs = variant.get("vs_reference") or {}
    paper, name = vs.get("paper"), reference["variant"]
    head = (f"The paper's measure (Section 6: pre-training reaches the asymptote \"in less than 1/2 of the training "
            f"steps\", a speed-up above {PAPER_SPEEDUP:g}x): the asymptote is {name}'s plateau, its final score "
            f"(mean over seeds) where its curve is flat, the change of its last 20 % of evaluations against the 20 % "
            f"before [95 % CI] within ±5 % of the last 20 %'s mean on at least {MIN_PER_SIDE} evaluations a side; "
            f"{plateau_text(variant, name)}.")
    if not paper or "speedup" not in paper:
        return ["", head]
    out = ["", head + f" Sustained reach: per seed the first update (pre-training included) at which the mean of its "
           f"last {paper['window']} evaluations is at or above the threshold; a seed whose mean never is is censored "
           "at the budget.", "",
           f"| threshold | score | {variant['variant']} | {name} | speed-up (updates) | paper | "
           "under 1/2 of the updates? |", "|---|--:|--:|--:|--:|--:|---|"]
    mine = {r["threshold"]: r for r in variant.get("sustained_reach") or []}
    theirs = {r["threshold"]: r for r in reference.get("sustained_reach") or []}
    for x in paper["speedup"]:
        said = paper["verdicts"][x["threshold"]]
        out.append(f"| {x['threshold']} | {x['score']:.1f} | {_per_seed(mine[x['threshold']])} | "
                   f"{_per_seed(theirs[x['threshold']])} | {bc_level.speedup_text(x)} | > {PAPER_SPEEDUP:g}x | "
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
    """'95.1 (85.6, 90.3)': the asymptote and its 90 % and 95 % thresholds where the paper's measure has one, else
    'none (43.8)'."""
    level = _number(variant.get("asymptote"))
    if variant.get("paper_asymptote"):
        return level + " (" + ", ".join(_number(stats.fraction_of(variant["asymptote"], f))
                                        for f in PAPER_FRACTIONS) + ")"
    return f"none ({level})"


PAPER_WORDS = f"< 1/2 of the updates (> {PAPER_SPEEDUP:g}x)"
CLAIMS_HEAD = ["| study | variant vs reference | seeds | asymptote (90 %, 95 % of it) | plateau test | "
               "speed-up to 90 % | speed-up to 95 % | paper | holds at 90 % / 95 %? | final | best | last | "
               "improvement over BC | BC level (seed mean) |",
               "|---|---|--:|---|---|--:|--:|---|---|--:|--:|--:|--:|--:|"]
CLAIMS_NOTE = ("The paper's measure, per comparison. Asymptote: the reference (from-scratch) arm's plateau, the mean "
               "over its seeds of each seed's last 10 % of evaluations, an asymptote only where its curve is flat. "
               "Plateau test: the change of its last 20 % of evaluations against the 20 % before (per seed, mean "
               "over seeds [95 % CI]), flat where the interval lies within the margin (±5 % of the last 20 %'s "
               f"mean, at least 1 point), on at least {MIN_PER_SIDE} evaluations a side (else 'too few "
               "evaluations'). Speed-up: "
               "the reference's mean updates / the variant's [95 % CI] to each seed's sustained reach, the first "
               "update (pre-training included) at which the mean of its last evaluations (as many as the level "
               f"averages, at least {MIN_WINDOW}) is at or above the threshold; ≥ / ≤ / 'both censored' where seeds "
               "never got there (counted at the budget). The paper's \"less than 1/2 of the training steps\" is a "
               f"speed-up above {PAPER_SPEEDUP:g}x: yes / no only where the interval lies wholly above / at or below "
               "it. Variant / reference, as the study tables print them: final, last and improvement over BC (final "
               "minus the comparison's BC level, seed by seed, with its 95 % CI) as IQMs over seeds; best: the "
               "seed-mean curve's peak.")


def claims_rows(name: str, summary: list[dict]) -> list[str]:
    """The claims table's rows of one study (`name`): one per comparison."""
    by_label = {s["variant"]: s for s in summary}
    rows = []
    for s in summary:
        vs = s.get("vs_reference")
        if not vs:
            continue
        ref = by_label[vs["reference"]]
        paper = vs.get("paper") or {}
        found = {x["threshold"]: x for x in paper.get("speedup", [])}
        verdicts = paper.get("verdicts", {}) if found else {}
        names = [threshold_name(f) for f in PAPER_FRACTIONS]
        ratios = [bc_level.speedup_text(found[n]) if n in found and n in verdicts else "n/a" for n in names]
        said = " / ".join(SHORT.get(verdicts[n], verdicts[n]) for n in names if n in verdicts) or "n/a"
        rows.append(f"| {name} | {s['variant']} vs {ref['variant']} | {len(s['seeds'])} | {_plateau_cell(s)} | "
                    f"{plateau_test(s)} | " + " | ".join(ratios) + f" | {PAPER_WORDS} | {said} | {_arms(s, ref)} | "
                    f"{bc_level.claim_cells(s)[0]} |")
    return rows


def claims_table(summaries: list[list[dict]], names: list[str]) -> str:
    """The paper's measure, one row per comparison of every study (`names`: how to call each)."""
    rows = [row for name, summary in zip(names, summaries) for row in claims_rows(name, summary)]
    return "\n".join(CLAIMS_HEAD + rows + ["", CLAIMS_NOTE])
