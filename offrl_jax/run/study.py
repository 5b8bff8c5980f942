"""What a study is: variants (`offrl_jax.run.variant`: an algorithm and its resolved config) on one dataset and env,
seeds and budget.

A `Study` is plain data with its JSON (`config.json`): `to_json`/`from_json` for the study itself, `record_json`
adding every variant's resolved config and the run records (`offrl_jax.run.provenance`).  `sweep_groups` finds the
variants that can train as one program.
"""
from __future__ import annotations

import dataclasses
import json
from typing import Any

from offrl_jax.algos import Config, family_of
from offrl_jax.data.dataset import Dataset
from offrl_jax.driver import check_call_grid
from offrl_jax.envs.registry import get_env_spec
from offrl_jax.online.config import OnlineConfig
from offrl_jax.run.provenance import run_record
from offrl_jax.run.variant import Variant, check_file_name  # noqa: F401  (where a study's users find them)

MAX_MEMBERS = 1024  # seeds (x sweep values) trained as one program: ~3 MB each for TD3+BC, ~30 for EDAC on 1M rows


@dataclasses.dataclass(frozen=True)
class Study:
    name: str
    dataset: str  # a known name ("hopper-medium") or a path
    env: str
    variants: tuple[Variant, ...]
    seeds: tuple[int, ...] = (0, 1, 2)
    updates: int = 100_000
    eval_every: int = 5_000
    eval_episodes: int = 10
    batch_size: int = 256
    checkpoint_every: int = 0  # 0 = at every evaluation
    keep_checkpoints: int = 0  # besides the last and the best, keep the N newest periodic checkpoints
    # (checkpoints/<labels>.<update>.msgpack; 0: none)
    max_transitions: int | None = None  # train on the first N transitions only (quick runs, tests); never cached
    clip_actions: bool = False  # clip out-of-bounds dataset actions (with a warning) instead of refusing the data
    reference: str | None = None  # label of the from-scratch variant whose final score is the asymptote (None: no
    # asymptote, and no updates/seconds to 90 %)
    final_window: tuple[int, int] | None = None  # final score = mean of evaluations in [lo, hi] (Adroit protocol)
    vmap_sweeps: bool = True  # variants differing only in one sweepable value (e.g. alpha) share one program
    online: OnlineConfig | None = None  # after the offline phases, fine-tune online in the env (None: offline only)
    # a finished run directory whose checkpoints are this study's offline phases: it starts from them (the online
    # phase of `experiments.finetune --from`)
    start_from: str | None = None

    def __post_init__(self):
        for name in ("variants", "seeds", "final_window"):  # JSON's lists, stored as tuples (hashable, comparable)
            if isinstance(getattr(self, name), list):
                object.__setattr__(self, name, tuple(getattr(self, name)))
        if isinstance(self.online, dict):  # as config.json gives it back
            object.__setattr__(self, "online", OnlineConfig(**self.online))
        if self.online is not None and not isinstance(self.online, OnlineConfig):
            raise ValueError(f"Study.online = {self.online!r:.100} must be an OnlineConfig or None")
        if self.start_from is not None and not (isinstance(self.start_from, str) and self.start_from):
            raise ValueError(f"Study.start_from = {self.start_from!r} must be a run directory or None")
        for name in ("name", "dataset", "env"):
            if not isinstance(getattr(self, name), str):
                raise ValueError(f"Study.{name} = {getattr(self, name)!r} must be a string")
        check_file_name("Study.name", self.name)
        for name in ("clip_actions", "vmap_sweeps"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"Study.{name} = {getattr(self, name)!r} must be True or False")
        for name in ("updates", "eval_every", "eval_episodes", "batch_size"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not 0 < value < 2**31:
                raise ValueError(f"Study.{name} = {value!r} must be a positive integer below 2**31")
        if not isinstance(self.seeds, tuple):
            raise ValueError(f"Study.seeds = {self.seeds!r} must be a tuple of integers")
        if not self.seeds:
            raise ValueError("Study.seeds must not be empty")
        if not all(isinstance(s, int) and not isinstance(s, bool) and 0 <= s < 2**31 for s in self.seeds):
            raise ValueError(f"Study.seeds = {self.seeds!r} must be integers in [0, 2**31)")
        if len(set(self.seeds)) != len(self.seeds):
            raise ValueError(f"Study.seeds = {self.seeds!r} must be distinct (a repeated seed is the same run twice)")
        if self.max_transitions is not None and (isinstance(self.max_transitions, bool) or
                                                 not isinstance(self.max_transitions, int) or self.max_transitions < 1):
            raise ValueError(f"Study.max_transitions = {self.max_transitions!r} must be a positive integer or None")
        window = self.final_window
        if window is not None and not (isinstance(window, tuple) and len(window) == 2 and all(
                isinstance(x, int) and not isinstance(x, bool) and x >= 0 for x in window) and window[0] <= window[1]):
            raise ValueError(f"Study.final_window = {window!r} must be two integers lo <= hi, both >= 0 (or None)")
        if self.reference is not None and not isinstance(self.reference, str):
            raise ValueError(f"Study.reference = {self.reference!r} must be a variant label or None")
        for name in ("checkpoint_every", "keep_checkpoints"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f"Study.{name} = {value!r} must be an integer >= 0")
        if not isinstance(self.variants, tuple) or not all(isinstance(v, Variant) for v in self.variants):
            raise ValueError(f"Study.variants = {self.variants!r:.200} must be a tuple of Variant")
        labels = [v.label for v in self.variants]
        if not labels or len(set(labels)) != len(labels):
            raise ValueError(f"Study.variants need unique labels, got {labels}")
        if self.reference is not None and not any(reference_label(self, label) for label in labels):
            raise ValueError(f"Study.reference = {self.reference!r} is not a variant label ({', '.join(labels)})")
        horizon = get_env_spec(self.env).max_episode_steps
        for v in self.variants:  # every variant's config, checked with the budget before anything is written
            if v.env not in ("", self.env):
                raise ValueError(f"variant {v.label!r} has {v.env}'s values, and the study is on {self.env}: make it "
                                 f"on {self.env} (Variant.make / Variant.of with env={self.env!r})")
            planned = v.config.phases(v.config.budget(self.updates))
            check_call_grid(planned, self.eval_every)
            if self.online is not None:
                self.online.check(v.label, planned[-1])
                self.online.rows(horizon)  # a buffer too small for the env's episodes: refused before any training
                if (total := v.config.budget(self.updates) + self.online.updates()) >= 2**31:
                    raise ValueError(f"variant {v.label!r}: its offline and online updates ({total:,}) are past what "
                                     f"the update counter holds (an int32: {2**31 - 1:,})")
        widest = max(len(group) for group, _ in self.groups()) * len(self.seeds)
        if widest > MAX_MEMBERS:
            n = len(self.seeds)
            what = f"{n} seed{'s' * (n != 1)}" + (" x sweep values" if widest > n else "")
            raise ValueError(f"Study.seeds: {what} make {widest:,} members of one program, over the {MAX_MEMBERS:,} "
                             "this library trains at once (every member's networks and optimiser state are in memory "
                             "together)")

    def variant(self, label: str) -> Variant:
        return next(v for v in self.variants if v.label == label)

    def config(self, label: str) -> Config:
        """The resolved, frozen config of the variant labelled `label`."""
        return self.variant(label).config

    def groups(self) -> list[tuple[tuple[Variant, ...], str | None]]:
        """The programs the study trains: (variants, swept name) each; a vmapped sweep group, or one variant alone
        when `vmap_sweeps` is off (see `sweep_groups`)."""
        return sweep_groups(self.variants) if self.vmap_sweeps else [((v,), None) for v in self.variants]

    def resolved(self) -> dict[str, dict[str, Any]]:
        """{label: every field of the variant's config}."""
        return {v.label: dataclasses.asdict(v.config) for v in self.variants}

    def sources(self) -> dict[str, dict[str, str]]:
        """{label: {field: where its resolved value came from}} (`offrl_jax.algos.SOURCES`)."""
        return {v.label: dict(v.sources) for v in self.variants}

    def _json(self) -> dict:
        fields = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        fields |= {"variants": [v.to_json() for v in self.variants],
                   "online": dataclasses.asdict(self.online) if self.online else None}
        return json.loads(json.dumps(fields, default=list)) | {"resolved": self.resolved(), "sources": self.sources()}

    def to_json(self) -> str:
        """The study: its fields, its variants (label, algorithm, preset), their configs (`resolved`) and `sources`."""
        return json.dumps(self._json(), indent=2, default=list)

    def record_json(self, ds: Dataset | None = None, previous: str | None = None,
                    data_sha256: str | None = None) -> str:
        """config.json: the study and the run records so far plus this one."""
        runs = run_records(json.loads(previous)) if previous else []
        raw = self._json() | {"runs": runs + [run_record(ds, self.dataset, data_sha256)]}
        return json.dumps(raw, indent=2, default=list) + "\n"

    @staticmethod
    def from_json(text: str) -> Study:
        """The study saved in a config.json's text; ValueError if it is not one (any structural problem)."""
        try:
            return Study._from_json(text)
        except (KeyError, TypeError, AttributeError, IndexError) as e:
            raise ValueError(f"not a saved study ({type(e).__name__}: {e})") from None

    @staticmethod
    def _from_json(text: str) -> Study:
        raw = json.loads(text)
        run_records(raw)  # what the run wrote about itself (checked here); the study is the rest
        resolved = raw.pop("resolved", {})
        sources = raw.pop("sources", {})
        raw.pop("runs", None)
        if not isinstance(resolved, dict) or not all(isinstance(c, dict) for c in resolved.values()):
            raise ValueError("'resolved' must map each variant to its config (an object)")
        if not isinstance(sources, dict) or not all(isinstance(c, dict) for c in sources.values()):
            raise ValueError("'sources' must map each variant to its fields' sources (an object)")
        if "transitions" in raw:  # runs saved before the cap was renamed
            raw["max_transitions"] = raw.pop("transitions")
        if not isinstance(raw.get("env"), str) or not isinstance(raw.get("dataset"), str):
            raise ValueError("'env' and 'dataset' must be strings")
        record = {"resolved": resolved, "sources": sources}
        raw["variants"] = tuple(Variant.from_json(v, record, raw["env"], raw["dataset"]) for v in raw["variants"])
        raw["seeds"] = tuple(raw["seeds"])
        raw["final_window"] = tuple(raw["final_window"]) if raw.get("final_window") else None
        return Study(**raw)


def run_records(raw: dict) -> list[dict]:
    """The run records of a config.json's contents (each start or resume of the run), checked: a list of objects."""
    runs = raw.get("runs", []) if isinstance(raw, dict) else None
    if not isinstance(runs, list) or not all(isinstance(r, dict) for r in runs):
        raise ValueError("'runs' must be a list of run records (objects)")
    return runs


def reference_label(study: Study, label: str) -> str | None:
    """The from-scratch variant `label` is measured against: `study.reference` (None: none), or in a sweep, where
    labels end in " alpha=2.5" etc., the reference with the same value ("scratch alpha=2.5")."""
    reference = study.reference
    if reference is None:
        return None
    labels = {v.label for v in study.variants}
    if reference in labels:
        return reference
    last = label.rsplit(" ", 1)[-1]
    swept = reference + " " + last if " " in label and "=" in last else None
    return swept if swept in labels else None


def sweep_groups(variants: tuple[Variant, ...]) -> list[tuple[tuple[Variant, ...], str | None]]:
    """Variants of one algorithm whose overrides differ only in one sweepable hyper-parameter (`SWEEPABLE`, e.g.
    TD3+BC's alpha) run as one program: [(variants, swept name or None)], in study order of first member."""
    groups: list[list] = []  # [[variants], swept name or None]
    for v in variants:
        for group in groups:
            key = _swept_name(group[0][0], v)
            if key is not None and group[1] in (None, key):
                group[0].append(v)
                group[1] = key
                break
        else:
            groups.append([[v], None])
    return [(tuple(members), name) for members, name in groups]


def _swept_name(a: Variant, b: Variant) -> str | None:
    if a.algo != b.algo or a.preset != b.preset:
        return None
    da, db = a.given(), b.given()
    diff = [k for k in sorted(da.keys() | db.keys()) if da.get(k) != db.get(k)]
    if len(diff) != 1 or diff[0] not in da or diff[0] not in db:
        return None
    sweepable = family_of(a.algo).config.SWEEPABLE
    return diff[0] if diff[0] in sweepable and all(isinstance(d[diff[0]], (int, float)) for d in (da, db)) else None
