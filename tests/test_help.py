"""Every entry point's --help says what each of its flags does: every argument of every command's parser (and of its
sub-commands) has a help text, and the config fields that take one of a few strings offer exactly the values their
config accepts.  The parsers are built in this process (`make_parser()`, or `main` stopped at its first parse), no
command is run."""
from __future__ import annotations

import argparse
import dataclasses
import importlib
import re
import typing
from pathlib import Path

import pytest

from offrl_jax.app import flags

ROOT = Path(__file__).resolve().parents[1]
# a package's __main__.py: the module whose `main` it runs
PACKAGE_MAINS = {"offrl_jax.data": "offrl_jax.data.catalogue"}


def entry_points() -> list[str]:
    """Every module with an `if __name__ == "__main__":` block, and every package's `__main__.py` (as its module)."""
    found = []
    for folder in ("offrl_jax", "experiments", "benchmarks"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            if ROOT / "benchmarks" / "adapters" in path.parents:  # run by other libraries' interpreters, not ours
                continue
            if path.name == "__main__.py":
                found.append(".".join(path.relative_to(ROOT).parent.parts))
            elif re.search(r'^if __name__ == "__main__":', path.read_text(), re.MULTILINE):
                found.append(".".join(path.relative_to(ROOT).with_suffix("").parts))
    return found


class Parsed(Exception):
    """Raised by the first parse of a command's `main`, carrying its parser."""


def command_parser(module_name: str, monkeypatch) -> argparse.ArgumentParser:
    """The parser a command builds: its `make_parser()`, or the one its `main` parses with (stopped right there)."""
    module = importlib.import_module(PACKAGE_MAINS.get(module_name, module_name))
    if hasattr(module, "make_parser"):
        return module.make_parser()

    def stop(self, args=None, namespace=None):
        raise Parsed(self)

    monkeypatch.setattr(argparse.ArgumentParser, "parse_known_args", stop)
    with pytest.raises(Parsed) as parsed:
        module.main(["--help"])
    return parsed.value.args[0]


def undocumented(parser: argparse.ArgumentParser) -> list[str]:
    """The arguments of `parser` and its sub-commands shown in --help without a help text."""
    missing = []
    for action in parser._actions:
        if isinstance(action, argparse._HelpAction):
            continue
        name = f"{parser.prog} {'/'.join(action.option_strings) or action.dest}"
        if isinstance(action, argparse._SubParsersAction):
            missing += [f"{parser.prog} {choice.dest}" for choice in action._choices_actions
                        if not (choice.help or "").strip()]
            for sub in action.choices.values():
                missing += undocumented(sub)
        elif not (action.help or "").strip():
            missing.append(name)
    return missing


def test_entry_points_are_found():
    found = set(entry_points())
    assert {"experiments.mujoco_medium", "experiments.theory", "offrl_jax.data", "offrl_jax.rollout",
            "benchmarks.throughput"} <= found
    assert {m for m in found if (ROOT / m.replace(".", "/") / "__main__.py").is_file()} == set(PACKAGE_MAINS)


@pytest.mark.parametrize("module", entry_points())
def test_every_flag_has_help(module, monkeypatch):
    if module == "benchmarks.pytorch":
        pytest.importorskip("torch")
    assert not undocumented(command_parser(module, monkeypatch))


def _str_fields() -> dict[str, list[type]]:
    """{str-typed config field: the configs that have it}."""
    fields: dict[str, list[type]] = {}
    for cls in flags.CONFIGS:
        for name, hint in typing.get_type_hints(cls).items():
            text = hint is str or set(typing.get_args(hint)) == {str, type(None)}  # str, or str | None
            if text and name in {f.name for f in dataclasses.fields(cls)}:
                fields.setdefault(name, []).append(cls)
    return fields


def test_string_config_flags_offer_what_the_config_accepts():
    """Each str field's flag has `choices`, each accepted by every config with that field, and a value outside them is
    refused by the config as well as by the flag."""
    fields = _str_fields()
    assert set(fields) == set(flags.CHOICES)
    parser = argparse.ArgumentParser()
    flags.add_config_flags(parser)
    by_dest = {action.dest: action for action in parser._actions}
    for name, classes in fields.items():
        assert tuple(by_dest[name].choices) == tuple(flags.CHOICES[name])
        for cls in classes:
            for value in flags.CHOICES[name]:
                cls(**{name: value})
            with pytest.raises(ValueError, match=name):
                cls(**{name: "not-a-choice"})


def test_a_family_reusing_a_field_name_with_another_type_is_refused():
    """All families share one flag per field name: a new family's `alpha: int` would be parsed as TD3+BC's float."""
    from offrl_jax.algos.config import Config
    from offrl_jax.algos.sacn import SACNConfig
    from offrl_jax.algos.td3bc import TD3BCConfig

    @dataclasses.dataclass(frozen=True)
    class ClashConfig(Config):
        alpha: int = 3

    @dataclasses.dataclass(frozen=True)
    class SameConfig(Config):
        alpha: float = 1.0  # the same name and type: one flag serves both

    with pytest.raises(ValueError, match="ClashConfig.alpha is <class 'int'> but TD3BCConfig.alpha is <class "
                                         "'float'>: one --alpha flag cannot parse both"):
        flags.add_config_flags(argparse.ArgumentParser(), configs=(TD3BCConfig, SACNConfig, ClashConfig))
    parser = argparse.ArgumentParser()
    flags.add_config_flags(parser, configs=(TD3BCConfig, SACNConfig, SameConfig))
    assert parser.parse_args(["--alpha", "0.5"]).alpha == [0.5]  # a sweepable field: a list of values


def test_the_readme_names_the_experiments_without_dry_run(monkeypatch):
    """README: every study that trains takes --dry-run, and it names those that take none; each module of its
    experiments table is one or the other, as its --help says."""
    readme = (ROOT / "README.md").read_text()
    table = re.findall(r"^\| `(\w+)` \|", readme.split("## Experiments", 1)[1].split("\n## ", 1)[0], re.MULTILINE)
    sentence = re.search(r"every study that\s+trains takes it; ([^)]*) train nothing and take none", readme)
    assert table and sentence, "README's experiments section no longer says which take --dry-run"
    without = set(re.findall(r"`(\w+)`", sentence[1]))
    assert without < set(table)
    for name in table:
        options = {o for a in command_parser(f"experiments.{name}", monkeypatch)._actions for o in a.option_strings}
        assert ("--dry-run" in options) == (name not in without), name


def test_each_family_lists_its_own_fields_with_its_own_help():
    """`--algo X --help` lists X's fields, each with X's help text: a field name may mean different things in two
    families; the fields of other families are not listed."""
    from offrl_jax.algos.config import Config

    @dataclasses.dataclass(frozen=True)
    class FirstConfig(Config):
        weight: float = 1.0  # the first family's weight of its behaviour term

    @dataclasses.dataclass(frozen=True)
    class SecondConfig(Config):
        weight: float = 3.0  # the second family's temperature
        only_second: int = 2  # a field of the second family only

    parser = argparse.ArgumentParser()
    flags.add_config_flags(parser, configs=(FirstConfig, SecondConfig))
    flags.show_family(parser, "first")
    first = " ".join(parser.format_help().split())
    assert "behaviour term. Default: 1.0" in first and "temperature" not in first and "--only-second" not in first
    flags.show_family(parser, "second")
    second = " ".join(parser.format_help().split())
    assert "temperature. Default: 3.0" in second and "behaviour term" not in second and "--only-second" in second
    assert parser.parse_args(["--weight", "2"]).weight == 2.0  # one flag parses it for both


def test_the_main_job_lists_the_fields_of_the_algo_it_trains():
    from tests.entry import run_module

    td3bc = run_module("experiments.mujoco_medium", "--algo", "td3bc", "--help")
    text = " ".join(td3bc.stdout.split())
    assert td3bc.returncode == 0 and "--alpha" in text and "Default: 2.5 (preset published)" in text
    assert not re.search(r"--(expectile|actor-beta|eta)\b", td3bc.stdout)  # not even in the usage line
    plain = run_module("experiments.mujoco_medium", "--help")  # the default --algo's, and how to see another's
    assert plain.stdout == td3bc.stdout and "--algo X --help lists X's" in " ".join(plain.stdout.split())
    iql = run_module("experiments.mujoco_medium", "--algo", "iql", "--help")
    assert iql.returncode == 0 and "--expectile" in iql.stdout
    assert not re.search(r"^ +--alpha\b", iql.stdout, re.MULTILINE)  # TD3+BC's (the module's text names it)


@pytest.mark.parametrize("algo", ["bc", "td3bc", "edac", "cql", "rebrac", "iql"])
def test_every_algo_has_its_help_even_one_the_default_flags_cannot_build(algo):
    """`--algo bc --help`: BC needs `--pretrain actor`, so the study's values cannot be read; its config's are shown."""
    from experiments import mujoco_medium
    from offrl_jax.app.dry_run import state_defaults

    parser = mujoco_medium.make_parser()
    state_defaults(parser, mujoco_medium.build, ["--algo", algo, "--help"])
    text = " ".join(parser.format_help().split())
    assert f"the fields of {algo}'s config" in text and "--gamma GAMMA" in text
