"""Run CORL's offline-to-online ReBRAC (`algorithms/finetune/rebrac.py` at commit 9aa6be9, saved beside this file as
rebrac_finetune.py, not changed) on this project's generated data, with the stand-ins of this folder (see run.py): the
offline updates, then one env step and one update per step in gymnasium's env (v5, 1,000-step time limit).

    python run_finetune.py ENV SEED OFFLINE_UPDATES ONLINE_STEPS ACTOR_BETA CRITIC_BETA [EVAL_EVERY [EVAL_EPISODES
                           [BATCH]]]

CORL has no fine-tuning config for the MuJoCo medium datasets, so the values are its offline ReBRAC config for
ENV-medium-v2 (the betas given; learning rates 1e-3 and batch 1024 in place of the fine-tuning file's 3e-4 and 256;
the rest of that config equals the file's defaults) and the fine-tuning file's defaults for the online part (half of
each minibatch from the online buffer, no exploration noise, the actor penalty decayed linearly to half and the
critic's dropped online, no warm-up, 2M-row buffers).  EVAL_EVERY (default 5000) counts loop steps (an update
offline, an env step and its update online); there are evaluations also after the last offline update and at the
end; EVAL_EPISODES defaults to 10; BATCH to the offline config's 1024 (256 is the batch of every CORL fine-tuning
config and of `experiments.finetune`).  Each evaluation prints one JSON line {"update", "env_step", "score"
(D4RL-normalised), "t"}.
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

USAGE = ("usage: run_finetune.py ENV SEED OFFLINE_UPDATES ONLINE_STEPS ACTOR_BETA CRITIC_BETA "
         "[EVAL_EVERY [EVAL_EPISODES [BATCH]]]")


def parse(argv):
    if not 6 <= len(argv) <= 9:
        raise ValueError(USAGE)
    env, (seed, offline, online), betas = argv[0], map(int, argv[1:4]), tuple(map(float, argv[4:6]))
    every, episodes, batch = [int(v) for v in argv[6:]] + [5000, 10, 1024][len(argv) - 6:]
    if env not in ("hopper", "halfcheetah", "walker2d"):
        raise ValueError(f"ENV {env!r} must be hopper, halfcheetah or walker2d (its -medium dataset)")
    if min(offline, online, every, episodes, batch) < 1 or min(betas) < 0:
        raise ValueError("OFFLINE_UPDATES, ONLINE_STEPS, EVAL_EVERY, EVAL_EPISODES and BATCH must be positive, the "
                         "betas >= 0")
    return env, seed, offline, online, betas, every, episodes, batch


try:
    ENV, SEED, OFFLINE, ONLINE, (ACTOR_BETA, CRITIC_BETA), EVERY, EPISODES, BATCH = parse(sys.argv[1:])
except ValueError as e:
    print(f"error: {e}" if str(e).startswith(("usage", "OFFLINE", "ENV")) else f"error: {e}; {USAGE}",
          file=sys.stderr)
    raise SystemExit(2) from None

import gym  # noqa: E402
import jax  # noqa: E402
import pyrallis  # noqa: E402
import wandb  # noqa: E402

jax.tree_map = jax.tree_util.tree_map  # removed from jax after CORL's file was written
pyrallis.wrap = lambda *a, **k: (lambda f: f)  # call train(Config) directly
import rebrac_finetune as corl  # noqa: E402


def counted(update):
    def call(*a, **k):
        wandb.updates += 1
        return update(*a, **k)
    return call


def evaluating(evaluate):
    def call(*a, **k):
        gym.Env.evaluating = True
        try:
            return evaluate(*a, **k)
        finally:
            gym.Env.evaluating = False
    return call


corl.update_td3, corl.update_td3_no_targets = counted(corl.update_td3), counted(corl.update_td3_no_targets)
corl.evaluate = evaluating(corl.evaluate)
corl.train(corl.Config(dataset_name=f"{ENV}-medium-v2", train_seed=SEED, num_offline_updates=OFFLINE,
                       num_online_updates=ONLINE, actor_bc_coef=ACTOR_BETA, critic_bc_coef=CRITIC_BETA,
                       actor_learning_rate=1e-3, critic_learning_rate=1e-3, batch_size=BATCH,
                       eval_every=EVERY, eval_episodes=EPISODES))
