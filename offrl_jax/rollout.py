"""Watch a trained policy: roll out a run's policy, print each episode's return and D4RL-normalised score, and
optionally write a video.

    python -m offrl_jax.rollout RUN_DIR --variant pretrained --seed 0 --episodes 3
    python -m offrl_jax.rollout RUN_DIR --episodes 1 --video hopper.mp4      # or .gif

Episode e starts from `env.reset(seed=e)`, the start states of the run's evaluations: with --episodes equal to the
run's evaluation episodes, the mean score is that seed's evaluation at the checkpoint's update (the run's last
evaluation when it ended with a checkpoint there), up to float rounding (one observation at a time here, a batch
of seeds x episodes in the run).
Videos render off-screen: MUJOCO_GL defaults to egl here (Mesa's EGL works without a GPU; osmesa also does).
An .mp4 needs imageio-ffmpeg (`pip install -e ".[video]"`); a .gif needs only Pillow.
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

from offrl_jax.system.cli import (
    OneLineParser,
    check_writable_file,
    int_at_least,
    one_line_warnings,
    positive_int,
    print_error,
)


def rollout(policy, episodes: int, video: Path | None = None, max_frames: int | None = None) -> np.ndarray:
    """Undiscounted returns of `episodes` episodes (episode e reset with seed e); frames to `video` if given."""
    from offrl_jax.envs.registry import make_env

    env = make_env(policy.env, disable_env_checker=True, **({"render_mode": "rgb_array"} if video else {}))
    returns, frames = [], []
    try:
        for e in range(episodes):
            obs, _ = env.reset(seed=e)
            total, done = 0.0, False
            while not done:
                if video is not None and (max_frames is None or len(frames) < max_frames):
                    frames.append(env.render())
                action = np.nan_to_num(policy(obs), nan=0.0, posinf=0.0, neginf=0.0)
                obs, reward, terminated, truncated, _ = env.step(action)
                total += float(reward)
                done = terminated or truncated
            returns.append(total)
        if video is not None:
            import imageio.v2 as imageio

            video.parent.mkdir(parents=True, exist_ok=True)
            # written beside it, then renamed: a failed write leaves no half-written video and keeps an old one
            tmp = video.with_name(f".{video.stem}.{os.getpid()}{video.suffix}")
            try:
                imageio.mimwrite(tmp, frames, fps=env.metadata.get("render_fps", 30))
                os.replace(tmp, video)
            finally:
                tmp.unlink(missing_ok=True)
    finally:
        env.close()
    return np.asarray(returns)


def _which(text: str) -> str | int:
    if text in ("last", "best", "handover"):
        return text
    try:
        return int_at_least(0)(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"expected last, best, handover or an update number >= 0, got {text!r}"
                                         ) from None


def main(argv: list[str] | None = None) -> int:
    p = OneLineParser(prog="python -m offrl_jax.rollout", description=__doc__.split("\n\n")[0])
    p.add_argument("run", type=Path, help="a run directory (its config.json and checkpoints/)")
    p.add_argument("--variant", default=None, help="variant label (default: the run's first)")
    p.add_argument("--seed", type=int, default=None, help="which trained seed (default: the run's first)")
    p.add_argument("--checkpoint", type=_which, default="last",
                   help="last (default), best (the one at the variant's best seed-mean evaluation), handover (where "
                        "an online phase started), or an update number (a checkpoint kept by --keep-checkpoints)")
    p.add_argument("--episodes", type=positive_int, default=3, help="episodes to roll out (default %(default)s)")
    p.add_argument("--video", type=Path, default=None, help="write the episodes as a video (.mp4 or .gif)")
    p.add_argument("--max-frames", type=positive_int, default=None, help="stop recording after this many frames")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --video file")
    args = p.parse_args(argv)
    one_line_warnings()
    try:
        if args.video is not None:
            if args.video.suffix.lower() not in (".mp4", ".gif"):
                raise ValueError(f"--video {args.video}: the name must end in .mp4 or .gif")
            if args.video.suffix.lower() == ".mp4":
                try:
                    import imageio_ffmpeg  # noqa: F401
                except ImportError:
                    raise ValueError("an .mp4 needs imageio-ffmpeg (pip install -e \".[video]\"); or write a .gif") \
                        from None
            if args.video.exists() and not args.video.is_dir() and not args.overwrite:
                raise ValueError(f"{args.video} exists; pass --overwrite to replace it")
            check_writable_file(args.video)
            os.environ.setdefault("MUJOCO_GL", "egl")  # before MuJoCo is imported
        from offrl_jax.envs.registry import normalized_score
        from offrl_jax.policy import load_policy

        policy = load_policy(args.run, args.variant, args.seed, args.checkpoint)
        print(f"{policy.env}: variant {policy.variant}, seed {policy.seed}, checkpoint at update {policy.update:,}",
              file=sys.stderr)
        returns = rollout(policy, args.episodes, args.video, args.max_frames)
    except (ValueError, OSError) as e:
        print_error(e)
        return 2
    scores = normalized_score(policy.env, returns)
    for e, (ret, score) in enumerate(zip(returns, scores)):
        print(f"episode {e}: return {ret:9.1f}  score {score:6.1f}")
    print(f"mean: return {returns.mean():9.1f}  score {scores.mean():6.1f}")
    if args.video is not None:
        print(f"video: {args.video}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    from offrl_jax.system.cli import run_main

    run_main(main)
