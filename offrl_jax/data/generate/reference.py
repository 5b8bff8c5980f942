"""What the generated MuJoCo datasets are measured against: D4RL v2's medium datasets and CORL's published scores
on them (https://github.com/tinkoff-ai/CORL, README "Last Scores": mean ± std over 4 seeds after 1M updates).

One place for these numbers: the medium checkpoint's target (`collect.MEDIUM_TARGET_SCORE`), the provenance written
beside a generated dataset and the fidelity table of `python -m experiments.fidelity` all read them here.
"""
from __future__ import annotations

# Per dataset: transitions, episodes and the mean normalised behaviour score of D4RL's file; "bc" and "td3bc": CORL's
# last scores (mean, std) of behaviour cloning and of TD3+BC (alpha 2.5, no LayerNorm) on it.
D4RL_V2: dict[str, dict] = {
    "hopper-medium": {"transitions": 1_000_000, "episodes": 2186, "normalized_score": 44.0,
                      "bc": (53.51, 1.76), "td3bc": (60.37, 3.49)},
    "halfcheetah-medium": {"transitions": 1_000_000, "episodes": 1000, "normalized_score": 40.0,
                           "bc": (42.40, 0.19), "td3bc": (48.10, 0.18)},
    "walker2d-medium": {"transitions": 1_000_000, "episodes": 1191, "normalized_score": 62.0,
                        "bc": (63.23, 16.24), "td3bc": (82.71, 4.78)},
}
CORL_UPDATES = 1_000_000  # the budget behind CORL's "bc" and "td3bc" scores

# How close a generated dataset should come (normalised points): behaviour and BC within TOLERANCE of D4RL's / CORL's
# value, or within CORL's own spread (one std) where that is wider (walker2d's BC).
TOLERANCE = 5.0


def target_band(reference: tuple[float, float] | float) -> tuple[float, float]:
    """(low, high) a measured score should fall in: the reference ± max(TOLERANCE, its std)."""
    mean, std = reference if isinstance(reference, tuple) else (reference, 0.0)
    half = max(TOLERANCE, std)
    return mean - half, mean + half
