"""Stands in for D4RL (its import registers the datasets; gym.py serves ours).

qlearning_dataset: D4RL's, for a dataset that already holds next_observations: every row but the time-out ones
(D4RL skips the last step of a timed-out episode, whose next observation it does not have)."""


def qlearning_dataset(env):
    ds = env.get_dataset()
    keep = ds["timeouts"] == 0
    return {k: ds[k][keep] for k in ("observations", "actions", "next_observations", "rewards", "terminals")}
