"""docs/howto.md as written: its first recipe (own numpy arrays -> .npz -> `datasets info` -> a quick training run)
and its third (load, evaluate and roll out that run's policy, with a video), each code block taken from the file
and run in a fresh folder, one after the other.  The second needs a Minari download and is not run."""
import csv
import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from offrl_jax.data.readers import load_dataset_path

HOWTO = Path(__file__).resolve().parents[1] / "docs" / "howto.md"


def recipes() -> dict[str, list[tuple[str, str]]]:
    """{section title: [(language, code), ...]} of the file's fenced code blocks."""
    found: dict[str, list[tuple[str, str]]] = {}
    for section in re.split(r"^## ", HOWTO.read_text(), flags=re.M)[1:]:
        title = section.splitlines()[0]
        found[title] = re.findall(r"^```(\w+)\n(.*?)^```", section, flags=re.M | re.S)
    return found


def run_shell(code: str, cwd: Path) -> list[subprocess.CompletedProcess]:
    """Each command line of a bash block as written (comments dropped), with this interpreter as `python`."""
    done = []
    for line in code.splitlines():
        words = shlex.split(line, comments=True)
        if not words:
            continue
        assert words[0] == "python", line
        result = subprocess.run([sys.executable, *words[1:]], cwd=cwd, capture_output=True, text=True, timeout=600,
                                env=os.environ | {"PYTHONWARNINGS": "ignore"})
        assert result.returncode == 0, f"{line}\n{result.stderr[-3000:]}"
        done.append(result)
    return done


@pytest.mark.slow  # one of the suite's longest (1-5 min on 2 busy cores); -m slow runs it
def test_the_recipes_run_as_written(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    blocks = recipes()
    (lang, make), (lang2, commands) = blocks["Train on your own numpy arrays"]
    assert (lang, lang2) == ("python", "bash")
    exec(make, {})
    info, train = run_shell(commands, tmp_path)
    facts = json.loads(info.stdout)
    assert (facts["env"], facts["transitions"], facts["obs_dim"], facts["act_dim"]) == ("hopper", 2000, 11, 3)
    assert facts["episodes"] == 4
    back = load_dataset_path(tmp_path / "my-hopper.npz")
    assert back.timeouts.sum() == 4 and not back.terminals.any()
    run = tmp_path / "runs" / "my-hopper"
    assert json.loads((run / "config.json").read_text())["name"] == "my-hopper-td3bc"  # named after the file
    summary = json.loads((run / "summary.json").read_text())
    assert [v["variant"] for v in summary] == ["pretrained", "scratch"] and summary[0]["updates"] == 1000
    assert summary["study"] == "my-hopper-td3bc" if "study" in summary else True
    assert {"curves.csv", "curves.png", "config.json"} <= {p.name for p in run.iterdir()}

    (lang, python), (lang2, commands) = blocks["Load, evaluate and roll out a trained policy"]
    assert (lang, lang2) == ("python", "bash")
    exec(python, {})
    score = float(capsys.readouterr().out.strip().splitlines()[-1])
    # what the comment says: seed 0's evaluation at the last checkpoint's update (1000), up to float rounding
    with open(run / "curves.csv") as f:
        evaluated = [r for r in csv.DictReader(f)
                     if (r["variant"], r["seed"], r["update"]) == ("pretrained", "0", "1000")]
    assert len(evaluated) == 1 and abs(score - float(evaluated[0]["score"])) < 1e-3, (score, evaluated)
    run_shell(commands, tmp_path)
    assert (tmp_path / "hopper.gif").stat().st_size > 0
