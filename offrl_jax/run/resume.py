"""A resume continues the run its files belong to, or changes nothing.

Every checkpoint carries the identity of what made it: the group's variants and resolved configs, the seeds, the
batch size, the evaluation interval and episodes, and the dataset's SHA-256 (`group_identity`).  Before a resumed
study writes anything, `check_resume` reads every group's checkpoint and refuses, with one line, one that

- was made by another run (its identity differs: another config.json, other hidden sizes, other data; the
  message names what differs, and a config field added to the code since is no difference at its default),
- holds states of other shapes than the study's networks (checkpoints saved before identities were stored are
  checked this way only),
- is past the study's budget or holds rows of variants that are not its own;

and refuses a variant that has evaluations in curves.csv but no checkpoint (resuming would drop them: restore the
checkpoint, or start a new run with --config), and a config.json whose resolved configs were edited.
"""
from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path
from typing import Any

import jax
import numpy as np
from flax import serialization

from offrl_jax.algos import family_of, make_algorithm
from offrl_jax.algos.config import ONLINE_FIELDS
from offrl_jax.driver import INIT, seed_keys
from offrl_jax.run.results import read_curves
from offrl_jax.run.study import Study, Variant
from offrl_jax.system.checkpoint import atomic_write_bytes, checkpoint_contents


class ResumeMismatch(ValueError):
    """The files of a run directory do not belong together; nothing was changed."""


def checkpoint_path(out_dir: Path, group: tuple[Variant, ...], which: str | int = "last") -> Path:
    """checkpoints/<labels>.msgpack: a group's last complete chunk (what --resume continues); with which="best",
    checkpoints/<label>.best.msgpack: one variant's seeds at its best seed-mean evaluation so far; with an update
    number, checkpoints/<labels>.<update>.msgpack: a group's checkpoint kept from that update (`keep_checkpoints`);
    with "handover", checkpoints/<labels>.handover.msgpack: the states an online phase starts from; with "online",
    checkpoints/<labels>.online.msgpack: the online phase's envs and buffers at the last checkpoint
    (`save_online_state`)."""
    if which == "best":
        return out_dir / "checkpoints" / f"{group[0].label}.best.msgpack"
    labels = "+".join(v.label for v in group)
    if which in ("handover", "online"):  # a run with an online phase: where it starts, and where it has got to
        return out_dir / "checkpoints" / f"{labels}.{which}.msgpack"
    return out_dir / "checkpoints" / (f"{labels}.msgpack" if which == "last" else f"{labels}.{int(which)}.msgpack")


def is_resumable(path: Path) -> bool:
    """Whether `path` is a checkpoint that a run writes only once it has a last checkpoint to resume from: any but
    a best, hand-over or online file (`checkpoint_path`: those can be written before the first last checkpoint) or
    an atomic write's temporary file."""
    return (path.suffix == ".msgpack" and not path.name.startswith(".")
            and not path.name.endswith((".best.msgpack", ".handover.msgpack", ".online.msgpack")))


def save_online_state(path: Path, state: dict) -> None:
    """Write the online phase's state (`offrl_jax.online.loop.online_state`), before the checkpoint it belongs to."""
    atomic_write_bytes(path, serialization.msgpack_serialize(state))


def load_online_state(path: Path, key: str) -> dict | None:
    """The online state saved with the checkpoint that `key` describes (`offrl_jax.online.loop.online_state_key`:
    its update and env step, the offline updates and the online settings), or None: none saved, or one of another
    point (a stop between the two writes, a budget changed since), unreadable or incomplete."""
    try:
        state = serialization.msgpack_restore(path.read_bytes())
        return state if state["key"] == key else None
    except Exception:  # noqa: BLE001  anything unreadable: the phase starts again, as with no file
        return None


def kept_updates(out_dir: Path, group: tuple[Variant, ...]) -> list[int]:
    """The updates of a group's kept periodic checkpoints, oldest first."""
    prefix = "+".join(v.label for v in group) + "."
    found = (p.name[len(prefix):-len(".msgpack")] for p in (out_dir / "checkpoints").glob(f"{prefix}*.msgpack"))
    return sorted(int(u) for u in found if u.isdigit())


def group_identity(study: Study, group: tuple[Variant, ...], data_sha256: str) -> dict[str, Any]:
    """What a group's checkpoint depends on (not the budget, which a resume may extend), as JSON-ready data; the
    online fields (`ONLINE_FIELDS`) are the online settings' part, so an offline run's checkpoint starts any online
    phase (`Study.start_from`)."""
    resolved = study.resolved()
    offline = lambda pairs: [list(o) for o in pairs if o[0] not in ONLINE_FIELDS]  # noqa: E731
    identity = {"variants": [[v.label, v.algo, offline(sorted(v.given().items()))] for v in group],
                "resolved": [{k: x for k, x in resolved[v.label].items() if k not in ONLINE_FIELDS} for v in group],
                "seeds": list(study.seeds),
                "batch_size": study.batch_size, "env": study.env, "data": data_sha256,
                "evaluation": {"eval_every": study.eval_every, "eval_episodes": study.eval_episodes}}
    if study.online is not None:  # not its env steps: a budget a resume may extend
        identity["online"] = {k: v for k, v in dataclasses.asdict(study.online).items() if k != "steps"} | {
            "fields": [{k: x for k, x in resolved[v.label].items() if k in ONLINE_FIELDS} for v in group]}
    return json.loads(json.dumps(identity, default=list))  # tuples as lists, as they come back from a file


DATA = "dataset (SHA-256)"  # `identity_differences`' name of the data's fingerprint


def other_data(payload: dict, data_sha256: str) -> str:
    """What a checkpoint trained on other data than this says: both fingerprints, and why data may differ."""
    saved = str(json.loads(payload["identity"]).get("data"))
    return (f"trained on data with SHA-256 {saved[:12]}..., and the data here has {data_sha256[:12]}... (a dataset "
            "generated again, on another machine or by another version of the code, is not bit-identical)")


def identity_differences(saved: dict[str, Any], current: dict[str, Any], config_defaults: list[dict]) -> list[str]:
    """What differs between a checkpoint's identity and the study's, by name.  A config field the checkpoint does
    not know (added to the code since) is no difference while the study keeps its default."""
    names = {"variants": "variants", "seeds": "seeds", "batch_size": "batch size", "env": "env",
             "data": DATA, "evaluation": "evaluation interval or episodes",
             "online": "online settings"}
    # (checkpoints before 2026-12-02 did not record their evaluation; an offline run's has no online settings: an
    # online phase may follow it)
    found = [name for key, name in names.items()
             if saved.get(key) != current.get(key) and not (key in ("evaluation", "online") and key not in saved)]
    for j, (old, new) in enumerate(zip(saved.get("resolved", []), current["resolved"])):
        label = current["variants"][j][0]
        for key in sorted(set(old) | set(new)):
            if key not in old and new[key] == config_defaults[j].get(key):
                continue
            if old.get(key, "(absent)") != new.get(key, "(absent)"):
                found.append(f"{label}: {key} {old.get(key, '(absent)')!r} -> {new.get(key, '(absent)')!r}")
    return found


def state_shapes(study: Study, group: tuple[Variant, ...], obs_dim: int, act_dim: int, rows: int) -> Any:
    """The state-dict of shapes (no arrays are made) that the group's checkpoint must have."""
    config = study.config(group[0].label)
    algo = make_algorithm(config, obs_dim, act_dim, rows)
    members = tuple(s for _ in group for s in study.seeds)
    shapes = jax.eval_shape(jax.vmap(algo.init), seed_keys(members, INIT, 0))
    return serialization.to_state_dict(shapes)


def shape_mismatch(expected: Any, found: Any, where: str = "") -> str | None:
    """The first leaf where two state dicts differ in structure or shape, as text; None when they agree."""
    if isinstance(expected, dict):
        if not isinstance(found, dict) or set(expected) != set(found):
            missing = sorted(set(expected) - set(found)) if isinstance(found, dict) else ["(not a mapping)"]
            extra = sorted(set(found) - set(expected)) if isinstance(found, dict) else []
            return f"{where or '/'}: expected entries {missing[:3]} not found" if missing else \
                f"{where or '/'}: unexpected entries {extra[:3]}"
        for key in expected:
            problem = shape_mismatch(expected[key], found[key], f"{where}/{key}")
            if problem:
                return problem
        return None
    if expected is None or found is None:  # an empty slot (e.g. a model without a target network)
        return None if expected is None and found is None else f"{where}: {found!r:.40}, expected {expected!r:.40}"
    shape = tuple(np.shape(found))
    return None if shape == tuple(expected.shape) else f"{where}: shape {shape}, expected {tuple(expected.shape)}"


def checkpoint_differences(payload: dict, study: Study, group: tuple[Variant, ...],
                           data_sha256: str | None) -> list[str]:
    """What differs between a checkpoint's recorded identity and `group` of `study` on the data with this SHA-256
    (None: the data is not compared)."""
    saved = json.loads(payload["identity"])
    defaults = [json.loads(json.dumps(dataclasses.asdict(family_of(v.algo).config()), default=list)) for v in group]
    return identity_differences(saved, group_identity(study, group, data_sha256 or saved.get("data")), defaults)


def resolved_differences(study: Study, config_path: Path) -> list[str]:
    """Where the `resolved` section of a run's config.json differs from what `study`'s variants resolve to now from
    the values given them, their preset and the tables ("label.field saved -> now"): a value edited by hand, which its
    recorded source does not give; a field only one of them has is no difference (it was added or removed since)."""
    try:
        saved = json.loads(config_path.read_text()).get("resolved") or {}
    except (OSError, ValueError, AttributeError):
        return []  # a config.json that cannot be read was refused when the study was read from it
    now = {v.label: dataclasses.asdict(v.again().config) for v in study.variants}
    now = json.loads(json.dumps(now, default=list))
    return [f"{label}.{key} {value!r} -> {now[label][key]!r}"
            for label, values in saved.items() if isinstance(values, dict) and label in now
            for key, value in values.items() if key in now[label] and value != now[label][key]]


def edited_resolved(study: Study, config_path: Path) -> str | None:
    """Where `config_path`'s `resolved` section was edited, the first half of the refusal naming what differs (its
    second half says what to do instead); None where it was not."""
    differ = resolved_differences(study, config_path)
    return f"{config_path}: its resolved configs are not what its variants give ({'; '.join(differ[:3])})" \
        if differ else None


def saved_rows(out_dir: Path, warn: bool = False) -> list[dict]:
    """A run's curves.csv rows; none if the file is missing or cannot be read (it is then written again from the
    checkpoints, which hold every row), saying so on stderr if `warn`."""
    curves = out_dir / "curves.csv"
    try:
        return read_curves(curves) if curves.is_file() else []
    except (OSError, ValueError, KeyError) as e:
        if warn:
            print(f"warning: {curves} cannot be read ({type(e).__name__}); it is written again from the checkpoints",
                  file=sys.stderr)
        return []


def check_resume(study: Study, out_dir: Path, ds, data_sha256: str) -> None:
    """Raise ResumeMismatch if a checkpoint in `out_dir` does not belong to `study` on `ds` (see the module)."""
    groups = study.groups()
    rows = saved_rows(out_dir, warn=True)
    if (out_dir / "checkpoints").exists() and not (out_dir / "checkpoints").is_dir():
        raise ResumeMismatch(f"{out_dir / 'checkpoints'} is not a directory; nothing was changed")
    for group, _ in groups:
        path, labels = checkpoint_path(out_dir, group), {v.label for v in group}
        if path.exists() and not path.is_file():
            raise ResumeMismatch(f"{path} is not a checkpoint file; nothing was changed")
        handover = checkpoint_path(out_dir, group, "handover")
        if not path.is_file() and study.start_from is not None and not any(
                r.get("env_steps") for r in rows if r.get("variant") in labels):
            if not handover.is_file():  # stopped before its hand-over: it starts from the finished run again
                continue
            path = handover  # stopped before its first online evaluation: it goes on from its hand-over
        if not path.is_file():
            done = [int(r["update"]) for r in rows if r.get("variant") in labels]
            if done:
                raise ResumeMismatch(
                    f"{path} is missing although curves.csv has evaluations of {', '.join(sorted(labels))} up to "
                    f"update {max(done)}, which resuming would drop; restore the checkpoint, or start a new run "
                    f"with --config {out_dir / 'config.json'}; nothing was changed")
            continue
        try:
            payload = serialization.msgpack_restore(path.read_bytes())
            update, history = int(payload["update"]), json.loads(payload["history"])
            states = payload["states"]
        except Exception as e:  # noqa: BLE001 -- any unreadable checkpoint gets the same one line
            raise ResumeMismatch(f"{path}: not a readable checkpoint ({type(e).__name__}); nothing was changed") \
                from None
        if "identity" in payload:
            differ = checkpoint_differences(payload, study, group, data_sha256)
            if differ == [DATA]:
                raise ResumeMismatch(f"{path}: {other_data(payload, data_sha256)}; resuming would go on with other "
                                     f"data: put back the data it trained on, or train again on this data with "
                                     f"--config {out_dir / 'config.json'} --dataset-path {study.dataset}; nothing "
                                     "was changed")
            if differ:
                raise ResumeMismatch(f"{path}: made by another run ({'; '.join(differ[:3])}"
                                     f"{'; ...' if len(differ) > 3 else ''}); nothing was changed")
        problem = shape_mismatch(state_shapes(study, group, ds.obs_dim, ds.act_dim, len(ds)), states)
        if problem:
            raise ResumeMismatch(f"{path}: does not fit the networks of {out_dir / 'config.json'} ({problem}); "
                                 "nothing was changed")
        strangers = sorted({str(r.get("variant")) for r in history} - labels)
        last_row = max((r.get("update", -1) for r in history if isinstance(r, dict)), default=update)
        budget = study.updates + (study.online.updates() if study.online else 0)
        if update > budget or update < 0 or last_row != update or strangers:
            why = (f"it is at update {update}, past the budget of {budget}" if update > budget else
                   f"its update counter ({update}) does not match its last evaluation ({last_row})"
                   if update < 0 or last_row != update else
                   f"it holds rows of other variants ({', '.join(strangers[:3])})")
            raise ResumeMismatch(f"{path}: does not belong to this run ({why}); nothing was changed")
    # the checkpoints are this study's: a resolved config that differs from it was edited in config.json
    if edited := edited_resolved(study, out_dir / "config.json"):
        raise ResumeMismatch(f"{edited}; an edited config.json is refused: start a new run with --config to change a "
                             "value; nothing was changed")


def start_from(study: Study, group: tuple[Variant, ...], data_sha256: str, template: Any, last_update: int):
    """(states, update, seconds, rows) of `group`'s last checkpoint in the finished run `study.start_from`, checked
    to be this group on this data with these settings, at the end of its offline phases; ValueError otherwise."""
    path = checkpoint_path(Path(study.start_from), group)
    if not path.is_file():
        raise ValueError(f"{path}: no checkpoint of {' + '.join(v.label for v in group)} to start from")
    payload = serialization.msgpack_restore(path.read_bytes())
    differ = checkpoint_differences(payload, study, group, data_sha256)
    if differ == [DATA]:
        raise ValueError(f"{path}: {other_data(payload, data_sha256)}; --from goes on with the data the run trained "
                         f"on: put it back, or train that run again on this data (--config "
                         f"{Path(study.start_from) / 'config.json'} --dataset-path {study.dataset}) and fine-tune that")
    if differ:
        raise ValueError(f"{path}: made by another run ({'; '.join(differ[:3])})")
    states, update, seconds, rows = checkpoint_contents(payload, template)
    if update != last_update or any(r.get("env_steps") for r in rows):
        raise ValueError(f"{path}: at update {update}, not at the end of its offline phases ({last_update}): "
                         f"finish it first (--resume {study.start_from})")
    return states, update, seconds, rows
