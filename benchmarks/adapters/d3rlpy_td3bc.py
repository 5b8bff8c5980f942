"""d3rlpy's TD3+BC (d3rlpy 2.8.1) on the CPU, timed as the body of its `fit` loop runs it.

    PYTHON benchmarks/adapters/d3rlpy_td3bc.py [--transitions N] [--updates K] [--repeats R] [--threads T]

PYTHON: an interpreter with `d3rlpy` (and so torch) installed.  One JSON line per repeat on stdout.

One `algo.update(batch)` = one critic update (plus, every `update_actor_interval`-th call, one actor update and the
Polyak updates of both targets).  So `critic_updates_per_s` = calls to `update` per second.  Each timed call is
exactly what fit's loop body does, minus logging/tqdm/evaluation:
    batch = dataset.sample_transition_batch(batch_size)   # d3rlpy/algos/qlearning/base.py:539
    loss  = algo.update(batch)                             # d3rlpy/algos/qlearning/base.py:545
Sampling and update are timed separately (perf_counter around each) and both go into the headline rate.

Network options (--layer-norm):
  pre  (default) Linear -> LayerNorm -> ReLU per hidden layer, via a small custom EncoderFactory in this file
       (d3rlpy has no built-in option for this order; same ops and parameter count as `post`).
  post d3rlpy's own VectorEncoderFactory(use_layer_norm=True): Linear -> ReLU -> LayerNorm.
  none VectorEncoderFactory() plain: Linear -> ReLU.   (--no-layer-norm is an alias for --layer-norm none)
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time

import d3rlpy
import numpy as np
import torch
from d3rlpy.models.encoders import EncoderFactory, VectorEncoderFactory, register_encoder_factory
from d3rlpy.models.torch.encoders import Encoder, EncoderWithAction
from torch import nn

OBS_DIM, ACT_DIM, EPISODE_LEN = 11, 3, 1000


# ---------------------------------------------------------------------------------------------------------------------
# Pre-activation LayerNorm encoders (Linear -> LayerNorm -> ReLU), mirroring d3rlpy's VectorEncoder[WithAction]
# (d3rlpy/models/torch/encoders.py:194-292) except for the LayerNorm position.
def _mlp(in_dim: int, hidden: list[int]) -> nn.Sequential:
    layers: list[nn.Module] = []
    for out_dim in hidden:
        layers += [nn.Linear(in_dim, out_dim), nn.LayerNorm(out_dim), nn.ReLU()]
        in_dim = out_dim
    return nn.Sequential(*layers)


class PreLNVectorEncoder(Encoder):
    def __init__(self, obs_dim: int, hidden: list[int]):
        super().__init__()
        self._layers = _mlp(obs_dim, hidden)

    def forward(self, x):
        return self._layers(x)


class PreLNVectorEncoderWithAction(EncoderWithAction):
    def __init__(self, obs_dim: int, act_dim: int, hidden: list[int]):
        super().__init__()
        self._layers = _mlp(obs_dim + act_dim, hidden)

    def forward(self, x, action):
        return self._layers(torch.cat([x, action], dim=1))


@dataclasses.dataclass()
class PreLNVectorEncoderFactory(EncoderFactory):
    hidden_units: list[int] = dataclasses.field(default_factory=lambda: [256, 256])

    def create(self, observation_shape):
        return PreLNVectorEncoder(observation_shape[0], self.hidden_units)

    def create_with_action(self, observation_shape, action_size, discrete_action=False):
        assert not discrete_action
        return PreLNVectorEncoderWithAction(observation_shape[0], action_size, self.hidden_units)

    @staticmethod
    def get_type() -> str:
        return "pre_ln_vector"


register_encoder_factory(PreLNVectorEncoderFactory)


def encoder_factory(layer_norm: str, hidden: list[int]) -> EncoderFactory:
    if layer_norm == "pre":
        return PreLNVectorEncoderFactory(hidden_units=hidden)
    if layer_norm == "post":
        return VectorEncoderFactory(hidden_units=hidden, activation="relu", use_layer_norm=True)
    return VectorEncoderFactory(hidden_units=hidden, activation="relu", use_layer_norm=False)


# ---------------------------------------------------------------------------------------------------------------------
def synthetic_hopper(n: int, seed: int) -> d3rlpy.dataset.MDPDataset:
    """Hopper-shaped rows: obs N(0,1) (11), actions U[-1,1] (3), rewards N(0,1), ~1% terminals, timeouts every
    1000 steps (and on the last row) where not terminal."""
    rng = np.random.default_rng(seed)
    obs = rng.standard_normal((n, OBS_DIM), dtype=np.float32)
    act = rng.uniform(-1.0, 1.0, (n, ACT_DIM)).astype(np.float32)
    rew = rng.standard_normal((n, 1), dtype=np.float32)
    term = (rng.random(n) < 0.01).astype(np.float32)
    timeout = np.zeros(n, np.float32)
    timeout[EPISODE_LEN - 1::EPISODE_LEN] = 1.0
    timeout[-1] = 1.0
    timeout[term == 1.0] = 0.0  # d3rlpy asserts they never coincide
    return d3rlpy.dataset.MDPDataset(observations=obs, actions=act, rewards=rew, terminals=term, timeouts=timeout,
                                     action_space=d3rlpy.ActionSpace.CONTINUOUS, action_size=ACT_DIM)


def build(args, dataset):
    enc = encoder_factory(args.layer_norm, [args.hidden] * args.layers)
    config = d3rlpy.algos.TD3PlusBCConfig(
        actor_learning_rate=args.lr, critic_learning_rate=args.lr,
        actor_encoder_factory=enc, critic_encoder_factory=enc,
        batch_size=args.batch_size, gamma=0.99, tau=0.005, n_critics=2,
        target_smoothing_sigma=0.2, target_smoothing_clip=0.5,
        alpha=args.alpha, update_actor_interval=args.policy_delay,
        compile_graph=False,  # only takes effect on CUDA anyway (d3rlpy/base.py:371)
    )
    algo = config.create(device="cpu:0")
    algo.build_with_dataset(dataset)
    return algo


def run_updates(algo, dataset, k: int, batch_size: int):
    t_sample = t_update = 0.0
    pc = time.perf_counter
    for _ in range(k):
        t0 = pc()
        batch = dataset.sample_transition_batch(batch_size)
        t1 = pc()
        algo.update(batch)
        t2 = pc()
        t_sample += t1 - t0
        t_update += t2 - t1
    return t_sample, t_update


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--transitions", type=int, default=100_000, help="synthetic dataset rows")
    p.add_argument("--updates", type=int, default=2000, help="timed algo.update calls (= critic updates) per repeat")
    p.add_argument("--repeats", type=int, default=3, help="timed repeats of --updates calls")
    p.add_argument("--threads", type=int, default=1, help="torch.set_num_threads")
    p.add_argument("--warmup", type=int, default=50, help="untimed update calls before the first repeat")
    p.add_argument("--layer-norm", choices=["pre", "post", "none"], default="pre",
                   help="LayerNorm before ReLU (ours), after it (d3rlpy's option) or none")
    p.add_argument("--no-layer-norm", dest="layer_norm", action="store_const", const="none", help="--layer-norm none")
    p.add_argument("--hidden", type=int, default=256, help="hidden width")
    p.add_argument("--layers", type=int, default=2, help="hidden layers")
    p.add_argument("--batch-size", type=int, default=256, help="minibatch rows")
    p.add_argument("--alpha", type=float, default=2.5, help="TD3+BC's alpha")
    p.add_argument("--policy-delay", type=int, default=2, help="critic updates per actor update")
    p.add_argument("--lr", type=float, default=3e-4, help="actor and critic learning rate")
    p.add_argument("--seed", type=int, default=0, help="seed of the data and of d3rlpy")
    p.add_argument("--print-model", action="store_true", help="print the torch modules to stderr")
    args = p.parse_args(argv)

    torch.set_num_threads(args.threads)
    d3rlpy.seed(args.seed)  # seeds numpy (transition sampling), torch and random

    t0 = time.perf_counter()
    dataset = synthetic_hopper(args.transitions, args.seed)
    algo = build(args, dataset)
    setup_s = time.perf_counter() - t0
    modules = algo.impl.modules
    n_params = {k: sum(p.numel() for p in v.parameters())
                for k, v in modules.get_torch_modules().items()}
    print(f"# setup {setup_s:.1f}s, transitions in buffer {dataset.transition_count}, "
          f"episodes {len(dataset.episodes)}, params {n_params}", file=sys.stderr)
    if args.print_model:
        print(modules.policy, modules.q_funcs, file=sys.stderr)

    run_updates(algo, dataset, args.warmup, args.batch_size)

    for r in range(args.repeats):
        c0, w0 = time.process_time(), time.perf_counter()
        t_sample, t_update = run_updates(algo, dataset, args.updates, args.batch_size)
        wall, cpu = time.perf_counter() - w0, time.process_time() - c0
        print(json.dumps({
            "library": "d3rlpy", "version": d3rlpy.__version__, "algo": "td3plusbc",
            "critic_updates_per_s": round(args.updates / wall, 2),
            "layer_norm": args.layer_norm != "none", "layer_norm_position": args.layer_norm,
            "threads": args.threads,
            "repeat": r, "updates": args.updates, "transitions": args.transitions, "batch_size": args.batch_size,
            "policy_delay": args.policy_delay,
            "wall_s": round(wall, 3), "process_cpu_s": round(cpu, 3),
            # under CPU contention wall time includes time stolen by other processes; this one mostly does not
            "critic_updates_per_cpu_s": round(args.updates / cpu, 2),
            "sample_s": round(t_sample, 3), "update_s": round(t_update, 3),
            "sample_fraction": round(t_sample / (t_sample + t_update), 4),
            "sample_ms_per_batch": round(1e3 * t_sample / args.updates, 4),
            "update_ms_per_call": round(1e3 * t_update / args.updates, 4),
            "update_only_critic_updates_per_s": round(args.updates / t_update, 2),
            "torch": torch.__version__, "device": "cpu",
        }), flush=True)


if __name__ == "__main__":
    main()
