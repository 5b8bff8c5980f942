"""The committed figures cannot go stale unnoticed: every figure under results/figures/ is listed in its sources.json,
and each of its source runs exists, is its study's current run (results/studies.json) and has the curves.csv it was
drawn from (`experiments.figures`)."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from experiments import figures, report, report_runs

ROOT = Path(__file__).resolve().parents[1]


def test_every_committed_figure_is_drawn_from_its_studies_current_runs():
    sources, studies = figures.read_json(figures.SOURCES), figures.read_json(figures.STUDIES)
    assert figures.stale(sources, studies) == []
    drawn = {p.with_suffix(".png").name for p in figures.FIGURES.iterdir() if p.suffix in (".png", ".pdf")}
    assert drawn == set(sources), "a figure under results/figures/ without sources, or sources without a figure"


def test_every_studys_current_run_is_a_run():
    for study, run in figures.read_json(figures.STUDIES).items():
        assert (ROOT / run / "summary.json").is_file() and (ROOT / run / "curves.csv").is_file(), (study, run)


def test_every_run_of_the_claims_table_is_a_run():
    runs = [line.strip() for line in (ROOT / "results" / "claims.sh").read_text().splitlines()
            if line.strip().startswith("results/")]
    assert len(runs) > 10
    assert [r for r in runs if not (ROOT / r / "summary.json").is_file()] == []


def copy_of_results(tmp_path: Path) -> tuple[Path, dict, dict]:
    """A root holding results/figures and the runs of figure2.png's first two panels, with their sources."""
    sources = figures.read_json(figures.SOURCES)
    sources = {"figure2.png": dict(sources["figure2.png"], panels=sources["figure2.png"]["panels"][:2])}
    for panel in sources["figure2.png"]["panels"]:
        (tmp_path / panel["run"]).mkdir(parents=True)
        for name in ("summary.json", "curves.csv"):
            shutil.copy(ROOT / panel["run"] / name, tmp_path / panel["run"] / name)
    (tmp_path / "results" / "figures").mkdir()
    for name in ("figure2.png", "figure2.pdf"):
        (tmp_path / "results" / "figures" / name).write_bytes(b"")
    studies = {p["study"]: p["run"] for p in sources["figure2.png"]["panels"]}
    return tmp_path, sources, studies


def test_a_missing_source_run_makes_its_figure_stale(tmp_path):
    root, sources, studies = copy_of_results(tmp_path)
    assert figures.stale(sources, studies, root) == []
    gone = sources["figure2.png"]["panels"][1]["run"]
    shutil.rmtree(root / gone)
    assert figures.stale(sources, studies, root) == [f"figure2.png: {gone} is not a run (no summary.json and "
                                                     "curves.csv there)"]


def test_a_newer_run_of_the_same_study_makes_the_figure_stale(tmp_path):
    root, sources, studies = copy_of_results(tmp_path)
    panel = sources["figure2.png"]["panels"][0]
    newer = "results/mujoco_medium/newer-run"
    shutil.copytree(root / panel["run"], root / newer)
    studies[panel["study"]] = newer  # recorded as the study's current run
    [line] = figures.stale(sources, studies, root)
    assert f"{panel['run']} has been replaced by {newer}" in line and line.startswith("figure2.png: ")


def test_a_source_whose_curves_changed_since_the_drawing_makes_the_figure_stale(tmp_path):
    root, sources, studies = copy_of_results(tmp_path)
    run = root / sources["figure2.png"]["panels"][0]["run"]
    (run / "curves.csv").write_text((run / "curves.csv").read_text() + "\n")
    [line] = figures.stale(sources, studies, root)
    assert "curves.csv changed since the figure was drawn" in line


def test_every_hopper_medium_panel_names_its_version():
    """hopper-medium changed at v1: a panel of a run on it says which version it is, in its title too."""
    for figure, spec in figures.read_json(figures.SOURCES).items():
        for panel in spec["panels"]:
            summary = json.loads((ROOT / panel["run"] / "summary.json").read_text())
            if summary[0]["dataset"] == "hopper-medium":
                versions = ("hopper-medium-v0", "hopper-medium-v1", "hopper-medium-v2")
                assert panel.get("dataset") in versions, (figure, panel)


def test_report_figures_takes_no_run_directories_and_report_needs_some(capsys):
    assert report.main(["results/figure2/hopper-edac", "--figures"]) == 2
    assert report.main([]) == 2
    assert capsys.readouterr().err.strip().splitlines()[-1].startswith("error: give one or more run directories")


def test_redraw_draws_each_figure_from_its_runs_and_records_their_curves(tmp_path):
    panel = {"study": "figure2/hopper-edac", "run": "results/figure2/hopper-edac", "dataset": "hopper-medium-v0"}
    sources = tmp_path / "sources.json"
    sources.write_text(json.dumps({"one.png": {"shows": "a test", "drawn_by": "plot_studies", "panels": [panel]}}))
    studies = tmp_path / "studies.json"
    studies.write_text(json.dumps({panel["study"]: panel["run"]}))
    written = figures.redraw(report_runs.run_summary, sources, studies)
    assert written == [tmp_path / "one.png", tmp_path / "one.pdf"]
    assert (tmp_path / "one.png").read_bytes()[:4] == b"\x89PNG"
    [drawn] = json.loads(sources.read_text())["one.png"]["panels"]
    assert drawn["curves_sha256"] == figures.curves_sha256(ROOT / panel["run"])


def test_redraw_refuses_a_replaced_source_before_drawing_anything(tmp_path):
    panel = {"study": "figure2/hopper-edac", "run": "results/figure2/hopper-edac"}
    sources = tmp_path / "sources.json"
    sources.write_text(json.dumps({"one.png": {"panels": [panel]}}))
    studies = tmp_path / "studies.json"
    studies.write_text(json.dumps({panel["study"]: "results/figure2/hopper-edac-critic9k"}))
    with pytest.raises(ValueError, match="has been replaced by results/figure2/hopper-edac-critic9k"):
        figures.redraw(report_runs.run_summary, sources, studies)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sources.json", "studies.json"]


def test_every_figure_names_the_function_that_draws_it():
    assert {figures.drawer(spec) for spec in figures.read_json(figures.SOURCES).values()} <= set(figures.DRAWERS)
    assert figures.drawer({"drawn_by": "offrl_jax.run.figures.plot_online_studies, one panel per run"}) == \
        "plot_online_studies"
    with pytest.raises(ValueError, match="expected one of plot_studies"):
        figures.drawer({"drawn_by": "somewhere.plot_anything"})
