"""Analytic matmul FLOPs of one gradient update, per algorithm and phase (see benchmarks/README.md, "FLOP counting").

Only dense-layer matmuls are counted (bias adds, LayerNorm, activations, Adam, sampling are O(width) per row and
ignored).  A dense layer (in -> out) on `rows` inputs costs F = 2 * rows * in * out in the forward pass.  Backward:

    gradient w.r.t. the parameters only   dW = X^T dY on every layer (F) + dX = dY W^T on every layer but the first
                                          (the data input needs no gradient)                       ~ 2F - F_first
    gradient w.r.t. the input only        dX on every layer (F); no weight gradients (critic inside an actor loss)
    second order (EDAC diversity)         forward F + input-gradient F, then the parameter gradient of both: 4F

A critic ensemble of N members costs N times one member.  Counts follow what the code performs (TD3+BC's actor loss
evaluates critic 1 only, since commit 4640cb4; it used to evaluate the whole ensemble).
"""
from __future__ import annotations

import dataclasses
from typing import Literal

Grad = Literal["none", "params", "input", "second_order"]


def mlp_dims(in_dim: int, hidden: tuple[int, ...], out_dim: int) -> list[tuple[int, int]]:
    """(in, out) of every dense layer of an `offrl_jax.nets.MLP`."""
    dims = [in_dim, *hidden, out_dim]
    return list(zip(dims[:-1], dims[1:]))


def forward_flops(dims: list[tuple[int, int]], rows: int) -> int:
    return sum(2 * rows * i * o for i, o in dims)


def eval_flops(dims: list[tuple[int, int]], rows: int, grad: Grad = "none", copies: int = 1) -> int:
    """FLOPs of evaluating an MLP (and its backward as requested) on `rows` inputs, for `copies` ensemble members."""
    f = forward_flops(dims, rows)
    first = 2 * rows * dims[0][0] * dims[0][1]
    total = {"none": f, "params": 3 * f - first, "input": 2 * f, "second_order": 6 * f}[grad]
    return copies * total


@dataclasses.dataclass
class Count:
    """A per-call FLOP count with a readable breakdown."""

    terms: list[tuple[str, int]] = dataclasses.field(default_factory=list)

    def add(self, what: str, flops: int) -> None:
        self.terms.append((what, int(flops)))

    @property
    def total(self) -> int:
        return sum(f for _, f in self.terms)


def _is_td3bc(config) -> bool:
    return hasattr(config, "policy_delay")


def update_flops(config, phase: str, obs_dim: int, act_dim: int, batch: int = 256) -> tuple[float, Count]:
    """(FLOPs per gradient update, per-call breakdown) of `phase` ("actor_pretrain", "pretrain", "critic_pretrain",
    "offline_rl") of an algorithm config from `offrl_jax.algos.make_config`.

    A TD3+BC offline-RL call is `policy_delay` updates (critic steps); FLOPs per update = per call / policy_delay.
    """
    h = tuple(config.hidden)
    n = config.num_critics
    critic = mlp_dims(obs_dim + act_dim, h, 1)
    c = Count()
    if _is_td3bc(config):
        actor = mlp_dims(obs_dim, h, act_dim)
        m = getattr(config, "cql_actions", 0)  # TD3+BC's (ReBRAC has no CQL term)
        q_actor = 1 if hasattr(config, "cql_actions") else n  # ReBRAC's actor loss takes the min over all critics

        def bc():
            c.add("actor fwd+grad (BC)", eval_flops(actor, batch, "params"))

        def critic_step(rl: bool):
            if rl or config.lam > 0:
                c.add("target actor fwd (s')", eval_flops(actor, batch))
                c.add(f"target critics fwd x{n}", eval_flops(critic, batch, copies=n))
            c.add(f"critics fwd+grad x{n}", eval_flops(critic, batch, "params", n))
            if getattr(config, "cql_weight", 0.0) > 0:
                c.add(f"CQL uniform actions: critics fwd+grad x{n} on B*{m}",
                      eval_flops(critic, batch * m, "params", n))

        if phase == "actor_pretrain":
            bc()
            return c.total, c
        if phase == "pretrain":
            if config.pretrain in ("actor", "actor+critic"):
                bc()
            if config.pretrain in ("critic", "actor+critic"):
                critic_step(rl=False)
            return c.total, c
        if phase == "offline_rl":
            for _ in range(config.policy_delay):
                critic_step(rl=True)
            c.add("actor fwd+grad", eval_flops(actor, batch, "params"))
            c.add(f"critics fwd + input-grad x{q_actor} (actor loss)", eval_flops(critic, batch, "input", q_actor))
            return c.total / config.policy_delay, c
        raise ValueError(f"unknown TD3BC phase {phase!r}")

    # soft family (EDAC / SAC-N / EDAC+BC / CQL)
    actor = mlp_dims(obs_dim, tuple(getattr(config, "actor_hidden", None) or h), 2 * act_dim)
    q_grad: Grad = "second_order" if config.eta != 0 else "params"
    m = getattr(config, "cql_actions", 0)  # the CQL family's (algos/cql.py)

    def critic_step(rl: bool):
        if rl or config.lam > 0:
            c.add("actor fwd (sample a' at s')", eval_flops(actor, batch))
            c.add(f"target critics fwd x{n}", eval_flops(critic, batch, copies=n))
        what = "fwd + action-grad + 2nd-order param grad (diversity)" if q_grad == "second_order" else "fwd+grad"
        c.add(f"critics {what} x{n}", eval_flops(critic, batch, q_grad, n))
        if rl and getattr(config, "cql_alpha", 0.0) > 0:
            c.add(f"CQL: actor fwd on 2 x B*{m}", eval_flops(actor, 2 * batch * m))
            c.add(f"CQL: critics fwd+grad x{n} on 3 x B*{m}", eval_flops(critic, 3 * batch * m, "params", n))

    if phase == "actor_pretrain":
        c.add("actor fwd (temperature)", eval_flops(actor, batch))
        c.add("actor fwd+grad (soft BC)", eval_flops(actor, batch, "params"))
    elif phase == "critic_pretrain":
        critic_step(rl=False)
    elif phase == "offline_rl":
        c.add("actor fwd (temperature)", eval_flops(actor, batch))
        c.add("actor fwd+grad", eval_flops(actor, batch, "params"))
        c.add(f"critics fwd + input-grad x{n} (actor loss)", eval_flops(critic, batch, "input", n))
        critic_step(rl=True)
    else:
        raise ValueError(f"unknown soft-family phase {phase!r}")
    return c.total, c


def chain_flops(width: int, batch: int, layers: int) -> int:
    """FLOPs of the peak-rate probe: `layers` dense (width x width) layers on a (batch, width) input."""
    return 2 * batch * width * width * layers


def xla_update_flops(algo, phase, obs_dim: int, act_dim: int, batch: int = 256) -> float:
    """XLA's own FLOP estimate (`cost_analysis()["flops"]`, every op, not only matmuls) of one `phase.update` call
    of one seed, divided by `phase.updates_per_call`: a cross-check of `update_flops`."""
    import jax
    import jax.numpy as jnp

    k = phase.updates_per_call
    state = jax.eval_shape(algo.init, jax.random.PRNGKey(0))
    spec = lambda *shape: jax.ShapeDtypeStruct(shape, jnp.float32)  # noqa: E731
    b = {"observations": spec(k, batch, obs_dim), "next_observations": spec(k, batch, obs_dim),
         "actions": spec(k, batch, act_dim), "rewards": spec(k, batch), "terminals": spec(k, batch),
         "timeouts": spec(k, batch), "returns": spec(k, batch), "idx": jax.ShapeDtypeStruct((k, batch), jnp.int32),
         "next_actions": spec(k, batch, act_dim)}  # read by ReBRAC only
    cost = jax.jit(phase.update).lower(state, b, jax.ShapeDtypeStruct((2,), jnp.uint32)).compile().cost_analysis()
    if isinstance(cost, list):
        cost = cost[0]
    return float(cost["flops"]) / k


def main(argv: list[str] | None = None) -> int:
    """Print the matmul GFLOPs of one gradient update of every algorithm and phase, on hopper's dimensions."""
    import argparse

    from offrl_jax.algos import make_config
    from offrl_jax.system.cli import OneLineParser, positive_int

    p = OneLineParser(prog="python -m benchmarks.flops", description=__doc__,
                      formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--batch", type=positive_int, default=256, help="minibatch rows (default %(default)s)")
    p.add_argument("--obs-dim", type=positive_int, default=11, help="observation size (default: hopper's 11)")
    p.add_argument("--act-dim", type=positive_int, default=3, help="action size (default: hopper's 3)")
    p.add_argument("--num-critics", type=positive_int, default=10, help="EDAC ensemble size (default %(default)s)")
    args = p.parse_args(argv)
    cases = [("td3bc", {}, ("pretrain", "offline_rl")),
             ("edac", {"num_critics": args.num_critics}, ("actor_pretrain", "critic_pretrain", "offline_rl"))]
    print(f"{'algorithm':<10} {'phase':<16} {'GFLOP/update':>12}")
    for algo, kw, phases in cases:
        config = make_config(algo, "hopper", **kw)
        for phase in phases:
            flops, _ = update_flops(config, phase, args.obs_dim, args.act_dim, args.batch)
            print(f"{algo:<10} {phase:<16} {flops / 1e9:>12.4f}")
    return 0


if __name__ == "__main__":
    from offrl_jax.system.cli import run_main

    run_main(main)
