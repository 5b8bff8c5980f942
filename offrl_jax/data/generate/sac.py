"""Online SAC in JAX, the behaviour-policy trainer of the generated D4RL-style datasets: the training loop and the
command line.  The learner (networks, losses, the update) is `sac_learner.SAC`; the run directory's state (saving,
resuming, checking) is `sac_run`.

Uniform-random actions for the first `warmup_steps` env steps, then one jitted update per env step fused with choosing
the next action (`SAC.update_and_act`) on a minibatch of the replay of every transition seen so far.

A run directory holds
    log.jsonl                     one line per evaluation (step, returns, normalised score, steps/s, losses, ...)
    checkpoints/actor_<step>.msgpack   actor variables after `step` env steps (flax msgpack, ~300 KB)
    replay/<start>_<end>.npz      every transition seen, in order, one file per evaluation period
    run.json                      config, env, seed, final step, why it stopped
    state.msgpack, state.json     the whole training state (`sac_learner.SACState`: networks, targets, optimisers,
                                  temperature, key) and the numpy RNG at the last evaluation: `--resume` continues
                                  from there (a state.msgpack of another layout is refused)

CLI:  python -m offrl_jax.data.generate.sac --env hopper --steps 1000000 --out DIR [--stop-score 100]
      python -m offrl_jax.data.generate.sac --resume DIR [--steps N]      # continue a stopped or killed run
Stops early at --stop-score (normalised eval score), on SIGINT / SIGTERM, or when DIR/STOP appears; the transitions
seen so far are always written.  A resumed run reloads the state and the replay up to the last evaluation (later
transitions are dropped), marks the interrupted episode's last transition as a time-out, and starts a new episode:
the replay stays a valid sequence of episodes, but the run is not bit-identical to an uninterrupted one.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import signal
import sys
import time
from pathlib import Path
from typing import Any

import flax.serialization
import numpy as np

from offrl_jax.data.generate.collect import evaluate
from offrl_jax.data.generate.replay import ReplayBuffer, reload_replay
from offrl_jax.data.generate.sac_learner import (
    SACConfig,
    make_sac,
    state_from_bytes,
)
from offrl_jax.data.generate.sac_run import check_new_run, discard_unstarted, resume_info, save_state
from offrl_jax.envs.registry import get_env_spec, make_env, normalized_score
from offrl_jax.system.cli import (
    OneLineParser,
    check_writable_dir,
    int_at_least,
    lock_run_dir,
    number,
    positive_int,
    print_error,
    seed_int,
)


def train(
    env_name: str,
    steps: int,
    out_dir: str | Path,
    seed: int = 0,
    cfg: SACConfig = SACConfig(),
    eval_every: int = 10_000,
    eval_episodes: int = 5,
    stop_score: float | None = None,
    progress: bool = True,
    max_episode_steps: int | None = None,
    resume: bool = False,
) -> dict[str, Any]:
    """Train SAC for `steps` env steps (or until a stop), writing the run directory described in the module doc.

    `resume=True` continues the run in `out_dir` from its last saved state (env, seed, config and evaluation settings
    come from its run.json; `steps` may extend the total).
    Returns run.json's content: {"env", "seed", "steps_done", "stopped", "checkpoints": [{"step", "return", ...}]}.
    """
    out = Path(out_dir)
    if resume:
        run, saved, cfg = resume_info(out)
        start = int(saved["step"])
        env_name, seed, eval_every, eval_episodes = run["env"], run["seed"], run["eval_every"], run["eval_episodes"]
        steps = max(steps or run["steps"], start)
        run |= {"steps": steps, "stopped": "running", "resumed_at": run.get("resumed_at", []) + [start]}
        run["checkpoints"] = [c for c in run["checkpoints"] if c["step"] <= start]
    else:
        check_new_run(out)
    spec = get_env_spec(env_name)
    try:
        buffer = ReplayBuffer(spec.obs_dim, spec.act_dim, steps)
    except MemoryError:
        raise ValueError(f"{steps:,} steps: the replay of every transition does not fit in memory") from None
    (out / "checkpoints").mkdir(parents=True, exist_ok=True)
    (out / "replay").mkdir(exist_ok=True)
    if not resume:
        run = {"env": spec.name, "gym_id": spec.gym_id, "seed": seed, "steps": steps,
               "config": dataclasses.asdict(cfg), "eval_every": eval_every, "eval_episodes": eval_episodes,
               "obs_dim": spec.obs_dim, "act_dim": spec.act_dim, "steps_done": 0, "stopped": "running",
               "checkpoints": []}
        start = 0
    (out / "STOP").unlink(missing_ok=True)
    (out / "run.json").write_text(json.dumps(run, indent=1))

    env = make_env(spec.name, max_episode_steps)
    obs_dim, act_dim = env.observation_space.shape[0], env.action_space.shape[0]
    sac = make_sac(obs_dim, act_dim, cfg)
    state = sac.init(seed)
    rng = np.random.default_rng(seed)
    if resume:
        state = state_from_bytes(state, (out / "state.msgpack").read_bytes())
        rng.bit_generator.state = saved["rng"]
        reload_replay(out, buffer, start)

    stop_reason = {"why": None}

    def _on_signal(signum, _frame):
        stop_reason["why"] = signal.Signals(signum).name

    old_handlers = {s: signal.signal(s, _on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=steps, desc=f"SAC {spec.name}", unit="step", mininterval=2.0, smoothing=0.02)
    obs, _ = env.reset(seed=seed + start)
    obs = obs.astype(np.float32)
    action = None
    ep_return, ep_len, last_train_return, last_eval = 0.0, 0, float("nan"), float("nan")
    saved_upto, info, t0, t_period, step = start, {}, time.time(), time.time(), start
    if bar is not None:
        bar.update(start)
    log = (out / "log.jsonl").open("a")
    try:
        for step in range(start + 1, steps + 1):
            if action is None:
                action = rng.uniform(-1.0, 1.0, act_dim).astype(np.float32)
            next_obs, reward, terminated, truncated, _ = env.step(action)
            next_obs = next_obs.astype(np.float32)
            buffer.add(obs, action, reward, next_obs, terminated, truncated and not terminated)
            ep_return += reward
            ep_len += 1
            if terminated or truncated:
                last_train_return, ep_return, ep_len = ep_return, 0.0, 0
                next_obs, _ = env.reset()
                next_obs = next_obs.astype(np.float32)
            obs = next_obs
            action = None
            if step >= cfg.warmup_steps:
                state, info, act = sac.update_and_act(state, buffer.sample(rng, cfg.batch_size), obs)
                action = np.asarray(act)
            if bar is not None:
                bar.update(1)
            if step % eval_every == 0 or step == steps or stop_reason["why"] or (out / "STOP").exists():
                returns = evaluate(spec.name, state.actor.params, eval_episodes, seed=seed + step, hidden=cfg.hidden,
                                   max_episode_steps=max_episode_steps)
                last_eval = float(returns.mean())
                score = float(normalized_score(spec.name, last_eval))
                ckpt = out / "checkpoints" / f"actor_{step:07d}.msgpack"
                ckpt.write_bytes(flax.serialization.to_bytes(state.actor.params))
                buffer.save_range(out / "replay" / f"{saved_upto:07d}_{step:07d}.npz", saved_upto, step)
                saved_upto = step
                save_state(out, state, rng, step)
                now = time.time()
                entry = {"step": step, "eval_return": last_eval, "eval_returns": returns.round(1).tolist(),
                         "normalized_score": round(score, 2), "train_return": last_train_return,
                         "steps_per_s": round(eval_every / max(now - t_period, 1e-9), 1) if step % eval_every == 0
                         else None, "wall_s": round(now - t0, 1),
                         **{k: float(v) for k, v in info.items()}, "checkpoint": str(ckpt.relative_to(out))}
                t_period = now
                log.write(json.dumps(entry) + "\n")
                log.flush()
                run["checkpoints"].append({"step": step, "eval_return": last_eval, "normalized_score": score,
                                           "file": entry["checkpoint"]})
                run["steps_done"] = step
                (out / "run.json").write_text(json.dumps(run, indent=1))
                msg = f"step {step}: eval {last_eval:.0f} (norm {score:.1f}), train ep {last_train_return:.0f}"
                (bar.write if bar is not None else print)(msg)
                if bar is not None:
                    bar.set_postfix(eval=f"{last_eval:.0f}", norm=f"{score:.0f}")
                if stop_score is not None and score >= stop_score:
                    stop_reason["why"] = f"stop_score {stop_score} reached"
                if (out / "STOP").exists():
                    stop_reason["why"] = "STOP file"
            if stop_reason["why"]:
                break
    finally:
        if saved_upto < buffer.size:  # an exception: keep what was seen
            buffer.save_range(out / "replay" / f"{saved_upto:07d}_{buffer.size:07d}.npz", saved_upto, buffer.size)
        log.close()
        if bar is not None:
            bar.close()
        for s, h in old_handlers.items():
            signal.signal(s, h)
        env.close()
        run["steps_done"] = buffer.size
        run["stopped"] = stop_reason["why"] or ("finished" if buffer.size == steps else "error")
        run["wall_s"] = round(time.time() - t0, 1)
        (out / "run.json").write_text(json.dumps(run, indent=1))
    return run


def main(argv: list[str] | None = None) -> int:
    p = OneLineParser(prog="offrl_jax.data.generate.sac", description=__doc__,
                      formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--env", help="hopper | halfcheetah | walker2d (required unless --resume)")
    p.add_argument("--steps", type=positive_int, default=None,
                   help="total env steps (default 1M; on --resume the run's own)")
    p.add_argument("--out", type=Path, help="run directory (must not hold a run already)")
    p.add_argument("--resume", type=Path, default=None,
                   help="continue the run in this directory (--steps may extend it)")
    p.add_argument("--seed", type=seed_int, default=None, help="default 0")
    p.add_argument("--eval-every", type=positive_int, default=None,
                   help="env steps between evaluations (default 10000)")
    p.add_argument("--eval-episodes", type=positive_int, default=None, help="episodes per evaluation (default 5)")
    p.add_argument("--warmup", type=int_at_least(0), default=None,
                   help=f"uniform-random steps before the first update (default {SACConfig.warmup_steps})")
    p.add_argument("--stop-score", type=number(), default=None, help="stop once the normalised eval score reaches this")
    p.add_argument("--no-progress", action="store_true", help="no progress bar (for batch logs)")
    a = p.parse_args(argv)
    settings = {"--env": a.env, "--out": a.out, "--seed": a.seed, "--eval-every": a.eval_every,
                "--eval-episodes": a.eval_episodes, "--warmup": a.warmup}
    try:
        if a.resume is not None:
            if given := [flag for flag, value in settings.items() if value is not None]:
                p.error(f"{', '.join(given)}: a resumed run keeps its own settings; give only --resume DIR "
                        "(and --steps, --stop-score)")
            resume_info(a.resume)
            check_writable_dir(a.resume)
        else:
            if missing := [flag for flag in ("--env", "--out") if settings[flag] is None]:
                p.error(f"{' and '.join(missing)} {'is' if len(missing) == 1 else 'are'} required (or --resume DIR)")
            get_env_spec(a.env)
            check_new_run(a.out)
            check_writable_dir(a.out)
        lock = lock_run_dir(a.resume or a.out)  # one process writes a run directory at a time
    except (OSError, ValueError) as e:
        p.error(str(e))
    cfg = SACConfig(warmup_steps=SACConfig.warmup_steps if a.warmup is None else a.warmup)
    steps = a.steps if a.steps is not None or a.resume else 1_000_000
    try:
        run = train(a.env, steps, a.resume or a.out, 0 if a.seed is None else a.seed, cfg,
                    a.eval_every or 10_000, a.eval_episodes or 5, a.stop_score, not a.no_progress,
                    resume=a.resume is not None)
    except (FileNotFoundError, FileExistsError, ValueError) as e:
        print_error(e)
        return 2
    except KeyboardInterrupt:  # before training began (its own Ctrl-C handling stops it at an evaluation)
        if a.resume is None:
            discard_unstarted(a.out)
        raise
    finally:
        Path(lock.name).unlink(missing_ok=True)
        lock.close()
    best = max(run["checkpoints"], key=lambda c: c["eval_return"], default=None)
    print(json.dumps({"steps_done": run["steps_done"], "stopped": run["stopped"], "best": best}))
    if run["stopped"] in ("SIGINT", "SIGTERM"):
        print(f"interrupted; resume with --resume {a.resume or a.out}", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    from offrl_jax.system.cli import run_main

    run_main(main)
