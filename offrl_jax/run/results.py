"""A run's curves: curves.csv IO and checks, the (seeds x evaluations) score matrix of a variant, and curves.png.
What is computed from them is `offrl_jax.run.summary`.
"""
from __future__ import annotations

import contextlib
import csv
import io
import math
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from offrl_jax.run.study import Study, Variant
from offrl_jax.system.checkpoint import atomic_write_bytes, atomic_write_text

CURVE_COLUMNS = ("variant", "algo", "seed", "phase", "update", "seconds", "score")  # then each metric logged


def write_curves(path: Path, rows: list[dict]) -> None:
    columns = list(dict.fromkeys([*CURVE_COLUMNS, *(k for row in rows for k in row)]))  # a header even without rows
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=columns, restval="")
    writer.writeheader()
    writer.writerows(rows)
    atomic_write_text(path, buffer.getvalue())


def read_curves(path: Path) -> list[dict]:
    """A curves.csv back as rows: seed and update as ints, text columns as text, the rest as floats; empty cells
    (a metric another variant logs) are left out."""
    ints, texts = {"seed", "update"}, {"variant", "algo", "phase"}
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        rows = []
        try:
            for row in reader:
                if None in row or None in row.values():  # more or fewer cells than the header: cut or edited
                    cells = sum(v is not None for k, v in row.items() if k is not None) + len(row.get(None, []))
                    raise ValueError(f"line {reader.line_num} has {cells} cells for "
                                     f"{len(reader.fieldnames or [])} columns (a truncated or edited file?)")
                rows.append({k: v if k in texts else int(v) if k in ints else float(v) for k, v in row.items()
                             if v != ""})
        except (ValueError, TypeError) as e:
            raise ValueError(f"{path}: not a curves.csv of this project ({e})") from None
    seeds: dict[str, set] = {}  # every evaluation holds every seed of its variant: a file cut at a line is refused
    at: dict[tuple, set] = {}  # an evaluation: its update and env step (the online warm-up's share the hand-over's
    for r in rows:  # update, each at its own env step)
        if "variant" in r and "seed" in r and "update" in r:
            when = (r["variant"], r["update"], r.get("env_steps", 0))
            if r["seed"] in at.get(when, ()):
                step = f" (env step {r['env_steps']:.0f})" if r.get("env_steps") else ""
                raise ValueError(f"{path}: {r['variant']} seed {r['seed']} has two rows at update {r['update']}"
                                 f"{step} (rows of two runs mixed?)")
            seeds.setdefault(r["variant"], set()).add(r["seed"])
            at.setdefault(when, set()).add(r["seed"])
    for (variant, update, _), have in at.items():
        if seeds[variant] - have:
            raise ValueError(f"{path}: {variant} at update {update} has no row for seed(s) "
                             f"{', '.join(map(str, sorted(seeds[variant] - have)))} (a truncated or edited file?)")
    return rows


def check_curve_seeds(path: Path, rows: list[dict], seeds) -> None:
    """Raise ValueError (one line) if a variant of curves.csv rows holds other seeds than its run's `seeds`."""
    for variant in sorted({r["variant"] for r in rows if "variant" in r}):
        found = {r["seed"] for r in rows if r.get("variant") == variant and "seed" in r}
        if found != set(seeds):
            raise ValueError(f"{path}: {variant} has seeds {', '.join(map(str, sorted(found)))} where its run has "
                             f"{', '.join(map(str, seeds))} (rows of another run?)")


def check_curve_algos(path: Path, rows: list[dict], study) -> None:
    """Raise ValueError (one line) if curves.csv rows name another algorithm for a variant than its study does."""
    algos = {v.label: v.algo for v in study.variants}
    if other := next((r for r in rows if "algo" in r and algos.get(r.get("variant"), r["algo"]) != r["algo"]), None):
        raise ValueError(f"{path}: its {other['variant']} rows are {other['algo']}'s, where the run trains "
                         f"{algos[other['variant']]} (rows of another run?)")


def short_curves(rows: list[dict], budgets: dict[str, int]) -> dict[str, int | None]:
    """The variants whose evaluations in curves.csv `rows` end before their budget of updates (TD3 may trim an odd
    budget by 1): {variant: its last evaluated update, None when it has none}."""
    last = {label: max((r["update"] for r in rows if r.get("variant") == label and "update" in r), default=None)
            for label in budgets}
    return {label: u for label, u in last.items() if u is None or u < budgets[label] - 1}


def pretrain_ends_of(rows: list[dict]) -> dict[str, int]:
    """Per variant, the last evaluation before offline RL (0 if none): what `run_study` records as its
    pre-training end (for BC, whose whole run is actor pre-training, the last evaluation).  Online rows come after
    every offline phase and are no pre-training."""
    ends: dict[str, int] = {}
    for r in rows:
        ends.setdefault(r["variant"], 0)
        if r.get("phase", "offline_rl") not in ("offline_rl", "online"):
            ends[r["variant"]] = max(ends[r["variant"]], r["update"])
    return ends


def ended_pretraining(phases: list, rows: list[dict], planned: int) -> int:
    """The pre-training updates of a group: the `planned` ones, or where a self-ending phase ended (its rows say)."""
    if any(p.auto_stop for p in phases):
        return max(pretrain_ends_of(rows).values(), default=planned)
    return planned


def best_scores(rows: list[dict]) -> dict[str, float]:
    """Per variant, the best seed-mean score of its evaluations so far."""
    by_eval: dict[tuple[str, int, int], list[float]] = {}  # an evaluation: its update and env step (the warm-up's
    for r in rows:  # evaluations share the hand-over's update)
        if math.isfinite(r["score"]):
            by_eval.setdefault((r["variant"], r["update"], r.get("env_steps") or 0), []).append(r["score"])
    best: dict[str, float] = {}
    for (label, *_), scores in by_eval.items():
        best[label] = max(best.get(label, -math.inf), sum(scores) / len(scores))
    return best


def metrics_at(rows: list[dict], members: list[tuple[Variant, int]], update: int) -> dict[str, np.ndarray] | None:
    """Every metric of the rows at `update`, one value per member (None if a member has no row there)."""
    at = {(r["variant"], r["seed"]): r for r in rows if r["update"] == update}
    if any((v.label, seed) not in at for v, seed in members):
        return None
    fixed = {"variant", "algo", "seed", "phase", "update", "seconds", "score", "phase_ended"}
    names = [k for k in at[(members[0][0].label, members[0][1])] if k not in fixed]
    try:
        return {k: np.array([at[(v.label, seed)][k] for v, seed in members]) for k in names}
    except KeyError:
        return None


def chunk_rows(members: list[tuple[Variant, int]], chunk, scores: np.ndarray) -> list[dict]:
    """The rows of curves.csv for one evaluated chunk (`offrl_jax.driver.Chunk`), one per member."""
    return [
        {"variant": variant.label, "algo": variant.algo, "seed": seed, "phase": chunk.phase, "update": chunk.update,
         "seconds": round(chunk.seconds, 3), "score": float(scores[m])}
        | ({} if chunk.env_steps is None else {"env_steps": chunk.env_steps})
        | {name: float(np.asarray(value)[m]) for name, value in sorted(chunk.metrics.items())}
        for m, (variant, seed) in enumerate(members)
    ]


def score_matrix(rows: list[dict], label: str, seeds: Sequence[int] | None = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(updates (E,), seconds (E,), scores (S, E)) of one variant, a row per seed of `seeds` in that order (a seed
    without rows all NaN), or per seed of the rows, in ascending order.  The online phase's warm-up evaluations,
    made before its first update, are left out: the hand-over's update is the offline phases' last evaluation
    (`offrl_jax.run.online_summary.online_curves` has them, by env step)."""
    mine = [r for r in rows if r["variant"] == label]
    last_offline = max((r["update"] for r in mine if r.get("phase") != "online"), default=-1)
    mine = [r for r in mine if r.get("phase") != "online" or r["update"] > last_offline]
    updates = np.array(sorted({r["update"] for r in mine}))
    seeds = list(seeds) if seeds is not None else sorted({r["seed"] for r in mine})
    mine = [r for r in mine if r["seed"] in seeds]
    scores = np.full((len(seeds), len(updates)), np.nan)
    seconds = np.zeros(len(updates))
    for r in mine:
        j = int(np.searchsorted(updates, r["update"]))
        scores[seeds.index(r["seed"]), j] = r["score"]
        seconds[j] = r["seconds"]
    return updates, seconds, scores


@contextlib.contextmanager
def all_nan_expected():
    """No RuntimeWarning for the NaN means of all-NaN data (no reference, every seed diverged there): a NaN in a
    summary, a gap in a curve."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        yield


def iqm_band(scores: np.ndarray, resamples: int = 2000) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(IQM, low, high) over seeds at every evaluation of `scores` (S, E): the 95 % bootstrap interval of the IQM
    (the IQM alone where a single seed gives no interval)."""
    from offrl_jax.run import stats
    found = [stats.interval([scores[:, j]], stats.iqm, resamples=resamples) for j in range(scores.shape[1])]
    middle = np.array([e.value for e in found])
    return (middle, np.array([e.value if e.low is None else e.low for e in found]),
            np.array([e.value if e.high is None else e.high for e in found]))


def write_figure(fig, path: Path, dpi: int = 120, pdf: bool = False) -> list[Path]:
    """Write the matplotlib figure `fig` as PNG at `path` (and as PDF beside it with `pdf`), each file atomically,
    and close it; returns the files written."""
    import matplotlib.pyplot as plt

    written = []
    for target, kind in ((path, "png"), (path.with_suffix(".pdf"), "pdf"))[:2 if pdf else 1]:
        buffer = io.BytesIO()
        fig.savefig(buffer, format=kind, dpi=dpi)
        atomic_write_bytes(target, buffer.getvalue())
        written.append(target)
    plt.close(fig)
    return written


def curves_title(name: str, dataset: str, seeds: int) -> str:
    """The title of a run's curves.png: what the band is, or that one seed has none; on two lines where one would
    run past a 7-inch figure's width (about 80 characters at font size 10)."""
    band = f"{seeds} seeds, IQM and stratified-bootstrap 95% CI" if seeds > 1 else "1 seed: no interval"
    title = f"{name}: {dataset}, {band}"
    return title if len(title) <= 80 else f"{name}: {dataset},\n{band}"


@all_nan_expected()
def plot_curves(path: Path, study: Study, rows: list[dict], pretrain_ends: dict[str, int],
                bc_levels: list[tuple[float, str]] = ()) -> None:
    """curves.png: every variant's IQM over seeds with its band, a dotted line where its pre-training ended, and a
    dash-dot line at each (score, label) of `bc_levels` (`bc_level.figure_lines`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for i, v in enumerate(study.variants):
        updates, _, scores = score_matrix(rows, v.label)
        if not len(updates):
            continue
        middle, low, high = iqm_band(scores)
        line, = ax.plot(updates, middle, label=v.label, color=f"C{i}")
        ax.fill_between(updates, low, high, alpha=0.2, color=f"C{i}")
        if pretrain_ends.get(v.label):
            ax.axvline(pretrain_ends[v.label], color=line.get_color(), ls=":", lw=1)
    for score, label in bc_levels:
        ax.axhline(score, color="black", ls="-.", lw=1, label=label)
    ax.set_xlabel("updates (pre-training included; dotted: end of pre-training)")
    ax.set_ylabel("D4RL-normalised score")
    ax.set_title(curves_title(study.name, study.dataset, len(study.seeds)), fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    write_figure(fig, path)
