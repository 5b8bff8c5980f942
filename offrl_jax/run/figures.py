"""Figures across runs: one panel per study, laid out as the paper's (rows: environments, columns: algorithms).

Each panel draws every variant's IQM score over seeds against updates with its 95 % bootstrap interval
(`offrl_jax.run.results.iqm_band`), a dotted line
where pre-training ended, a dashed line at the behaviour data's score (the mean D4RL-normalised return of the
dataset's episodes) when that dataset is in the cache, and a dash-dot line at the study's BC level
(`offrl_jax.run.bc_level`; not with `overlay`).  `overlay=True` draws every study in one panel instead.
Updates are ticked as 20k / 1M; the figure is written as PNG and PDF.  `plot_online_studies` draws runs with an
online phase against env steps.
"""
from __future__ import annotations

import functools
import json
from pathlib import Path

from offrl_jax.run.bc_level import figure_lines
from offrl_jax.run.results import all_nan_expected, iqm_band, read_curves, score_matrix, write_figure

ALGO_NAMES = {"td3bc": "TD3+BC", "edac": "EDAC", "td3bc_cql": "TD3+BC+CQL", "edac_bc": "EDAC+BC", "bc": "BC",
              "cql": "CQL", "calql": "Cal-QL", "sacn": "SAC-N", "iql": "IQL", "rebrac": "ReBRAC"}


@functools.cache
def behaviour_score(dataset: str, sha256: str | None = None) -> float | None:
    """The dataset's behaviour score, if the dataset is cached (None otherwise: nothing is generated here) and, with
    `sha256`, only if the cached data has that fingerprint (`offrl_jax.run.provenance`: the data a run recorded)."""
    from offrl_jax.data import catalogue
    from offrl_jax.run.provenance import fingerprint
    from offrl_jax.run.summary import behaviour_score as of_data

    try:
        if not catalogue.is_cached(dataset):
            return None
        ds = catalogue.load(dataset)
    except Exception:  # noqa: BLE001 -- a reference line is optional; a dataset we cannot read simply has none
        return None
    return of_data(ds) if sha256 is None or fingerprint(ds) == sha256 else None


def panel_grid(summaries: list[list[dict]]) -> tuple[list[str], list[str]]:
    """(row names, column names): envs x algorithms when every (env, algorithm) is one study, else one row."""
    keys = [(s[0]["env"], s[0]["algo"]) for s in summaries]
    if len(set(keys)) == len(keys):
        return list(dict.fromkeys(k[0] for k in keys)), list(dict.fromkeys(k[1] for k in keys))
    return [""], [str(i) for i in range(len(summaries))]


def updates_label(x: float, _=None) -> str:
    """20000 -> 20k, 1000000 -> 1M, 2500 -> 2.5k."""
    if abs(x) >= 1e6:
        return f"{x / 1e6:g}M"
    return f"{x / 1e3:g}k" if abs(x) >= 1e3 else f"{x:g}"


def data_label(dataset: str) -> str:
    """hopper-medium-v0 -> hopper-medium v0 (a version named in a title); a name without a version as it is."""
    from offrl_jax.data.dataset import split_version

    name, version = split_version(dataset)
    return dataset if name == dataset else f"{name} v{version}"


def plot_studies(study_dirs: list[Path], path: Path, reference: bool = True, overlay: bool = False,
                 summaries: list[list[dict]] | None = None, datasets: list[str | None] | None = None) -> list[Path]:
    """One panel per study directory (its summary.json, or its summary in `summaries`, and its curves.csv), or all in
    one (`overlay`), written to `path` as PNG and beside it as PDF; returns the files written.  Each panel's title
    names its data, algorithm, seeds and budget; `datasets` names a study's data where its summary's name is not
    enough (a versioned id, e.g. hopper-medium-v0), for the title and for the behaviour line of a run that did not
    record its behaviour score."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter

    if summaries is None:
        summaries = [json.loads((d / "summary.json").read_text()) for d in study_dirs]
    rows, cols = ([""], ["0"]) if overlay else panel_grid(summaries)
    fig, axes = plt.subplots(len(rows), len(cols), figsize=(4.2 * len(cols), 3.2 * len(rows)), squeeze=False)
    used = set()
    datasets = datasets or [None] * len(study_dirs)
    for index, (study_dir, summary, dataset) in enumerate(zip(study_dirs, summaries, datasets)):
        dataset = dataset or summary[0]["dataset"]
        env, algo = summary[0]["env"], summary[0]["algo"]
        r, c = (0, 0) if overlay else (rows.index(env), cols.index(algo)) if rows != [""] else (0, index)
        ax = axes[r][c]
        used.add((r, c))
        curves = read_curves(study_dir / "curves.csv")
        for i, entry in enumerate(summary):
            updates, _, scores = score_matrix(curves, entry["variant"])
            if not len(updates):
                continue
            color = f"C{len(ax.get_lines()) if overlay else i}"
            with all_nan_expected():
                mean, low, high = iqm_band(scores)
            label = f"{study_dir.name}: {entry['variant']}" if overlay else entry["variant"]
            ax.plot(updates, mean, color=color, label=label)
            ax.fill_between(updates, low, high, color=color, alpha=0.2)
            if entry.get("pretrain_updates"):
                ax.axvline(entry["pretrain_updates"], color=color, ls=":", lw=1)
        recorded = next((s["behaviour_score"] for s in summary if s.get("behaviour_score") is not None), None)
        behaviour = (recorded if recorded is not None else behaviour_score(dataset)) if reference else None
        if behaviour is not None:
            ax.axhline(behaviour, color="grey", ls="--", lw=1, label=f"behaviour data ({behaviour:.1f})")
        for score, label in [] if overlay else figure_lines(summary):
            ax.axhline(score, color="black", ls="-.", lw=1, label=label)
        if not overlay:
            n, budget = len(summary[0]["seeds"]), max(s["updates"] for s in summary)
            ax.set_title(f"{data_label(dataset)}, {ALGO_NAMES.get(algo, algo)} ({n} seed{'s' * (n != 1)}, "
                         f"{updates_label(budget)} updates)", fontsize=10)
        ax.xaxis.set_major_formatter(FuncFormatter(updates_label))
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
        if r == len(rows) - 1:
            ax.set_xlabel("updates (dotted: end of pre-training)")
        if c == 0:
            ax.set_ylabel("normalised score")
    for r in range(len(rows)):
        for c in range(len(cols)):
            if (r, c) not in used:
                axes[r][c].axis("off")
    fig.suptitle("IQM over seeds; band: stratified-bootstrap 95 % interval", fontsize=9)
    fig.tight_layout()
    return write_figure(fig, path, dpi=110, pdf=True)


def plot_online_studies(study_dirs: list[Path], path: Path, summaries: list[list[dict]] | None = None,
                        datasets: list[str | None] | None = None) -> list[Path]:
    """One panel per run with an online phase, three to a row: every variant's IQM score against online env steps
    from its hand-over (`offrl_jax.run.online_summary.draw_online`), written to `path` as PNG and PDF."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter

    from offrl_jax.run.online_summary import draw_online

    if summaries is None:
        summaries = [json.loads((d / "summary.json").read_text()) for d in study_dirs]
    datasets = datasets or [None] * len(study_dirs)
    cols = min(3, len(study_dirs))
    rows_of_panels = -(-len(study_dirs) // cols)
    fig, axes = plt.subplots(rows_of_panels, cols, figsize=(5.6 * cols, 4.0 * rows_of_panels), squeeze=False)
    for ax in axes.flat[len(study_dirs):]:
        ax.set_visible(False)
    for ax, study_dir, summary, dataset in zip(axes.flat, study_dirs, summaries, datasets):
        rows, seeds = read_curves(study_dir / "curves.csv"), tuple(summary[0]["seeds"])
        behaviour = next((s["behaviour_score"] for s in summary if s.get("behaviour_score") is not None), None)
        draw_online(ax, [s["variant"] for s in summary], rows, seeds, behaviour, fontsize=7)
        steps = max((int(r["env_steps"]) for r in rows if r.get("phase") == "online"), default=0)
        offline = max(s["updates"] for s in summary)
        ax.set_title(f"{data_label(dataset or summary[0]['dataset'])}, "
                     f"{ALGO_NAMES.get(summary[0]['algo'], summary[0]['algo'])} ({len(seeds)} seeds, "
                     f"{updates_label(offline)} updates + {updates_label(steps)} env steps)", fontsize=10)
        ax.xaxis.set_major_formatter(FuncFormatter(updates_label))
    fig.suptitle("IQM over seeds; band: stratified-bootstrap 95 % interval", fontsize=9)
    fig.tight_layout()
    return write_figure(fig, path, dpi=110, pdf=True)
