"""A hand-written TD3+BC update in plain `jax.numpy` (no flax, no driver), to tell framework overhead from XLA's own
cost: the same networks, batch, optimiser and delayed schedule as `offrl_jax.algos.td3bc`, on a synthetic
hopper-shaped dataset.

    python -m benchmarks.handwritten                       # LayerNorm, 1 seed, not vmapped
    python -m benchmarks.handwritten --no-layer-norm --seeds 3 --mode vmap
    python -m benchmarks.handwritten --fused-ln            # LayerNorm+ReLU with a hand-written VJP

Prints critic updates/s summed over seeds (one call = 2 critic updates + 1 actor update, counted as 2 updates, as in
`benchmarks.throughput`).  Seeds run as `--mode vmap` (jax.vmap over a leading axis), `unrolled` (one scan per seed
in the same program) or, for one seed, `single` (no seed axis at all).
"""
from __future__ import annotations

import time

import jax
import jax.numpy as jnp
import numpy as np
import optax

from offrl_jax.system.cli import OneLineParser, positive_int

OBS, ACT, HIDDEN, BATCH, ROWS = 11, 3, 256, 256, 100_000


def dense(key, n_in, n_out):
    lim = 1 / np.sqrt(n_in)
    return {"w": jax.random.uniform(key, (n_in, n_out), minval=-lim, maxval=lim), "b": jnp.zeros(n_out)}


def mlp_init(key, sizes):
    keys = jax.random.split(key, len(sizes) - 1)
    return {"dense": [dense(k, a, b) for k, a, b in zip(keys, sizes[:-1], sizes[1:])],
            "ln": [{"g": jnp.ones(s), "b": jnp.zeros(s)} for s in sizes[1:-1]]}


def ln_relu(x, g, b):
    """relu(LayerNorm(x) * g + b), autodiff."""
    mu = x.mean(-1, keepdims=True)
    var = ((x - mu) ** 2).mean(-1, keepdims=True)
    return jax.nn.relu((x - mu) * jax.lax.rsqrt(var + 1e-6) * g + b)


@jax.custom_vjp
def ln_relu_fused(x, g, b):
    return _fused_fwd(x, g, b)[0]


def _fused_fwd(x, g, b):
    xc = x - x.mean(-1, keepdims=True)
    rstd = jax.lax.rsqrt((xc * xc).mean(-1, keepdims=True) + 1e-6)
    xhat = xc * rstd
    y = jnp.maximum(xhat * g + b, 0.0)
    return y, (xhat, rstd, y, g)


def _fused_bwd(res, dy):
    xhat, rstd, y, g = res
    dz = jnp.where(y > 0, dy, 0.0)
    rows = tuple(range(dz.ndim - 1))
    dxhat = dz * g
    dx = rstd * (dxhat - dxhat.mean(-1, keepdims=True) - xhat * (dxhat * xhat).mean(-1, keepdims=True))
    return dx, jnp.sum(dz * xhat, axis=rows), jnp.sum(dz, axis=rows)


ln_relu_fused.defvjp(_fused_fwd, _fused_bwd)


def make_update(layer_norm: bool, fused: bool, data):
    act_fn = ln_relu_fused if fused else ln_relu

    def mlp(p, x):
        for i, d in enumerate(p["dense"][:-1]):
            x = x @ d["w"] + d["b"]
            x = act_fn(x, p["ln"][i]["g"], p["ln"][i]["b"]) if layer_norm else jax.nn.relu(x)
        return x @ p["dense"][-1]["w"] + p["dense"][-1]["b"]

    actor = lambda p, o: jnp.tanh(mlp(p, o))  # noqa: E731
    critics = lambda p, o, a: jax.vmap(lambda q: mlp(q, jnp.concatenate([o, a], -1))[..., 0])(p)  # noqa: E731  (2, B)
    tx = optax.adam(3e-4)

    def init(key):
        k_a, k_c = jax.random.split(key)
        a = mlp_init(k_a, [OBS, HIDDEN, HIDDEN, ACT])
        c = jax.vmap(lambda k: mlp_init(k, [OBS + ACT, HIDDEN, HIDDEN, 1]))(jax.random.split(k_c, 2))
        copy = lambda t: jax.tree.map(jnp.copy, t)  # noqa: E731
        return {"a": a, "c": c, "a_t": copy(a), "c_t": copy(c), "a_opt": tx.init(a), "c_opt": tx.init(c)}

    def critic_step(s, b, key):
        next_a = actor(s["a_t"], b["next_obs"])
        next_a = jnp.clip(next_a + jnp.clip(0.2 * jax.random.normal(key, next_a.shape), -0.5, 0.5), -1, 1)
        target = b["rew"] + 0.99 * (1 - b["term"]) * critics(s["c_t"], b["next_obs"], next_a).min(0)
        loss = lambda c: ((critics(c, b["obs"], b["act"]) - jax.lax.stop_gradient(target)) ** 2).mean(-1).sum()  # noqa: E731
        updates, opt = tx.update(jax.grad(loss)(s["c"]), s["c_opt"], s["c"])
        return s | {"c": optax.apply_updates(s["c"], updates), "c_opt": opt}

    def actor_step(s, b):
        def loss(a):
            pi = actor(a, b["obs"])
            q = critics(jax.tree.map(lambda x: x[:1], s["c"]), b["obs"], pi)[0]
            return -2.5 / jax.lax.stop_gradient(jnp.abs(q).mean()) * q.mean() + ((pi - b["act"]) ** 2).mean()

        updates, opt = tx.update(jax.grad(loss)(s["a"]), s["a_opt"], s["a"])
        s = s | {"a": optax.apply_updates(s["a"], updates), "a_opt": opt}
        polyak = lambda p, t: optax.incremental_update(p, t, 0.005)  # noqa: E731
        return s | {"a_t": polyak(s["a"], s["a_t"]), "c_t": polyak(s["c"], s["c_t"])}

    def call(s, key):
        k_idx, k1, k2 = jax.random.split(key, 3)
        idx = jax.random.randint(k_idx, (2, BATCH), 0, ROWS)
        b0, b1 = ({k: v[idx[i]] for k, v in data.items()} for i in range(2))
        return actor_step(critic_step(critic_step(s, b0, k1), b1, k2), b1), None

    return init, call


def synthetic(key):
    ks = jax.random.split(key, 4)
    return {"obs": jax.random.normal(ks[0], (ROWS, OBS)), "act": jnp.tanh(jax.random.normal(ks[1], (ROWS, ACT))),
            "rew": jax.random.normal(ks[2], (ROWS,)), "next_obs": jax.random.normal(ks[3], (ROWS, OBS)),
            "term": jnp.zeros((ROWS,))}


def run(layer_norm=True, fused=False, seeds=1, mode="single", calls=200, reps=5) -> float:
    """Critic updates/s summed over seeds (median of `reps` timed chunks of `calls` calls, after one warm-up)."""
    init, call = make_update(layer_norm, fused, synthetic(jax.random.PRNGKey(1)))
    scan = lambda s, k: jax.lax.scan(call, s, jax.random.split(k, calls))[0]  # noqa: E731
    keys = jax.random.split(jax.random.PRNGKey(0), seeds)
    if mode == "single":
        if seeds != 1:
            raise ValueError("--mode single runs one seed; use vmap or unrolled for more")
        state, fn = init(keys[0]), scan
    else:
        state = jax.vmap(init)(keys)
        if mode == "vmap":
            fn = lambda s, k: jax.vmap(scan)(s, jax.random.split(k, seeds))  # noqa: E731
        else:
            def fn(s, k):
                ks = jax.random.split(k, seeds)
                out = [scan(jax.tree.map(lambda x: x[i], s), ks[i]) for i in range(seeds)]  # noqa: B023
                return jax.tree.map(lambda *xs: jnp.stack(xs), *out)
    fn = jax.jit(fn, donate_argnums=0)
    state = jax.block_until_ready(fn(state, jax.random.PRNGKey(1)))
    times = []
    for i in range(reps):
        tic = time.perf_counter()
        state = jax.block_until_ready(fn(state, jax.random.PRNGKey(2 + i)))
        times.append(time.perf_counter() - tic)
    return 2 * calls * seeds / float(np.median(times))


def main(argv=None) -> float:
    p = OneLineParser(prog="benchmarks.handwritten", description=__doc__.split("\n\n")[0])
    p.add_argument("--no-layer-norm", action="store_true", help="networks without LayerNorm (default: with)")
    p.add_argument("--fused-ln", action="store_true", help="LayerNorm+ReLU with a hand-written VJP")
    p.add_argument("--seeds", type=positive_int, default=1, help="seeds trained at once (default %(default)s)")
    p.add_argument("--mode", choices=("single", "vmap", "unrolled"), default=None,
                   help="default: single for 1 seed, vmap otherwise")
    p.add_argument("--calls", type=positive_int, default=200, help="update calls per timed chunk")
    p.add_argument("--reps", type=positive_int, default=5, help="timed chunks, median reported")
    args = p.parse_args(argv)
    mode = args.mode or ("single" if args.seeds == 1 else "vmap")
    if mode == "single" and args.seeds != 1:
        p.error(f"--mode single runs one seed, not {args.seeds}; use vmap or unrolled for more")
    rate = run(not args.no_layer_norm, args.fused_ln, args.seeds, mode, args.calls, args.reps)
    print(f"hand-written TD3+BC, layer_norm={not args.no_layer_norm} fused_ln={args.fused_ln} seeds={args.seeds} "
          f"mode={mode}: {rate:.1f} updates/s")
    return rate


if __name__ == "__main__":
    from offrl_jax.system.cli import run_main

    run_main(main)
