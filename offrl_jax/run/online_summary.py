"""The online phase's measures, per variant and seed, with the IQM over seeds and its bootstrap interval:

    hand-over     the score of the last offline evaluation, where the online phase starts
    dip           the lowest evaluation in the first `DIP_WINDOW` of the online env steps (at least the first online
                  evaluation) minus the hand-over score: negative where fine-tuning first unlearns
    final         the last online evaluation
    gain          final minus hand-over
    train score   the mean D4RL score of the training episodes over the whole online phase (the regret analogue:
                  what acting while learning scored), each evaluation interval weighted by its episodes
    env steps to  the behaviour score, and to 90 % of the best seed-mean online evaluation of any variant (below it
                  where that is negative); a seed there at the hand-over counts 0, one that never gets there is
                  censored at the online budget (the mean is then a lower bound, "≥")

Rows are curves.csv's (`offrl_jax.run.results.read_curves`): online ones have phase "online" and `env_steps`.
"""
from __future__ import annotations

import numpy as np

from offrl_jax.run import stats
from offrl_jax.run.results import all_nan_expected

DIP_WINDOW = 0.1  # the dip is looked for in this first fraction of the online env steps
BEST_FRACTION = 0.9


def online_curves(rows: list[dict], label: str, seeds: tuple[int, ...]) -> dict[str, np.ndarray]:
    """One variant's online curves: handover (S,), env_steps (E,), scores (S, E), train (S, E) and episodes (S, E)
    (NaN where a seed has no row)."""
    mine = [r for r in rows if r["variant"] == label]
    offline = [r for r in mine if r["phase"] != "online"]
    last = max((r["update"] for r in offline), default=None)
    handover = np.full(len(seeds), np.nan)
    for r in offline:
        if r["update"] == last:
            handover[seeds.index(r["seed"])] = r["score"]
    online = [r for r in mine if r["phase"] == "online"]
    steps = np.array(sorted({int(r["env_steps"]) for r in online}), dtype=int)
    shape = (len(seeds), len(steps))
    scores, train, episodes = np.full(shape, np.nan), np.full(shape, np.nan), np.zeros(shape)
    for r in online:
        i, j = seeds.index(r["seed"]), int(np.searchsorted(steps, int(r["env_steps"])))
        scores[i, j], train[i, j] = r["score"], r.get("train_score", np.nan)
        episodes[i, j] = r.get("train_episodes", 0.0)
    return {"handover": handover, "env_steps": steps, "scores": scores, "train": train, "episodes": episodes}


def summarize_online(rows: list[dict], labels: list[str], seeds: tuple[int, ...], online_steps: int,
                     behaviour: float | None = None) -> list[dict]:
    """One dict per variant with an online phase (labels in order): the measures above, each {"per_seed": [...],
    "iqm": Estimate JSON}, and the env steps to each threshold {"threshold", "score", "env_steps", "censored",
    "mean": Estimate JSON}."""
    with all_nan_expected():
        curves = {label: online_curves(rows, label, tuple(seeds)) for label in labels}
        curves = {label: c for label, c in curves.items() if len(c["env_steps"])}
        means = [np.nanmean(c["scores"], axis=0) for c in curves.values()]
        best = max((float(np.nanmax(m)) for m in means if np.isfinite(m).any()), default=None)
        thresholds = ([("behaviour data", behaviour)] if behaviour is not None else []) + (
            [(f"{BEST_FRACTION:.0%} of best", stats.fraction_of(best, BEST_FRACTION))] if best is not None else [])
        out = []
        for label, c in curves.items():
            steps, scores = c["env_steps"], c["scores"]
            early = steps <= max(DIP_WINDOW * online_steps, steps[0])
            weights = c["episodes"]
            train = np.where(weights.sum(axis=1) > 0, np.nansum(np.nan_to_num(c["train"]) * weights, axis=1)
                             / np.maximum(weights.sum(axis=1), 1), np.nan)
            measures = {"handover": c["handover"], "dip": np.nanmin(scores[:, early], axis=1) - c["handover"],
                        "final": scores[:, -1], "gain": scores[:, -1] - c["handover"], "train_score": train}
            entry = {"variant": label, "online_steps": online_steps, "best": best}
            for name, values in measures.items():
                entry[name] = {"per_seed": [float(x) for x in values],
                               "iqm": stats.interval([values], stats.iqm).to_json()}
            entry["reach"] = []
            at = np.concatenate([[0], steps])  # the hand-over is env step 0
            from_handover = np.concatenate([c["handover"][:, None], scores], axis=1)
            for name, score in thresholds:
                reach, censored = stats.first_reach(at, from_handover, score)
                reach = np.where(censored, online_steps, reach)
                entry["reach"].append({"threshold": name, "score": float(score), "env_steps": reach.tolist(),
                                       "censored": censored.tolist(),
                                       "mean": stats.interval([reach], stats.mean).to_json()})
            out.append(entry)
        return out


def online_table(online: list[dict]) -> list[str]:
    """The printed lines of `summarize_online`'s result (none without an online phase)."""
    if not online:
        return []
    est = lambda d, fmt=".1f": stats.Estimate.from_json(d).text(fmt)  # noqa: E731
    lines = ["", f"Online phase ({online[0]['online_steps']:,} env steps per seed; IQM over seeds [95 % CI]; dip = "
                 f"lowest evaluation in the first {DIP_WINDOW:.0%} of the env steps minus the hand-over score; "
                 "train score = the training episodes' mean score over the phase)", "",
             "| variant | hand-over | dip | final | gain | train score |", "|---|--:|--:|--:|--:|--:|"]
    for s in online:
        lines.append(f"| {s['variant']} | {est(s['handover']['iqm'])} | {est(s['dip']['iqm'], '+.1f')} | "
                     f"{est(s['final']['iqm'])} | {est(s['gain']['iqm'], '+.1f')} | {est(s['train_score']['iqm'])} |")
    names = [r["threshold"] for r in online[0]["reach"]]
    if names:
        lines += ["", "Env steps to each threshold (mean over seeds [95 % CI]; ≥: some seeds never reached it, "
                      "counted at the budget)", "",
                  "| variant | " + " | ".join(f"{n} ({r['score']:.1f})" for n, r in zip(names, online[0]["reach"]))
                  + " |", "|---|" + "--:|" * len(names)]
        for s in online:
            cells = [("≥ " if any(r["censored"]) else "") + est(r["mean"], ",.0f") for r in s["reach"]]
            lines.append(f"| {s['variant']} | " + " | ".join(cells) + " |")
    return lines


@all_nan_expected()
def plot_online(path, labels: list[str], rows: list[dict], seeds: tuple[int, ...], title: str,
                behaviour: float | None = None) -> None:
    """online.png: `draw_online` of a run, titled."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from offrl_jax.run.results import write_figure

    fig, ax = plt.subplots(figsize=(7, 4.5))
    draw_online(ax, labels, rows, seeds, behaviour)
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    write_figure(fig, path)


@all_nan_expected()
def draw_online(ax, labels: list[str], rows: list[dict], seeds: tuple[int, ...], behaviour: float | None = None,
                fontsize: float | None = None) -> None:
    """Every variant's IQM score over seeds against online env steps, with its 95 % bootstrap band, starting at
    its hand-over score (env step 0), and a dashed line at the behaviour data's score."""
    from offrl_jax.run.results import iqm_band

    for i, label in enumerate(labels):
        c = online_curves(rows, label, tuple(seeds))
        if not len(c["env_steps"]):
            continue
        steps = np.concatenate([[0], c["env_steps"]])
        middle, low, high = iqm_band(np.concatenate([c["handover"][:, None], c["scores"]], axis=1))
        ax.plot(steps, middle, label=label, color=f"C{i}")
        ax.fill_between(steps, low, high, alpha=0.2, color=f"C{i}")
    if behaviour is not None:
        ax.axhline(behaviour, color="gray", ls="--", lw=1, label=f"behaviour data ({behaviour:.1f})")
    ax.set_xlabel("online env steps per seed (0: the hand-over)")
    ax.set_ylabel("D4RL-normalised score")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=fontsize)
