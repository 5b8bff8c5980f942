"""What a user reads speaks of the project and its results only: no words about how the work was organised
(see PROCESS_WORDS) in the README, RESULTS.md, docs/, benchmarks/README.md, the code's
comments and docstrings, or any --help."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.entry import run_module

ROOT = Path(__file__).resolve().parents[1]
PROCESS_WORDS = re.compile(r"\bsessions?\b|\bissues? ?#?\d+|\b(?:this|last|next) week\b|\bwork periods?\b|"
                           r"\bsprints?\b|\bticket ?#?\d+", re.IGNORECASE)
TEXTS = [ROOT / "README.md", ROOT / "RESULTS.md", ROOT / "benchmarks" / "README.md",
         *sorted((ROOT / "docs").rglob("*.md")),
         *sorted((ROOT / "offrl_jax").rglob("*.py")), *sorted((ROOT / "experiments").glob("*.py")),
         *sorted((ROOT / "benchmarks").glob("*.py"))]


def test_user_facing_text_has_no_process_words():
    found = [f"{path.relative_to(ROOT)}:{n}: {line.strip()[:80]}" for path in TEXTS
             for n, line in enumerate(path.read_text().splitlines(), 1) if PROCESS_WORDS.search(line)]
    assert not found, "\n".join(found)


@pytest.mark.parametrize("module", ["experiments.mujoco_medium", "experiments.figure2", "experiments.report",
                                    "offrl_jax.rollout", "offrl_jax.data", "benchmarks.throughput"])
def test_help_has_no_process_words(module):
    result = run_module(module, "--help", timeout=120)
    assert result.returncode == 0 and result.stdout.strip()
    assert not PROCESS_WORDS.search(result.stdout), [line for line in result.stdout.splitlines()
                                                     if PROCESS_WORDS.search(line)]
