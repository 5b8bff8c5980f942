"""What `--dry-run` prints: every study a command would run, its budget, and each variant's phases and resolved
config, every field with its value (as config.json's `resolved` records it) and where it came from (as its `sources`
does: `offrl_jax.algos.SOURCES`).  Nothing is written, loaded or trained: the dataset's env is the study's own."""
from __future__ import annotations

import json

from offrl_jax.run.study import Study


def describe(studies: list[Study]) -> str:
    lines = ["dry run: nothing is written, loaded or trained"]
    for study in studies:
        seeds = study.seeds
        lines += [f"study {study.name}",
                  f"  dataset: {study.dataset} (env {study.env})"
                  + (f", its first {study.max_transitions:,} transitions" if study.max_transitions else ""),
                  f"  budget: {study.updates:,} updates per variant, {len(seeds)} seed{'s' * (len(seeds) != 1)} "
                  f"({', '.join(map(str, seeds))}), batch {study.batch_size}, evaluation every {study.eval_every:,} "
                  f"updates ({study.eval_episodes} episode{'s' * (study.eval_episodes != 1)} per seed)"
                  + (f", final score over updates {study.final_window[0]:,}-{study.final_window[1]:,}"
                     if study.final_window else "")]
        resolved, sources = study.resolved(), study.sources()
        for v in study.variants:
            config = study.config(v.label)
            phases = ", ".join(f"{s.name} {s.steps:,}" + (f" ({s.updates_per_call} per call)" if s.updates_per_call > 1
                                                          else "") + (" (ends itself, at most)" if s.auto_stop else "")
                               for s in config.schedule(study.updates))
            lines += [f"  variant {v.label}: {v.algo}" + (f", preset {v.preset}" if v.preset else ""),
                      f"    phases: {phases}"]
            lines += [f"    {name} = {json.dumps(value, default=list)}  ({sources[v.label][name]})"
                      for name, value in resolved[v.label].items()]
    return "\n".join(lines)
