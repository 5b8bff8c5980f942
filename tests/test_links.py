"""Every relative link and image in the README, RESULTS.md, docs/ and the READMEs under benchmarks/ and results/
points at a file or folder of the repository."""
from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", ROOT / "RESULTS.md", *sorted((ROOT / "docs").glob("*.md")),
         ROOT / "benchmarks" / "README.md", *sorted((ROOT / "results").rglob("README.md"))]
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")


def relative_links(page: Path) -> list[str]:
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.DOTALL)  # code blocks hold no links
    text = re.sub(r"`[^`\n]*`", "", text)
    return [t for t in LINK.findall(text) if not re.match(r"[a-z]+:", t) and not t.startswith("#")]


def test_every_relative_link_resolves():
    broken = [f"{page.relative_to(ROOT)}: {target}" for page in PAGES for target in relative_links(page)
              if not (page.parent / target.split("#")[0]).exists()]
    assert not broken, "\n".join(broken)


def test_the_link_finder_finds_links_and_images_but_not_code():
    page = ROOT / "README.md"
    assert "results/figures/figure2.png" in relative_links(page) and "RESULTS.md" in relative_links(page)


def prose_and_cells(page: Path) -> tuple[list[tuple[int, str]], list[tuple[int, str]]]:
    """(line number, text) of every prose line and of every table cell of a page, code blocks left out."""
    prose, cells, fence = [], [], False
    for n, line in enumerate(page.read_text().splitlines(), 1):
        if line.lstrip().startswith("```"):
            fence = not fence
        elif line.startswith("|"):
            cells += [(n, c) for c in line.strip("|").split("|")]
        elif not fence and not line.startswith("    "):
            prose.append((n, line))
    return prose, cells


def test_the_readme_and_results_stay_scannable():
    """A newcomer reads the README's first screen and RESULTS.md's sections: prose wrapped at 120 characters, table
    cells short (the README's at most 40 words, RESULTS.md's 60; more is a sentence in docs/ or a study's README)."""
    for page, lines, words in ((ROOT / "README.md", 160, 40), (ROOT / "RESULTS.md", 420, 60)):
        prose, cells = prose_and_cells(page)
        assert len(page.read_text().splitlines()) <= lines, page.name
        assert [n for n, line in prose if len(line) > 120] == [], page.name
        assert [n for n, cell in cells if len(cell.split()) > words] == [], page.name
