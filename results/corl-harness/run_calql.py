"""Run CORL's offline-to-online Cal-QL (`algorithms/finetune/cal_ql.py` at commit 79294fa, saved beside this file as
cal_ql.py, not changed) on this project's generated data, with the stand-ins of this folder (see run.py): the offline
updates, then one env step and one update per step in gymnasium's env (v5, 1,000-step time limit), on the CPU.

    python run_calql.py ENV SEED OFFLINE_UPDATES ONLINE_STEPS [EVAL_EVERY [EVAL_EPISODES]]

CORL has no Cal-QL config for the MuJoCo datasets, so the values are the file's defaults but for `policy_lr` 1e-4
(every published CORL Cal-QL config's; the file's default is 3e-5, and the temperature's learning rate is the
policy's): `qf_lr` 3e-4, `cql_alpha` and `cql_alpha_online` 10, two hidden critic layers, `mixing_ratio` 0.5, batch
256, states normalised, orthogonal init, dense rewards, no reward normalisation.  EVAL_EVERY (default 5000) counts
loop steps (an update offline, an env step and its update online); EVAL_EPISODES defaults to 10.  Each evaluation
prints one JSON line {"update", "env_step", "score" (D4RL-normalised), "t"} and one line of the last update's metrics
on stdout, and {"evaluation_s"} (its seconds) on stderr.
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

USAGE = "usage: run_calql.py ENV SEED OFFLINE_UPDATES ONLINE_STEPS [EVAL_EVERY [EVAL_EPISODES]]"


def parse(argv):
    if not 4 <= len(argv) <= 6:
        raise ValueError(USAGE)
    env, (seed, offline, online) = argv[0], map(int, argv[1:4])
    every, episodes = [int(v) for v in argv[4:]] + [5000, 10][len(argv) - 4:]
    if env not in ("hopper", "halfcheetah", "walker2d"):
        raise ValueError(f"ENV {env!r} must be hopper, halfcheetah or walker2d (its -medium dataset)")
    if min(offline, online, every, episodes) < 1:
        raise ValueError("OFFLINE_UPDATES, ONLINE_STEPS, EVAL_EVERY and EVAL_EPISODES must be positive")
    return env, seed, offline, online, every, episodes


try:
    ENV, SEED, OFFLINE, ONLINE, EVERY, EPISODES = parse(sys.argv[1:])
except ValueError as e:
    print(f"error: {e}" if str(e).startswith(("usage", "OFFLINE", "ENV")) else f"error: {e}; {USAGE}",
          file=sys.stderr)
    raise SystemExit(2) from None

import json  # noqa: E402
import time  # noqa: E402

import gym  # noqa: E402
import pyrallis  # noqa: E402

pyrallis.wrap = lambda *a, **k: (lambda f: f)  # call train(TrainConfig) directly
import cal_ql as corl  # noqa: E402


def evaluating(evaluate):
    """Marks the evaluation's env steps as such (gym.py) and prints its seconds to stderr, to tell training's time
    from the evaluations'."""
    def call(*a, **k):
        gym.Env.evaluating, t0 = True, time.time()
        try:
            return evaluate(*a, **k)
        finally:
            gym.Env.evaluating = False
            print(json.dumps({"evaluation_s": round(time.time() - t0, 2)}), file=sys.stderr, flush=True)
    return call


corl.eval_actor = evaluating(corl.eval_actor)
corl.train(corl.TrainConfig(device="cpu", env=f"{ENV}-medium-v2", seed=SEED, offline_iterations=OFFLINE,
                            online_iterations=ONLINE, eval_freq=EVERY, n_episodes=EPISODES, policy_lr=1e-4,
                            qf_lr=3e-4, cql_alpha=10.0, cql_alpha_online=10.0, q_n_hidden_layers=2, mixing_ratio=0.5,
                            batch_size=256, normalize=True, orthogonal_init=True, is_sparse_reward=False,
                            normalize_reward=False))
