"""Use what was trained: a run's policy in three lines, and an export that needs no training code.

    from offrl_jax.policy import load_policy
    policy = load_policy("runs/mujoco_medium/20261202-080000", variant="pretrained", seed=0)
    action = policy(obs)                         # (obs_dim,) or (B, obs_dim) raw observations -> actions in [-1, 1]

The policy is the deterministic one the evaluations score (TD3+BC's actor; tanh of the EDAC/CQL actor's mean), on
observations normalised with the training data's statistics, which the checkpoint stores.  It acts from the
variant's last checkpoint (the state after its last complete chunk of updates; `policy.update`), from the one
taken at its best seed-mean evaluation (`checkpoint="best"`), or in a run with an online phase from the states it
started from (`checkpoint="handover"`).

`policy.export(path)` writes the whole policy (normalisation included) as a serialized `jax.export` function with a
symbolic batch size; `load_exported(path)` reads it back with nothing but JAX.
"""
from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import serialization

from offrl_jax.algos import make_algorithm, saved_config
from offrl_jax.envs.registry import get_env_spec
from offrl_jax.run.resume import checkpoint_differences, checkpoint_path, kept_updates, shape_mismatch
from offrl_jax.run.study import Study


@dataclasses.dataclass
class Policy:
    act: Callable[[jax.Array], jax.Array]  # jitted: raw observations (B, obs_dim) -> actions (B, act_dim)
    env: str
    variant: str
    seed: int
    update: int  # the updates its checkpoint had done (pre-training included)
    config: Any  # the variant's resolved algorithm config
    obs_dim: int
    act_dim: int

    def __call__(self, obs) -> np.ndarray:
        """Actions for raw observations (obs_dim,) or (B, obs_dim); a wrong shape or a NaN/inf observation raises
        ValueError (a non-finite input would give non-finite actions)."""
        try:
            if np.iscomplexobj(obs):
                raise TypeError
            obs = np.asarray(obs, np.float32)
        except (TypeError, ValueError):
            raise ValueError(f"observations must be real numbers, shaped ({self.obs_dim},) or "
                             f"(B, {self.obs_dim})") from None
        if obs.ndim not in (1, 2) or obs.shape[-1] != self.obs_dim:
            raise ValueError(f"observations shaped {obs.shape}; {self.env}'s policy takes ({self.obs_dim},) or "
                             f"(B, {self.obs_dim})")
        if not np.isfinite(obs).all():
            bad = np.argwhere(~np.isfinite(obs.reshape(-1, self.obs_dim)))[0]
            raise ValueError(f"observation {bad[0]} has a non-finite value (index {bad[1]}): the policy would "
                             "return non-finite actions")
        actions = np.asarray(self.act(obs[None] if obs.ndim == 1 else obs))
        if not np.isfinite(actions).all():
            bad = int(np.argwhere(~np.isfinite(actions))[0][0])
            raise ValueError(f"the policy's action for observation {bad} is not finite (an observation far outside "
                             "the training data's range, or a checkpoint whose parameters diverged)")
        return actions[0] if obs.ndim == 1 else actions

    def export(self, path: str | Path, platforms: tuple[str, ...] | None = None) -> Path:
        """Write the policy as a serialized `jax.export` function: float32 (b, obs_dim) -> (b, act_dim), for the
        platform it is exported on unless `platforms` names others (e.g. ("cpu", "cuda"))."""
        from jax import export

        (batch,) = export.symbolic_shape("b")
        exported = export.export(jax.jit(self.act), platforms=platforms)(
            jax.ShapeDtypeStruct((batch, self.obs_dim), jnp.float32))
        path = Path(path)
        path.write_bytes(exported.serialize())
        return path


def load_exported(path: str | Path) -> Callable[[np.ndarray], np.ndarray]:
    """An exported policy as `act(obs)`: (B, obs_dim) -> (B, act_dim), or one (obs_dim,) observation -> (act_dim,),
    as the loaded policy takes them; needs only JAX.  Another shape, a non-finite observation, and a file that is
    not an exported policy are refused in one line (ValueError)."""
    from jax import export

    try:
        exported = export.deserialize(bytearray(Path(path).read_bytes()))
        obs_dim = exported.in_avals[0].shape[-1]
    except OSError as e:
        raise ValueError(f"{path}: cannot be read ({e.strerror or type(e).__name__})") from None
    except Exception as e:  # noqa: BLE001 -- whatever the deserializer raises on foreign bytes, one line
        raise ValueError(f"{path}: not an exported policy ({type(e).__name__})") from None

    def act(obs) -> np.ndarray:
        obs = np.asarray(obs, np.float32)
        if obs.ndim not in (1, 2) or obs.shape[-1] != obs_dim:
            raise ValueError(f"observations of shape {tuple(obs.shape)}: expected ({obs_dim},) or (B, {obs_dim})")
        if not np.isfinite(obs).all():
            raise ValueError("observations must be finite (NaN or inf given)")
        if obs.ndim == 2 and obs.shape[0] == 0:
            return np.zeros((0, exported.out_avals[0].shape[-1]), np.float32)
        actions = np.asarray(exported.call(jnp.asarray(obs[None] if obs.ndim == 1 else obs)))
        return actions[0] if obs.ndim == 1 else actions

    return act


def load_policy(run_dir: str | Path, variant: str | None = None, seed: int | None = None,
                checkpoint: str | int = "last") -> Policy:
    """The deterministic policy of `variant` (default: the run's first) and `seed` (default: its first) from the
    run saved in `run_dir`: its last checkpoint, with checkpoint="best" the one taken at the variant's best
    seed-mean evaluation, with "handover" the offline phases' last states where an online phase started, or with
    an update number one kept by `keep_checkpoints`.  Raises ValueError (one line)
    for a run, variant, seed or checkpoint that is not there."""
    seed = int(seed) if isinstance(seed, np.integer) else seed  # numpy integers are integers
    checkpoint = int(checkpoint) if isinstance(checkpoint, np.integer) else checkpoint
    if checkpoint not in ("last", "best", "handover") and (isinstance(checkpoint, bool) or
                                                          not isinstance(checkpoint, int)):
        raise ValueError(f"checkpoint must be 'last', 'best', 'handover' or an update number, not {checkpoint!r}")
    if isinstance(checkpoint, int) and checkpoint < 0:
        raise ValueError(f"checkpoint = {checkpoint} must be an update number >= 0 (or 'last', 'best')")
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int)):
        raise ValueError(f"seed must be an integer (one of the run's seeds), not {seed!r}")
    run_dir = Path(run_dir)
    try:
        raw = json.loads((run_dir / "config.json").read_text())
        study = Study.from_json(json.dumps(raw))
    except (OSError, ValueError, KeyError, TypeError) as e:
        hint = ""
        studies = [p.parent.name for p in sorted(run_dir.glob("*/config.json"))]
        if studies:
            hint = f"; it holds several studies: pass one of them ({', '.join(studies)})"
        raise ValueError(f"{run_dir}: not a saved run ({type(e).__name__}: {e}){hint}") from None
    labels = [v.label for v in study.variants]
    variant = labels[0] if variant is None else variant
    if variant not in labels:
        raise ValueError(f"{run_dir}: no variant '{variant}'; the run has {', '.join(labels)}")
    seed = study.seeds[0] if seed is None else seed
    if seed not in study.seeds:
        raise ValueError(f"{run_dir}: no seed {seed}; the run has seeds {', '.join(map(str, study.seeds))}")
    groups = study.groups()
    group = next(g for g, _ in groups if variant in [v.label for v in g])
    path = checkpoint_path(run_dir, group if checkpoint != "best" else tuple(v for v in group if v.label == variant),
                           checkpoint)
    handover = checkpoint_path(run_dir, group, "handover")
    if checkpoint == "last" and not path.exists() and handover.is_file():
        path = handover  # stopped before its first online evaluation: its last states are the hand-over's
    if path.exists() and not path.is_file():
        raise ValueError(f"{path}: not a checkpoint file (a {'directory' if path.is_dir() else 'special file'})")
    if checkpoint == "handover" and not path.is_file() and study.online is None:
        raise ValueError(f"{run_dir}: '{variant}' has no hand-over checkpoint: the run has no online phase (it was "
                         "never fine-tuned); its last checkpoint is --checkpoint last")
    if not path.is_file():
        kept = kept_updates(run_dir, group)
        hint = f"; kept updates: {', '.join(map(str, kept))}" if kept and isinstance(checkpoint, int) else ""
        raise ValueError(f"{path}: no checkpoint of '{variant}' (the run had not reached its first checkpoint, or "
                         f"its checkpoints were not kept){hint}")
    try:
        payload = serialization.msgpack_restore(path.read_bytes())
        payload["states"], payload["update"]
    except Exception as e:  # noqa: BLE001 -- any unreadable checkpoint gets the same one line
        raise ValueError(f"{path}: not a readable checkpoint ({type(e).__name__}: {e})") from None
    if "obs_mean" not in payload:
        raise ValueError(f"{path}: made before checkpoints stored the observation statistics; train it again "
                         f"(--config {run_dir / 'config.json'}) to act from it")
    if "identity" in payload:  # the checkpoint must be this run's: its variants, configs, seeds and data
        records = [r for r in raw.get("runs", []) if isinstance(r, dict)]
        data_sha256 = ((records[-1].get("dataset") or {}).get("sha256")) if records else None
        differ = checkpoint_differences(payload, study, group, data_sha256)
        if differ:
            raise ValueError(f"{path}: made by another run than {run_dir / 'config.json'} ({'; '.join(differ[:3])})")
    members = [[str(label), int(s)] for label, s in payload.get("members", [])]
    if [variant, seed] not in members:
        raise ValueError(f"{path}: holds no '{variant}' seed {seed} (it holds "
                         f"{', '.join(f'{label} seed {s}' for label, s in members)}); it does not match config.json")
    member = members.index([variant, seed])
    spec = get_env_spec(payload.get("env", study.env))
    v = next(v for v in group if v.label == variant)
    resolved = raw.get("resolved", {}).get(variant)  # the run's own values (checked by Study.from_json above)
    config = saved_config(v.algo, resolved) if resolved else study.config(variant)
    states = jax.tree.map(lambda x: np.asarray(x)[member], payload["states"])
    rows = int(np.shape(states["soft_returns"])[0]) if "soft_returns" in states else 1
    algo = make_algorithm(config, spec.obs_dim, spec.act_dim, rows)
    template = jax.eval_shape(algo.init, jax.random.PRNGKey(0))
    problem = shape_mismatch(serialization.to_state_dict(template), states)
    if problem:
        raise ValueError(f"{path}: does not fit the networks of {run_dir / 'config.json'} ({problem})")
    state = serialization.from_state_dict(template, states)
    state = jax.tree.map(jnp.asarray, state)
    mean, std = jnp.asarray(payload["obs_mean"]), jnp.asarray(payload["obs_std"])
    act = jax.jit(lambda obs: algo.act(state, (obs - mean) / std))
    return Policy(act, spec.name, variant, seed, int(payload["update"]), config, spec.obs_dim, spec.act_dim)

