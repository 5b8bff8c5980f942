"""`experiments.report --plot`: the committed Figure 2 runs as one grid (rows: envs, columns: algorithms)."""
from __future__ import annotations

import shutil
import struct
from pathlib import Path

from offrl_jax.run.figures import panel_grid

ROOT = Path(__file__).resolve().parents[1]
RUNS = [ROOT / "results" / "figure2" / name for name in ("halfcheetah-td3bc", "walker2d-td3bc", "hopper-edac")]


def png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", data[16:24])


def test_the_committed_figure2_runs_make_one_envs_by_algorithms_grid(tmp_path):
    from experiments import report

    figure = tmp_path / "figure2.png"
    assert report.main([*map(str, RUNS), "--plot", str(figure), "--no-reference"]) == 0
    width, height = png_size(figure)
    assert (width, height) == (int(4.2 * 2 * 110), int(3.2 * 3 * 110))  # 3 envs x 2 algorithms
    assert figure.with_suffix(".pdf").read_bytes()[:4] == b"%PDF"


def test_overlay_draws_every_study_in_one_panel(tmp_path):
    from experiments import report

    figure = tmp_path / "overlay.png"
    assert report.main([*map(str, RUNS[:2]), "--plot", str(figure), "--overlay", "--no-reference"]) == 0
    assert png_size(figure) == (int(4.2 * 110), int(3.2 * 110))


def test_update_ticks_read_as_20k_and_1m():
    from offrl_jax.run.figures import updates_label

    assert [updates_label(x) for x in (0, 2500, 20_000, 1_000_000, 1_500_000)] == ["0", "2.5k", "20k", "1M", "1.5M"]


def test_studies_that_share_an_env_and_algorithm_go_in_one_row():
    one = [{"env": "hopper", "algo": "td3bc"}]
    assert panel_grid([one, one]) == ([""], ["0", "1"])
    assert panel_grid([one, [{"env": "door", "algo": "edac"}]]) == (["hopper", "door"], ["td3bc", "edac"])


def test_plot_refuses_a_name_that_is_not_a_png(tmp_path, capsys):
    from experiments import report

    assert report.main([str(RUNS[0]), "--plot", str(tmp_path / "x.jpg")]) == 2
    assert "must end in .png" in capsys.readouterr().err


def test_report_replaces_no_figure_and_counts_a_study_once(tmp_path, capsys):
    """An existing --plot figure (or its .pdf) is refused, untouched, unless --overwrite; a run given twice too."""
    from experiments import report

    for name in ("mine.png", "theirs.pdf"):
        (tmp_path / name).write_text("keep me")
    for fig in ("mine.png", "theirs.png"):
        assert report.main([str(RUNS[0]), "--plot", str(tmp_path / fig), "--no-reference"]) == 2
        assert "exists; pass --overwrite" in capsys.readouterr().err
    assert {p.name: p.read_text() for p in tmp_path.iterdir()} == {"mine.png": "keep me", "theirs.pdf": "keep me"}
    assert report.main([str(RUNS[0]), str(RUNS[0]) + "/", "--no-reference"]) == 2
    assert "is given twice" in capsys.readouterr().err
    assert report.main([str(RUNS[0]), "--plot", str(tmp_path / "mine.png"), "--no-reference", "--overwrite"]) == 0
    assert (tmp_path / "mine.png").read_bytes()[:4] == b"\x89PNG"


def test_report_refuses_an_aggregate_of_one_study_before_any_table(tmp_path, capsys):
    """--aggregate of one study (or of a --merge, which makes one) is refused before a table is printed."""
    from experiments import report

    figure = tmp_path / "agg.png"
    for args in ([str(RUNS[0])], [str(RUNS[0]), str(RUNS[1]), "--merge", str(tmp_path / "merged")]):
        assert report.main([*args, "--aggregate", str(figure), "--no-reference"]) == 2
        out, err = capsys.readouterr()
        assert out == "" and err.startswith("error: --aggregate takes two or more studies"), (out, err)
        assert len(err.strip().splitlines()) == 1
    assert not any(tmp_path.iterdir())


def test_a_runs_curves_title_says_what_its_band_is_one_seed_has_none_and_a_long_one_wraps():
    from offrl_jax.run.results import curves_title
    assert (curves_title("hm-td3bc", "hopper-medium", 5)
            == "hm-td3bc: hopper-medium, 5 seeds, IQM and stratified-bootstrap 95% CI")
    assert curves_title("hm-td3bc", "hopper-medium", 1) == "hm-td3bc: hopper-medium, 1 seed: no interval"
    merged = curves_title("hopper-medium-calql+td3bc+iql", "online phase", 5)  # a merged study's long name
    assert merged == ("hopper-medium-calql+td3bc+iql: online phase,\n5 seeds, IQM and stratified-bootstrap 95% CI")
    assert max(len(line) for line in merged.splitlines()) <= 80


def test_report_counts_a_study_inside_a_directory_of_studies_once(tmp_path, capsys):
    """A directory of studies and a study inside it: the study would count twice in the aggregate; refused."""
    from experiments import report

    studies = tmp_path / "studies"
    for run in RUNS[:2]:
        shutil.copytree(run, studies / run.name)
    assert report.main([str(studies), str(studies / RUNS[0].name), "--no-reference"]) == 2
    out, err = capsys.readouterr()
    assert not out and err.startswith(f"error: {studies / RUNS[0].name} is given twice"), err
    assert report.main([str(studies), "--no-reference"]) == 0 and "Across 2 studies" in capsys.readouterr().out


def test_aggregate_refuses_studies_without_a_variant_in_common_and_a_runs_own_figure(tmp_path, capsys):
    from experiments import report

    other = ROOT / "results" / "layernorm" / "hopper-td3bc"  # LN variants: none in common with Figure 2's
    figure = tmp_path / "agg.png"
    assert report.main([str(RUNS[0]), str(other), "--aggregate", str(figure), "--no-reference"]) == 2
    out, err = capsys.readouterr()
    assert not out and err.startswith("error: --aggregate: the studies have no variant in common"), err
    assert len(err.strip().splitlines()) == 1 and not figure.exists()
    run = tmp_path / "run"
    shutil.copytree(RUNS[0], run)
    before = (run / "curves.png").read_bytes()
    assert report.main([str(run), str(RUNS[1]), "--aggregate", str(run / "curves.png"), "--overwrite",
                        "--no-reference"]) == 2
    out, err = capsys.readouterr()
    assert not out and "is a run's own file" in err and (run / "curves.png").read_bytes() == before, err
    assert report.main([str(RUNS[0]), str(RUNS[1]), "--plot", str(figure), "--aggregate", str(figure),
                        "--no-reference"]) == 2
    assert "--plot and --aggregate both name" in capsys.readouterr().err and not figure.exists()
