"""fql's ReBRAC agent (github.com/seohongpark/fql, `agents/rebrac.py`), timed as its `main.py` trains offline.

    PYTHON benchmarks/adapters/fql_rebrac.py --source CHECKOUT [--transitions N] [--updates K] [--repeats R]

PYTHON: an interpreter with jax, flax, optax, distrax and ml_collections; CHECKOUT: a checkout of fql, whose `agents/`
and `utils/` are imported from there, never copied.  Their loop body, as `main.py` runs it offline: a numpy batch
from their `ReplayBuffer` (`return_next_actions` on, as `main.py` sets it for rebrac), then the jitted
`agent.update(batch, full_update=(i % actor_freq == 0))`: one critic update per call, the actor and targets every
`actor_freq` (2).  Their `get_config()` except the widths (`--hidden`, both networks; theirs 4x512, ours
3x256), the batch (256, theirs too) and the activation (`--activation`: ReLU as ours, where their MLP's default is
GELU); LayerNorm in the critic only, as ours (theirs after the activation, ours before it: the same work).  Their
one Adam steps every parameter each update (the actor's and the targets' too, with zero gradients) and logs
gradient statistics: their loop's own cost, kept.  One warm-up of K updates (it compiles both `full_update`
variants), then R timed repeats; one JSON line per repeat on stdout.
"""
import argparse
import json
import sys
import time
from pathlib import Path

p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
p.add_argument("--source", required=True, type=Path, help="a checkout of github.com/seohongpark/fql")
p.add_argument("--transitions", type=int, default=100_000)
p.add_argument("--updates", type=int, default=1000, help="critic updates (calls of agent.update) per timed repeat")
p.add_argument("--repeats", type=int, default=3)
p.add_argument("--hidden", type=int, nargs="+", default=[256, 256, 256])
p.add_argument("--batch", type=int, default=256)
p.add_argument("--activation", choices=("relu", "gelu"), default="relu",
               help="hidden activation: relu, ours (default), or gelu, their MLP's default")
a = p.parse_args()
if not (a.source / "agents" / "rebrac.py").is_file():
    sys.exit(f"error: {a.source}: no agents/rebrac.py (--source takes a checkout of github.com/seohongpark/fql)")
sys.path.insert(0, str(a.source.resolve()))

import flax.linen as nn  # noqa: E402
import jax  # noqa: E402
import numpy as np  # noqa: E402
import utils.networks  # noqa: E402
from agents.rebrac import ReBRACAgent, get_config  # noqa: E402
from utils.datasets import ReplayBuffer  # noqa: E402

if a.activation == "relu":  # their Value and Actor build `MLP` by its module-global name: a subclass stands in

    class ReluMLP(utils.networks.MLP):
        activations: object = nn.relu

    utils.networks.MLP = ReluMLP

rng = np.random.default_rng(0)
n = a.transitions
terminals = np.zeros(n, np.float32)
terminals[999::1000] = 1.0  # episode ends every 1000 rows, as their d4rl loader marks them
data = dict(observations=rng.standard_normal((n, 11)).astype(np.float32),
            actions=rng.uniform(-1, 1, (n, 3)).astype(np.float32),
            rewards=rng.standard_normal(n).astype(np.float32),
            terminals=terminals, masks=1.0 - (rng.random(n) < 0.01).astype(np.float32),
            next_observations=rng.standard_normal((n, 11)).astype(np.float32))
buffer = ReplayBuffer.create_from_initial_dataset(data, size=n + 1)  # as main.py without balanced sampling
buffer.return_next_actions = True
config = get_config()
config["actor_hidden_dims"] = config["value_hidden_dims"] = tuple(a.hidden)
config["batch_size"] = a.batch
example = buffer.sample(1)
agent = ReBRACAgent.create(0, example["observations"], example["actions"], config)


def loop(agent, k):
    info = None
    for i in range(1, k + 1):
        batch = buffer.sample(config["batch_size"])
        agent, info = agent.update(batch, full_update=(i % config["actor_freq"] == 0))
    jax.block_until_ready((agent, info))
    return agent


tic = time.perf_counter()
agent = loop(agent, a.updates)
warmup_s = time.perf_counter() - tic
for r in range(a.repeats):
    tic, cpu = time.perf_counter(), time.process_time()
    agent = loop(agent, a.updates)
    wall, cpu = time.perf_counter() - tic, time.process_time() - cpu
    print(json.dumps({"library": "fql", "algo": "rebrac", "jax": jax.__version__, "repeat": r, "updates": a.updates,
                      "hidden": a.hidden, "activation": a.activation, "critic_layer_norm": config["layer_norm"],
                      "actor_layer_norm": config["actor_layer_norm"], "batch": config["batch_size"],
                      "warmup_s": round(warmup_s, 2), "wall_s": round(wall, 3), "cpu_s": round(cpu, 3),
                      "critic_updates_per_s": round(a.updates / wall, 2)}), flush=True)
