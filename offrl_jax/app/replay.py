"""A saved run again: a --config replay with some values changed (`replay`), a --resume extended past its budget
(`extend`), and the --parallel a run last ran with (`recorded_parallel`), which a resume and a replay keep."""
from __future__ import annotations

import dataclasses
from pathlib import Path

from offrl_jax.run.provenance import recorded_command
from offrl_jax.run.study import Study
from offrl_jax.system.cli import UsageError

# run flag destination -> the Study field it sets (seeds and --dataset-path are mapped in `replay`)
RUN_FIELDS = ("updates", "eval_every", "eval_episodes", "batch_size", "checkpoint_every", "keep_checkpoints",
              "max_transitions", "clip_actions")


def extend(saved: Study | list[Study], updates: int) -> Study | list[Study]:
    """The saved study (or studies) with a larger budget: --resume --updates N continues a run past its end."""
    studies = saved if isinstance(saved, list) else [saved]
    if any(updates < s.updates for s in studies):
        raise UsageError(f"--updates {updates:,} is less than the saved run's {max(s.updates for s in studies):,}; "
                         "a resumed run can be extended, not shortened")
    if updates != max(s.updates for s in studies) and any(s.online is not None for s in studies):
        raise UsageError("--updates: the saved run fine-tunes online after its offline updates, so they cannot be "
                         "extended on resume; start a new run (or finetune --from a longer offline run)")
    longer = [dataclasses.replace(s, updates=updates) for s in studies]
    return longer if isinstance(saved, list) else longer[0]


def replay(saved: Study | list[Study], args, given: set[str], hparams: dict) -> Study | list[Study]:
    """The saved study (or studies) with the run flags in `given` and the hyper-parameters `hparams` replaced."""
    swept = sorted(k for k, v in hparams.items() if isinstance(v, list))  # `config_values`: a sweep is a list
    if swept:
        raise UsageError(f"--config takes one value per hyper-parameter (got several for {', '.join(swept)}); "
                         "start a new run to sweep")
    fields = {f: getattr(args, f) for f in RUN_FIELDS if f in given}
    if "dataset_path" in given:
        fields["dataset"] = str(args.dataset_path)

    def seeds(study: Study) -> dict:
        """--seeds / --seed-offset over the saved seeds: the one not given is the saved run's (its count, or its
        first seed), not the flag's default."""
        if not given & {"seeds", "seed_offset"}:
            return {}
        first = args.seed_offset if "seed_offset" in given else study.seeds[0]
        return {"seeds": tuple(range(first, first + (args.seeds if "seeds" in given else len(study.seeds))))}

    def one(study: Study) -> Study:
        for field in hparams:  # the variants were made to differ in it (a sweep, an ablation): their labels say so
            values = {repr(v.given().get(field, "(its default)")): v for v in study.variants}
            if len(values) > 1:
                raise UsageError(f"--{field.replace('_', '-')}: the saved run's variants differ in {field} ("
                                 f"{', '.join(f'{v.label}: {k}' for k, v in values.items())}), so one value for all "
                                 "would leave their labels false; start a new run to compare other values")
        variants = tuple(v.with_values(hparams) for v in study.variants)
        return dataclasses.replace(study, variants=variants, **fields, **seeds(study))

    return [one(s) for s in saved] if isinstance(saved, list) else one(saved)


def recorded_parallel(config_path: Path, prog: str, default: int, depth: int = 0) -> int | None:
    """The --parallel of a run's last start or resume by command `prog` (`default` where it was not given, or the
    --parallel of the run its --config replayed, which it took; None: not recorded, or started otherwise, say by
    `run_study` from Python, or replaying a run no longer where it was)."""
    words = recorded_command(config_path)
    if words is None or words[1:3] != ["-m", prog]:
        return None
    flag = lambda name: next((w.split("=", 1)[1] if "=" in w else nxt  # noqa: E731
                              for w, nxt in zip(words, words[1:] + [""]) if w == name or w.startswith(name + "=")),
                             None)
    value = flag("--parallel")
    if value is None and (replayed := flag("--config")):
        path = Path(replayed) / "config.json" if Path(replayed).is_dir() else Path(replayed)
        if not path.is_absolute() or not path.is_file() or depth > 8:
            return None
        return recorded_parallel(path, prog, default, depth + 1)
    try:
        return default if value is None else int(value)
    except ValueError:
        return None
