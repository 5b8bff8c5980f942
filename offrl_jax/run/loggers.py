"""Run tracking where researchers look: TensorBoard (tensorboardX) or Weights & Biases, beside curves.csv.

curves.csv stays the record; a logger gets the same rows as they are written: per evaluation, every seed's score and
metrics (losses, Q, BC error, temperature, ...) and the seed mean, under `<variant>/<metric>` (mean) and
`<variant>/seed<i>/<metric>`, at the global update, plus the training updates per second of the chunk.  The
resolved config of every variant and the run records go in as the run's configuration.  Both writers are optional
extras (`pip install -e ".[tensorboard]"` or `".[wandb]"`); wandb follows its own environment (WANDB_MODE=offline
writes under the run directory without an account; WANDB_PROJECT, default offrl_jax), and a resumed run continues
its wandb run (`RUN/wandb-run-id`).  Only the process that owns the run directory logs; a logger that fails is
turned off with a warning, and the run goes on.
"""
from __future__ import annotations

import json
import math
import os
import uuid
from collections import defaultdict
from pathlib import Path

from offrl_jax.run.results import read_curves
from offrl_jax.system.checkpoint import atomic_write_text

LOGGERS = ("tensorboard", "wandb")
_NOT_SCALARS = {"variant", "algo", "seed", "phase", "update", "phase_ended"}


class _Logger:
    """Sends every row it has not sent yet (rows already in curves.csv when a run resumes count as sent)."""

    def __init__(self, seen: set[tuple]):
        self.seen = seen
        self.last_seconds: dict[tuple, tuple[int, float]] = {}

    def log(self, rows: list[dict]) -> None:
        new = [r for r in rows if (r["variant"], r["seed"], r["update"]) not in self.seen]
        by_eval = defaultdict(list)
        for row in new:
            self.seen.add((row["variant"], row["seed"], row["update"]))
            by_eval[(row["variant"], row["update"])].append(row)
        for (variant, update), group in sorted(by_eval.items(), key=lambda kv: kv[0][1]):
            scalars = {}
            for row in group:
                for key, value in row.items():
                    if key not in _NOT_SCALARS and isinstance(value, (int, float)) and math.isfinite(value):
                        scalars[f"{variant}/seed{row['seed']}/{key}"] = float(value)
            for key in {k for row in group for k in row} - _NOT_SCALARS:
                values = [float(r[key]) for r in group if isinstance(r.get(key), (int, float))
                          and math.isfinite(r[key])]
                if values:
                    scalars[f"{variant}/{key}"] = sum(values) / len(values)
            before = self.last_seconds.get(variant)
            seconds = scalars.get(f"{variant}/seconds")
            if before is not None and seconds is not None and seconds > before[1]:
                scalars[f"{variant}/updates_per_s"] = (update - before[0]) / (seconds - before[1])
            if seconds is not None:
                self.last_seconds[variant] = (update, seconds)
            self.write(scalars, update)

    def write(self, scalars: dict[str, float], step: int) -> None:
        raise NotImplementedError

    def close(self) -> None:
        pass


class _TensorBoard(_Logger):
    def __init__(self, out_dir: Path, config: dict, seen: set[tuple]):
        super().__init__(seen)
        from tensorboardX import SummaryWriter

        self.writer = SummaryWriter(str(out_dir / "tensorboard"))
        self.writer.add_text("config", "```\n" + json.dumps(config, indent=2, default=str) + "\n```")

    def write(self, scalars: dict[str, float], step: int) -> None:
        for tag, value in scalars.items():
            self.writer.add_scalar(tag, value, step)
        self.writer.flush()

    def close(self) -> None:
        self.writer.close()


class _WandB(_Logger):
    def __init__(self, out_dir: Path, config: dict, name: str, seen: set[tuple]):
        super().__init__(seen)
        import wandb

        id_file = out_dir / "wandb-run-id"  # a resumed run continues the same wandb run
        run_id = id_file.read_text().strip() if id_file.is_file() else uuid.uuid4().hex[:12]
        try:
            self.run = wandb.init(project=os.environ.get("WANDB_PROJECT", "offrl_jax"), name=name, id=run_id,
                                  resume="allow", dir=str(out_dir), config=config)
        except Exception as e:  # noqa: BLE001 -- wandb's own errors (no login, no network) as one line
            raise ValueError(f"--logger wandb: {type(e).__name__}: {e} (WANDB_MODE=offline needs no account)") \
                from None
        atomic_write_text(id_file, run_id + "\n")
        self.run.define_metric("update")
        self.run.define_metric("*", step_metric="update")

    def write(self, scalars: dict[str, float], step: int) -> None:
        self.run.log(scalars | {"update": step})

    def close(self) -> None:
        self.run.finish()


def make_logger(kind: str, out_dir: Path, study, config: dict, resume: bool = False) -> _Logger:
    """A logger for the run in `out_dir`; ValueError (one line) for an unknown kind or a writer not installed."""
    if kind not in LOGGERS:
        raise ValueError(f"unknown logger '{kind}'; valid: {', '.join(LOGGERS)}")
    curves = out_dir / "curves.csv"
    seen = {(r["variant"], r["seed"], r["update"]) for r in read_curves(curves)} if resume and curves.is_file() \
        else set()
    try:
        if kind == "tensorboard":
            return _TensorBoard(out_dir, config, seen)
        return _WandB(out_dir, config, f"{study.name}-{out_dir.name}", seen)
    except ImportError:
        extra = "tensorboard" if kind == "tensorboard" else "wandb"
        raise ValueError(f"--logger {kind} needs its writer: pip install -e \".[{extra}]\"") from None
