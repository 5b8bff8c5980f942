"""Run CORL's ReBRAC (`algorithms/offline/rebrac.py` at commit 6afec90, saved beside this file as rebrac.py, not
changed) on this project's generated data: gym.py, d4rl.py and wandb.py here stand in for the old gym API, D4RL's
loader and wandb, so the file reads `hopper-medium` from offrl_jax's catalogue and evaluates on gymnasium's Hopper-v5.

    python run.py ENV SEED EPOCHS ACTOR_BETA CRITIC_BETA [NORMALIZE_STATES 0/1]

One epoch is 1,000 updates; each prints one JSON line {"epoch", "score" (D4RL-normalised, 5 episodes)}.
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
import jax  # noqa: E402

jax.tree_map = jax.tree_util.tree_map  # removed from jax after CORL's file was written
import pyrallis  # noqa: E402

pyrallis.wrap = lambda *a, **k: (lambda f: f)  # call main(Config) directly
import rebrac  # noqa: E402

env, seed, epochs, actor_beta, critic_beta = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), *map(float, sys.argv[4:6])
normalize_states = len(sys.argv) > 6 and sys.argv[6] == "1"
rebrac.main(rebrac.Config(dataset_name=f"{env}-medium-v2", train_seed=seed, num_epochs=epochs, eval_every=1,
                          actor_bc_coef=actor_beta, critic_bc_coef=critic_beta, eval_episodes=5,
                          normalize_states=normalize_states))
