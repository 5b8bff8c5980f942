"""The committed figures under results/figures/, each redrawn from its recorded source runs by one command:

    python -m experiments.report --figures

`results/figures/sources.json` lists every figure: what it shows, how it is drawn (`drawn_by`:
`offrl_jax.run.figures.plot_studies`, one panel per run against updates, or `plot_online_studies`, against online
env steps) and its panels, each with its study (a key of `results/studies.json`), the run drawn, the data the
run trained on where the run's own dataset name does not say which version (e.g. `hopper-medium-v0`), and the SHA-256
of the run's curves.csv when the figure was last drawn (written by the command).  `results/studies.json` is the one
place that says which run is a study's current one: a newer run that replaces it is recorded there.

A figure is stale (`stale`, checked by tests/test_figure_sources.py) when a source is not a run any more, when its
study's current run is another one (it was replaced), or when its curves.csv changed since the figure was drawn.
"""
from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FIGURES = ROOT / "results" / "figures"
SOURCES = FIGURES / "sources.json"
STUDIES = ROOT / "results" / "studies.json"


def read_json(path: Path) -> dict:
    try:
        found = json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise ValueError(f"{path}: not valid JSON ({e})") from None
    if not isinstance(found, dict):
        raise ValueError(f"{path}: an object expected")
    return found


def curves_sha256(run: Path) -> str:
    return hashlib.sha256((run / "curves.csv").read_bytes()).hexdigest()


def source_problem(panel: dict, studies: dict, root: Path = ROOT) -> str | None:
    """Why a panel's run cannot be drawn as its study's result (None if it can): it is not a run, its study is not
    recorded, or the study's current run is another one."""
    run, study = panel["run"], panel["study"]
    if not ((root / run / "summary.json").is_file() and (root / run / "curves.csv").is_file()):
        return f"{run} is not a run (no summary.json and curves.csv there)"
    if study not in studies:
        return f"its study {study} is not in {STUDIES.relative_to(ROOT)}"
    if studies[study] != run:
        return (f"{run} has been replaced by {studies[study]}, the current run of {study} "
                f"({STUDIES.relative_to(ROOT)})")
    return None


def stale(sources: dict, studies: dict, root: Path = ROOT) -> list[str]:
    """One line per reason a committed figure no longer shows its studies' current runs (empty: none)."""
    found = []
    for figure, spec in sources.items():
        for kind in (".png", ".pdf"):
            if not (root / "results" / "figures" / Path(figure).with_suffix(kind)).is_file():
                found.append(f"{figure}: no {Path(figure).with_suffix(kind).name} in results/figures")
        for panel in spec["panels"]:
            if problem := source_problem(panel, studies, root):
                found.append(f"{figure}: {problem}")
            elif panel.get("curves_sha256") != curves_sha256(root / panel["run"]):
                found.append(f"{figure}: {panel['run']}/curves.csv changed since the figure was drawn; redraw it "
                             "with python -m experiments.report --figures")
    return found


DRAWERS = ("plot_studies", "plot_online_studies")  # the functions of offrl_jax.run.figures a figure is drawn by


def drawer(spec: dict) -> str:
    """The function a figure's "drawn_by" names ("offrl_jax.run.figures.plot_studies, one panel per run")."""
    name = spec["drawn_by"].split(",")[0].strip().rsplit(".", 1)[-1]
    if name not in DRAWERS:
        raise ValueError(f"drawn_by {spec['drawn_by']!r}: expected one of {', '.join(DRAWERS)}")
    return name


def redraw(summary_of: Callable[[Path, str | None], list[dict]], sources_path: Path = SOURCES,
           studies_path: Path = STUDIES) -> list[Path]:
    """Draw every figure of `sources_path` from its runs, each summarised by `summary_of(run, the data it trained
    on)` (`experiments.report_runs.run_summary`: as the report reads a run), then record each run's
    curves.csv SHA-256 there; a source that is not its study's current run is refused (ValueError) before anything
    is drawn.  Returns the files written."""
    from offrl_jax.run import figures as drawing
    from offrl_jax.system.checkpoint import atomic_write_bytes

    sources, studies = read_json(sources_path), read_json(studies_path)
    for figure, spec in sources.items():
        for panel in spec["panels"]:
            if problem := source_problem(panel, studies):
                raise ValueError(f"{sources_path}: {figure}: {problem}")
    written = []
    for figure, spec in sources.items():
        runs, datasets = [ROOT / panel["run"] for panel in spec["panels"]], [p.get("dataset") for p in spec["panels"]]
        draw = getattr(drawing, drawer(spec))
        written += draw(runs, sources_path.parent / figure, datasets=datasets,
                        summaries=[summary_of(run, data) for run, data in zip(runs, datasets)])
        for panel, run in zip(spec["panels"], runs):
            panel["curves_sha256"] = curves_sha256(run)
    atomic_write_bytes(sources_path, (json.dumps(sources, indent=2) + "\n").encode())
    return written
