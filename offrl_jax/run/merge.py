"""Merging a study's runs: one study from runs of it that each trained some of its variants (say one process per
variant on a GPU), side by side in a new run directory and re-summarised (`merge_runs`), and the hyper-parameters
in which the merged variants of one algorithm differ (`merged_differences`).

With `relabel`, the runs may be studies of different algorithms on the same data and budget (say Cal-QL's and
TD3+BC's fine-tuning runs, each with a `pretrained` arm): every variant is labelled `<algorithm>-<label>`
(`relabelled`: `calql-scratch`, `td3bc-pretrained`), the runs' study names may differ, and the merged study is
named after the dataset and the algorithms (`merged_name`).
"""
from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path

from offrl_jax.run import bc_level
from offrl_jax.run.online_summary import plot_online
from offrl_jax.run.provenance import recorded_data
from offrl_jax.run.results import (
    check_curve_algos,
    check_curve_seeds,
    curves_title,
    plot_curves,
    pretrain_ends_of,
    read_curves,
    short_curves,
    write_curves,
)
from offrl_jax.run.study import Study, reference_label
from offrl_jax.run.summary import summarize, summary_json
from offrl_jax.system.checkpoint import atomic_write_text


def merged_differences(studies: list[Study]) -> list[str]:
    """Hyper-parameters in which variants of one algorithm from different runs differ, besides their pre-training
    (what the merged study compares): "field (label: value, ...)" each, for `merge_runs`'s caller to say."""
    found = []
    variants = [(i, v.algo, v.label, s.resolved()[v.label]) for i, s in enumerate(studies) for v in s.variants]
    for algo in dict.fromkeys(a for _, a, _, _ in variants):
        mine = [(i, label, config) for i, a, label, config in variants if a == algo]
        if len({i for i, _, _ in mine}) < 2:
            continue
        for field in mine[0][2]:
            values = {label: config.get(field) for _, label, config in mine}
            if "pretrain" not in field and len({repr(v) for v in values.values()}) > 1:
                found.append(f"{field} ({', '.join(f'{label}: {v}' for label, v in values.items())})")
    return found


def relabelled(study: Study) -> Study:
    """`study` with every variant labelled `<algorithm>-<label>` ("td3bc-scratch") and its reference with it: the
    runs of different algorithms `merge_runs(relabel=True)` joins, whose labels ("pretrained") would collide."""
    if study.reference is None:
        reference = None
    else:
        algos = sorted({study.variant(r).algo for v in study.variants if (r := reference_label(study, v.label))})
        if len(algos) != 1:  # a study's reference is one algorithm's from-scratch variant (or its sweep)
            raise ValueError(f"{study.name}: its reference {study.reference!r} is variants of {', '.join(algos)}, so "
                             "it has no one algorithm to be labelled with")
        reference = f"{algos[0]}-{study.reference}"
    variants = tuple(dataclasses.replace(v, label=f"{v.algo}-{v.label}") for v in study.variants)
    return dataclasses.replace(study, variants=variants, reference=reference)


def merged_name(studies: list[Study]) -> str:
    """The name of a study merged from `studies` that `relabelled` them: theirs where they agree, else the dataset's
    name and the algorithms, in order, joined by + ("hopper-medium-calql+td3bc")."""
    if len({s.name for s in studies}) == 1:
        return studies[0].name
    data = Path(studies[0].dataset)  # a known name ("hopper-medium") or a path
    data_name = re.sub(r"[^A-Za-z0-9._+=-]+", "-", data.stem if data.suffix else data.name).strip("-.") or "data"
    algos = dict.fromkeys(v.algo for s in studies for v in s.variants)
    return f"{data_name}-{'+'.join(algos)}"


def merge_runs(run_dirs: list[Path], out_dir: Path, behaviour: float | None = None,
               relabel: bool = False) -> list[dict]:
    """One study from runs of it that each trained some of its variants (say one process per variant on a GPU):
    their variants and curves side by side in `out_dir` (config.json, curves.csv, summary.json, curves.png, and
    online.png for a study with an online phase), re-summarised, so that the from-scratch asymptote and the
    speed-ups reach every variant.  The runs must agree on everything but their variants (and checkpoint interval);
    `out_dir` must not hold a run yet.  With `relabel`, runs of different algorithms: every variant labelled
    `<algorithm>-<label>` (`relabelled`) in config.json, curves.csv and summary.json, and the runs' names may
    differ (`merged_name`)."""
    if (out_dir / "config.json").exists():
        raise FileExistsError(f"{out_dir} already holds a run; merge into a new directory")
    studies = []
    for d in run_dirs:
        if not (d / "config.json").exists() or not (d / "curves.csv").exists():
            raise FileNotFoundError(f"{d}: not a run directory (config.json and curves.csv expected)")
        try:
            studies.append(Study.from_json((d / "config.json").read_text()))
        except ValueError as e:
            raise ValueError(f"{d / 'config.json'}: {e}") from None
    own = ("variants", "reference", "checkpoint_every", "keep_checkpoints") + (("name",) if relabel else ())
    shared = [{k: v for k, v in dataclasses.asdict(s).items() if k not in own} for s in studies]
    for d, fields in zip(run_dirs[1:], shared[1:]):
        if differ := [k for k in fields if fields[k] != shared[0][k]]:
            hint = " (--relabel merges runs of different algorithms)" if differ == ["name"] else ""
            raise ValueError(f"{d} is not the same study as {run_dirs[0]}: {', '.join(differ)} differ{hint}")
    shas = {d: recorded_data(d / "config.json") for d in run_dirs}  # the data each trained on, where recorded
    if len(set(shas.values()) - {None}) > 1:
        raise ValueError("the runs trained on different data (config.json's dataset SHA-256: "
                         + ", ".join(f"{d}: {sha[:8] if sha else 'none recorded'}" for d, sha in shas.items()) + ")")
    merged = [relabelled(s) for s in studies] if relabel else studies
    if relabel:  # two runs of one algorithm that trained one arm each
        seen: dict[str, Path] = {}
        for d, s in zip(run_dirs, merged):
            if twice := next((v.label for v in s.variants if v.label in seen), None):
                raise ValueError(f"{seen[twice]} and {d} both trained {twice}; merge runs of different variants")
            seen |= {v.label: d for v in s.variants}
    variants = tuple(v for s in merged for v in s.variants)
    # a run without the from-scratch variant names no reference; the one that trained it does
    references = sorted({s.reference for s in merged if s.reference is not None})
    if len(references) > 1:
        raise ValueError(f"the runs name different reference variants: {', '.join(references)}")
    reference = references[0] if references else None
    study = dataclasses.replace(studies[0], variants=variants, reference=reference,  # checks labels are unique
                                name=merged_name(studies) if relabel else studies[0].name)
    rows = []
    for d, s, m in zip(run_dirs, studies, merged):
        mine = read_curves(d / "curves.csv")
        check_curve_seeds(d / "curves.csv", mine, s.seeds)
        check_curve_algos(d / "curves.csv", mine, s)
        short = short_curves(mine, {v.label: s.updates for v in s.variants})
        if short:
            raise ValueError(f"{d / 'curves.csv'}: ends before the run's {s.updates:,} updates ("
                             f"{', '.join(f'{label} at {u or 0:,}' for label, u in short.items())}); merge finished "
                             "runs")
        label = {v.label: w.label for v, w in zip(s.variants, m.variants)}  # the run's label -> the merged study's
        rows += [r | {"variant": label.get(r["variant"], r["variant"])} for r in mine]
        if behaviour is None and (d / "summary.json").is_file():
            try:
                behaviour = next((x["behaviour_score"] for x in json.loads((d / "summary.json").read_text())
                                  if x.get("behaviour_score") is not None), None)
            except (json.JSONDecodeError, TypeError, AttributeError):
                pass
    ends = pretrain_ends_of(rows)
    summary = summarize(study, rows, ends, behaviour)
    out_dir.mkdir(parents=True, exist_ok=True)
    records = [r for d in run_dirs for r in json.loads((d / "config.json").read_text()).get("runs", [])]
    atomic_write_text(out_dir / "config.json", study.record_json(previous=json.dumps({"runs": records})))
    write_curves(out_dir / "curves.csv", rows)
    atomic_write_text(out_dir / "summary.json", summary_json(summary))
    plot_curves(out_dir / "curves.png", study, rows, ends, bc_level.figure_lines(summary))
    if study.online is not None:
        plot_online(out_dir / "online.png", [v.label for v in study.variants], rows, study.seeds,
                    curves_title(study.name, "online phase", len(study.seeds)), behaviour)
    return summary
