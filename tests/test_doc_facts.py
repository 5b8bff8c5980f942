"""What the README, RESULTS.md and docs/ say about the code holds: the paths and modules they name exist, the core's
size is what docs/extending.md says, and every place that lists the algorithm families' config classes lists them
all.  The families are the registry's (`offrl_jax.algos`), so that adding one needs no change here."""
from __future__ import annotations

import importlib
import importlib.util
import re
from pathlib import Path

from offrl_jax.algos import FAMILIES, FAMILY_FILES

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", ROOT / "RESULTS.md", *sorted((ROOT / "docs").glob("*.md"))]
CODE_SPAN = re.compile(r"`([^`\n]+)`")
PATH = re.compile(r"^(?:offrl_jax|experiments|tests|benchmarks|docs)/[\w./-]*$")
MODULE = re.compile(r"^(?:offrl_jax|experiments|benchmarks)(?:\.\w+)+$")


def spans(page: Path) -> list[str]:
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.DOTALL)  # examples, not statements about the code
    return [s.split("::")[0].rstrip(".,:;") for s in CODE_SPAN.findall(text)]


def test_named_paths_exist():
    missing = [f"{page.relative_to(ROOT)}: {s}" for page in PAGES for s in spans(page)
               if PATH.match(s) and "*" not in s and not (ROOT / s).exists()]
    assert not missing, "\n".join(missing)


def resolves(dotted: str) -> bool:
    """A module, or a module's attribute (one or two levels down: a function, a class, its method)."""
    parts = dotted.split(".")
    for cut in range(len(parts), 0, -1):
        name = ".".join(parts[:cut])
        try:
            if importlib.util.find_spec(name) is None:
                continue
        except ModuleNotFoundError:
            continue
        obj = importlib.import_module(name)
        for attr in parts[cut:]:
            if not hasattr(obj, attr):
                return False
            obj = getattr(obj, attr)
        return True
    return False


def test_named_modules_and_functions_exist():
    missing = [f"{page.relative_to(ROOT)}: {s}" for page in PAGES for s in spans(page)
               if MODULE.match(s) and not resolves(s)]
    assert not missing, "\n".join(missing)


def test_the_core_is_the_size_docs_extending_says():
    """The core without the family files (the registry's `FAMILY_FILES`): a new family does not change it."""
    said = re.search(r"the core \(`offrl_jax/\*\.py` and `offrl_jax/algos/` without the family files\) is about\s+"
                     r"([\d,]+) lines", (ROOT / "docs" / "extending.md").read_text())
    assert said, "docs/extending.md no longer states the core's size; drop this test with it"
    families = {ROOT / "offrl_jax" / "algos" / f"{name}.py" for name in FAMILY_FILES}
    assert all(path.is_file() for path in families), families
    lines = sum(len(p.read_text().splitlines()) for p in [*(ROOT / "offrl_jax").glob("*.py"),
                                                           *(ROOT / "offrl_jax" / "algos").glob("*.py")]
                if p not in families)
    stated = int(said[1].replace(",", ""))
    assert abs(lines - stated) <= 0.1 * stated, f"the core is {lines:,} lines; docs/extending.md says about {stated:,}"


def test_a_study_is_the_size_of_the_example_docs_extending_names():
    said = re.search(r"see `experiments/ablation.py` \| ~(\d+) lines", (ROOT / "docs" / "extending.md").read_text())
    assert said, "docs/extending.md no longer states a study's size; drop this test with it"
    lines = len((ROOT / "experiments" / "ablation.py").read_text().splitlines())
    assert abs(lines - int(said[1])) <= 0.25 * int(said[1]), f"experiments/ablation.py is {lines} lines"


def test_a_list_of_the_families_config_classes_names_every_family():
    configs = {family.config.__name__ for family in FAMILIES.values()}
    for page in PAGES:
        for paragraph in re.split(r"\n\s*\n", page.read_text()):
            named = configs & set(re.findall(r"`(\w+Config)`", paragraph))
            assert len(named) < 2 or named == configs, (page.name, sorted(configs - named), paragraph[:120])


def test_the_walk_of_alpha_in_docs_extending_is_the_files_that_name_it():
    """docs/extending.md walks `--alpha 10` through at most four files: each exists, the family and the loss name the
    value, and the files it says carry the config in between name no `alpha` in their code (tokens, not text)."""
    import io
    import tokenize

    text = (ROOT / "docs" / "extending.md").read_text()
    walk = text[text.index("Where `--alpha 10` goes, file by file"):]
    walk = walk[:walk.index("\n\n", walk.index("| file |"))]
    files = re.findall(r"^\| `([\w/.]+\.py)` \|", walk, re.MULTILINE)
    assert 0 < len(files) <= 4 and re.search(rf"\({['', 'one', 'two', 'three', 'four'][len(files)]} files", walk)

    def names(path: str) -> set[str]:
        source = (ROOT / "offrl_jax" / path).read_text()
        return {t.string for t in tokenize.generate_tokens(io.StringIO(source).readline) if t.type == tokenize.NAME}

    assert all((ROOT / "offrl_jax" / f).is_file() for f in files), files
    assert "alpha" in names("algos/td3bc.py") and "alpha" in names("losses.py")
    carriers = ["app/studies.py", "run/study.py", "run/runner.py", "run/group.py", "app/flags.py", "algos/__init__.py"]
    assert not [f for f in carriers if "alpha" in names(f)]


def test_reading_one_algorithm_is_the_files_docs_extending_counts():
    """docs/extending.md's reading set: the files of the `--alpha` walk and the project modules each family file
    imports; at most seven files and 2,000 lines for TD3+BC, as stated, and for every other family."""
    import ast

    text = (ROOT / "docs" / "extending.md").read_text()
    said = re.search(r"is to read seven files, about ([\d,]+) lines", text)
    assert said, "docs/extending.md no longer states the reading set; drop this test with it"
    walk = ["app/flags.py", "algos/__init__.py", "losses.py"]

    def reading_set(family: str) -> set[str]:
        tree = ast.parse((ROOT / "offrl_jax" / "algos" / f"{family}.py").read_text())
        imported = {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom) and node.module
                    and node.module.startswith("offrl_jax")}
        imported |= {f"{node.module}.{a.name}" for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)
                     and node.module == "offrl_jax" for a in node.names}
        files = {m.removeprefix("offrl_jax.").replace(".", "/") + ".py" for m in imported}
        return {f for f in files if (ROOT / "offrl_jax" / f).is_file()} | set(walk) | {f"algos/{family}.py"}

    def lines(files: set[str]) -> int:
        return sum(len((ROOT / "offrl_jax" / f).read_text().splitlines()) for f in files)

    td3bc = reading_set("td3bc")
    assert td3bc == {*walk, "algos/td3bc.py", "algos/config.py", "algos/common.py", "nets.py"}, sorted(td3bc)
    stated = int(said[1].replace(",", ""))
    assert lines(td3bc) <= 2000 and abs(lines(td3bc) - stated) <= 0.1 * stated, lines(td3bc)
    for family in FAMILY_FILES:
        files = reading_set(family)
        assert len(files) <= 8 and lines(files) <= 2300, (family, sorted(files), lines(files))
