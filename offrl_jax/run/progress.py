"""What a run shows and records as it goes: the progress bar (or one plain line per evaluation in a batch log), and
the rows of every variant, written to curves.csv after each evaluation."""
from __future__ import annotations

import sys
import threading
import time
from pathlib import Path

from tqdm.auto import tqdm

from offrl_jax.run.results import write_curves


class Progress:
    """The progress bar, or with `progress` off one plain line per evaluation (so a batch log shows the run as it
    goes), or with `quiet` nothing (the other processes of a multi-process run); `update`, `set_postfix_str`,
    `write` and `close` as tqdm's, `status` a postfix that a batch log does not get."""

    def __init__(self, total: int, progress: bool, quiet: bool = False):
        self.bar = tqdm(total=total, disable=quiet or not progress, unit="upd", dynamic_ncols=True, file=sys.stderr)
        self.plain, self.quiet, self.total, self.done = not progress and not quiet, quiet, total, 0
        self.tic = time.monotonic()

    def update(self, n: int) -> None:
        self.bar.update(n)
        self.done += n

    def status(self, text: str) -> None:
        """What is going on, on the bar only (not a line of a batch log)."""
        if not self.plain:
            self.bar.set_postfix_str(text)

    def set_postfix_str(self, text: str) -> None:
        if not self.plain:
            return self.bar.set_postfix_str(text)
        minutes, seconds = divmod(int(time.monotonic() - self.tic), 60)
        print(f"[{100 * self.done / self.total:3.0f}% {minutes:3d}:{seconds:02d}] {text}", file=sys.stderr, flush=True)

    def write(self, text: str, file=None) -> None:
        if not self.quiet:
            self.bar.write(text, file=sys.stderr)

    def close(self) -> None:
        self.bar.close()


class Recorder:
    """Rows of every variant (in study order), written to curves.csv after each evaluation (and handed to the
    `logger`, if any; with `path` None, only kept); thread-safe.  `kept`: a resumed run's rows, from its curves.csv,
    so that the file keeps the variants whose groups have not resumed yet (each group's restore replaces its
    variants' rows by its checkpoint's)."""

    def __init__(self, path: Path | None, labels: list[str], logger=None, kept: list[dict] = ()):
        self.path, self.rows, self.logger = path, {label: [] for label in labels}, logger
        for row in kept:
            if row.get("variant") in self.rows:
                self.rows[row["variant"]].append(row)
        self.lock, self.stop = threading.Lock(), threading.Event()

    def set(self, rows_by_label: dict[str, list[dict]]) -> None:
        with self.lock:
            self.rows.update({label: list(rows) for label, rows in rows_by_label.items()})
            if self.path is not None:
                write_curves(self.path, self.all_rows())
            if self.logger is not None:
                try:
                    self.logger.log([row for rows in rows_by_label.values() for row in rows])
                except Exception as e:  # noqa: BLE001 -- the logger is a copy; training and curves.csv go on
                    print(f"warning: the logger failed ({type(e).__name__}: {e}); it is off for the rest of the run",
                          file=sys.stderr)
                    self.logger = None

    def all_rows(self) -> list[dict]:
        return [row for rows in self.rows.values() for row in rows]
