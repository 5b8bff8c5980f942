"""Run CORL's IQL (`algorithms/offline/iql.py` at commit 6afec90, saved beside this file as iql.py, not changed) on
this project's generated data, with the stand-ins of this folder (see run.py), on the CPU:

    OFFRL_STOP_AT=UPDATES python run_iql.py ENV SEED [DETERMINISTIC 0/1] [TAU] [NORMALIZE_REWARD 0/1]

CORL's config for ENV-medium-v2 otherwise (expectile 0.7, beta 3, 1M-update run and so its actor learning-rate
cosine); 10 evaluation episodes every 2,500 updates, each printed as one JSON line {"update", "score"}; the run
ends at the first evaluation at or past OFFRL_STOP_AT updates.
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
import pyrallis  # noqa: E402
import torch  # noqa: E402

pyrallis.wrap = lambda *a, **k: (lambda f: f)  # call train(TrainConfig) directly
torch.set_num_threads(1)
import iql  # noqa: E402

env, seed = sys.argv[1], int(sys.argv[2])
deterministic = len(sys.argv) > 3 and sys.argv[3] == "1"
tau = float(sys.argv[4]) if len(sys.argv) > 4 else 0.005
normalize_reward = len(sys.argv) > 5 and sys.argv[5] == "1"
iql.train(iql.TrainConfig(env=f"{env}-medium-v2", seed=seed, device="cpu", eval_freq=2500, n_episodes=10,
                          iql_deterministic=deterministic, tau=tau, normalize_reward=normalize_reward))
