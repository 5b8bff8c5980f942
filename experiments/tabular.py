"""The paper's motivational example (Section 3, Table 1): offline tabular Q-learning from zero vs every-visit
Monte-Carlo initialisation.

The MDP (the figure is missing from the paper's text; it follows from Table 1): states 0-3 on a line, actions
-> and <-, rewards r(0,->) = 0, r(1,<-) = -1, r(1,->) = -2, r(2,->) = +3, state 3 terminal, gamma = alpha = 1.
The one offline trajectory is 0 -> 1 <- 0 -> 1 -> 2 -> 3.  One epoch = one Q-learning update per transition, in
trajectory order; the max at s' is over the actions the data shows in s'.

    python -m experiments.tabular          # the table
    python -m experiments.tabular --json   # {"zero": [[Q(0,->), Q(1,<-), Q(1,->), Q(2,->)] per epoch 0..3], "mc": ...}
"""
from __future__ import annotations

import json

import numpy as np

from offrl_jax.data.returns import returns_to_go
from offrl_jax.system.cli import OneLineParser

RIGHT, LEFT = "->", "<-"
# (s, a, r, s', terminal) in trajectory order
TRAJECTORY = [(0, RIGHT, 0.0, 1, 0), (1, LEFT, -1.0, 0, 0), (0, RIGHT, 0.0, 1, 0), (1, RIGHT, -2.0, 2, 0),
              (2, RIGHT, 3.0, 3, 1)]
PAIRS = [(0, RIGHT), (1, LEFT), (1, RIGHT), (2, RIGHT)]  # the table's columns


def mc_initialisation(gamma: float = 1.0) -> dict[tuple[int, str], float]:
    """Every-visit Monte-Carlo estimate of Q for each (s, a) in the data, via the library's returns_to_go."""
    rewards = np.array([t[2] for t in TRAJECTORY], np.float32)
    terminals = np.array([t[4] for t in TRAJECTORY], np.float32)
    returns = np.asarray(returns_to_go(rewards, terminals, np.zeros_like(terminals), gamma))
    visits: dict[tuple[int, str], list[float]] = {}
    for (s, a, *_), g in zip(TRAJECTORY, returns):
        visits.setdefault((s, a), []).append(float(g))
    return {pair: float(np.mean(gs)) for pair, gs in visits.items()}


def q_learning(q: dict[tuple[int, str], float], epochs: int = 3, gamma: float = 1.0,
               lr: float = 1.0) -> list[list[float]]:
    """Q values of the table's columns after each epoch 0..epochs."""
    q = dict(q)
    history = [[q[p] for p in PAIRS]]
    for _ in range(epochs):
        for s, a, r, s_next, terminal in TRAJECTORY:
            next_values = [v for (state, _), v in q.items() if state == s_next]
            bootstrap = 0.0 if terminal or not next_values else max(next_values)
            q[(s, a)] += lr * (r + gamma * bootstrap - q[(s, a)])
        history.append([q[p] for p in PAIRS])
    return history


def table1() -> dict[str, list[list[float]]]:
    zero = {pair: 0.0 for pair in PAIRS}
    return {"zero": q_learning(zero), "mc": q_learning(mc_initialisation())}


def main(argv: list[str] | None = None) -> None:
    parser = OneLineParser(prog="experiments.tabular", description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", action="store_true", help="print the table as JSON")
    args = parser.parse_args(argv)
    result = table1()
    if args.json:
        print(json.dumps(result))
        return
    header = " ".join(f"Q{p[0]},{p[1]:>2}" for p in PAIRS)
    print(f"epoch | zero init: {header} | MC init: {header}")
    for epoch, (z, m) in enumerate(zip(result["zero"], result["mc"])):
        fmt = lambda row: " ".join(f"{v:+7.1f}" for v in row)  # noqa: E731
        print(f"{epoch:5d} |            {fmt(z)} |          {fmt(m)}")


if __name__ == "__main__":
    from offrl_jax.system.cli import run_main

    run_main(main)
