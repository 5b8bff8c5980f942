"""The online phase's loop settings (`OnlineConfig`): plain data, part of a study (`Study.online`) and of its
config.json; the sampling and exploration values are the family's config fields (`offrl_jax.algos.config`)."""
from __future__ import annotations

import dataclasses


@dataclasses.dataclass(frozen=True)
class OnlineConfig:
    """The online phase's loop: how many env steps, how they are cut into blocks, updates per step, the warm-up, the
    buffer and the evaluations.  The sampling and exploration values are the family's config fields (`replay`,
    `online_mix`, `explore_noise`, ...), resolved as every hyper-parameter is."""
    steps: int  # env steps of every member
    block: int = 1_000  # env steps collected between two update scans (K)
    utd: int = 1  # updates per env step (the update-to-data ratio)
    warmup: int = 0  # env steps collected with the hand-over policy before the first online update (WSRL: 5000)
    capacity: int = 0  # online buffer rows per member; 0: every online step (nothing is overwritten)
    eval_every: int = 5_000  # env steps between evaluations

    def __post_init__(self):
        for name in ("steps", "block", "utd", "eval_every"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not 0 < value < 2**31:
                raise ValueError(f"online {name} = {value!r} must be a positive integer below 2**31")
        for name in ("warmup", "capacity"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < 2**31:
                raise ValueError(f"online {name} = {value!r} must be an integer >= 0")
        for name in ("steps", "eval_every", "warmup"):
            if getattr(self, name) % self.block:
                raise ValueError(f"online {name} ({getattr(self, name)}) must be a multiple of the block "
                                 f"({self.block} env steps)")
        if self.warmup >= self.steps:
            raise ValueError(f"the online warm-up ({self.warmup} env steps) leaves no step of the {self.steps} to "
                             "update in")
        if self.updates() >= 2**31:
            raise ValueError(f"online utd {self.utd} x {self.steps - self.warmup:,} env steps after the warm-up make "
                             f"{self.updates():,} updates, past what the update counter holds (an int32: "
                             f"{2**31 - 1:,})")

    def updates(self) -> int:
        """Online updates of every member: utd for each env step after the warm-up."""
        return (self.steps - self.warmup) * self.utd

    def rows(self, horizon: int) -> int:
        """The buffer's rows per member: `capacity`, or every online step (at least what the ring needs to write the
        returns of an episode ending in a block); refused when a given capacity is too small for that."""
        rows = self.capacity or max(self.steps, horizon - 1 + self.block)
        if rows < horizon - 1 + self.block:
            raise ValueError(f"an online buffer of {rows} rows cannot hold an episode of up to {horizon} steps ending "
                             f"in a block of {self.block}: give a capacity of at least {horizon - 1 + self.block}")
        return rows

    def check(self, label: str, last) -> None:
        """Raise ValueError unless variant `label`, whose last (planned) phase is `last`, can go on online:
        it ends in offline RL (there is a critic to fine-tune), and each block's updates fill whole update calls."""
        if last.pretraining:
            raise ValueError(f"variant {label!r} has no offline-RL phase to fine-tune online (behaviour cloning "
                             "alone has no critic)")
        if (self.block * self.utd) % last.updates_per_call:
            raise ValueError(f"variant {label!r} makes {last.updates_per_call} updates per call (the policy delay), "
                             f"so online block x utd ({self.block} x {self.utd}) must be a multiple of "
                             f"{last.updates_per_call}")
