"""The hyper-parameters every algorithm family shares (`Config`), and the checks that give a bad value one line.

A family's config is a frozen dataclass that extends `Config` with its own fields (`TD3BCConfig`, `SACNConfig`) and
may give a shared field its own default.  Each field's comment is its `--help` text (`offrl_jax/app/flags.py`).
Construction checks every field against its annotation (`check_types`, which also stores JSON's forms as the
annotation says, so a config read back from config.json equals the one written), then every value (`require`).
"""
from __future__ import annotations

import dataclasses
import math
import numbers
import types
import typing
from typing import Any, Literal

import numpy as np

from offrl_jax.algos.common import AutoStop, DataNeeds, Phase, joint_phases
from offrl_jax.losses import BALANCES
from offrl_jax.nets import INITS, Arch

# What a TD target does at a time-out (the time limit cut the episode, the task did not end):
#   "bootstrap"  r + gamma Q(s', a') as anywhere else (the state is not terminal)
#   "stop"       r, as at a terminal (the authors' code: dones = terminals + timeouts)
#   "drop"       the row is never sampled (CORL's loader drops it: its next observation is not recorded)
TIMEOUTS = ("bootstrap", "stop", "drop")
REPLAY_MODES = ("mix", "append", "online-only")  # `offrl_jax.online.sampling`
# the fields only an online phase reads: flags of the fine-tuning study alone (a study that never goes online would
# ignore them); a family adds its own online fields to this set
ONLINE_FIELDS = frozenset({"replay", "online_mix", "explore_noise", "online_critic_beta", "online_actor_beta_floor",
                           "calibration_online"})
PretrainMode = Literal["none", "actor", "critic", "actor+critic"]
# The values of the `authors` preset every family shares: the authors' code (AdamJelley/EfficientOfflineRL, a CORL
# fork) switch by switch; each family's file adds its own, and docs/fidelity.md has the table (what the paper says,
# what their code and CORL do, our default, the flag).
AUTHORS_CODE = {"layer_norm_affine": False, "layer_norm_eps": 1e-5, "init": "torch", "balance": "signed",
                "timeouts": "stop"}


@dataclasses.dataclass(frozen=True)
class Config:
    actor_lr: float = 3e-4  # Adam learning rate of the actor
    critic_lr: float = 3e-4  # Adam learning rate of the critics
    gamma: float = 0.99  # discount
    tau: float = 0.005  # Polyak rate of the target networks
    hidden: tuple[int, ...] = (256, 256)  # critic hidden widths (and the actor's unless actor_hidden is set)
    actor_hidden: tuple[int, ...] | None = None  # actor hidden widths; None (unset): the same as hidden
    actor_layer_norm: bool = True  # LayerNorm after every hidden layer of the actor (the paper: on)
    critic_layer_norm: bool = True  # LayerNorm after every hidden layer of the critics (the paper: on)
    layer_norm_affine: bool = True  # learned LN scale/bias; False = the authors' code (elementwise_affine=False)
    layer_norm_eps: float = 1e-6  # flax's default; torch's (the authors') 1e-5
    init: str = "flax"  # flax (lecun-normal, zero bias), torch (nn.Linear's default), orthogonal or orthogonal_all
    num_critics: int = 2  # critic ensemble size
    timeouts: str = "bootstrap"  # TD target at a time-out: bootstrap, stop (the authors'), drop the row (CORL's)
    # rewards x 1000 / (max - min episode return) of the dataset before any target or return is computed (CORL's
    # IQL on hopper); evaluation scores are the environment's own
    normalize_reward: bool = False
    # pre-training (first imitate, then improve): which networks, and for how many of the run's updates
    pretrain: PretrainMode = "actor+critic"
    pretrain_updates: int = 10_000
    # pretrain_auto: each pre-training phase ends when its supervised losses stop improving (common.AutoStop: the
    # mean over a window of updates improved by less than tol, relative, for every member), pretrain_updates is then
    # the cap; the updates left go to offline RL
    pretrain_auto: bool = False
    # this variant's offline updates (pre-training included) in place of the study's budget; None: the study's
    # (the fine-tuning study's online-rl arm: 0, no offline phase)
    offline_updates: int | None = None
    # with --pretrain-updates auto: updates per window over which the losses are averaged (must divide the
    # evaluation interval)
    pretrain_auto_window: int = 1_000
    # with --pretrain-updates auto: the relative improvement per window below which a phase ends
    pretrain_auto_tol: float = 0.01
    lam: float = 0.0  # TD weight in critic pre-training (0 = pure MC; the paper: 0 or 0.1)
    # how lam mixes: the authors' normalised losses (loss) or eq. 5's targets (target)
    lambda_mode: Literal["loss", "target"] = "loss"
    # online fine-tuning (`experiments.finetune`; `ONLINE_FIELDS`): how each online minibatch is drawn (REPLAY_MODES):
    # mix = a fixed share from the online buffer (Cal-QL, CORL's ReBRAC), append = online rows join the dataset
    # (CORL's IQL), online-only = the dataset is dropped (WSRL)
    replay: str = "mix"
    online_mix: float = 0.5  # the online share of each minibatch with replay "mix" (Cal-QL and CORL's ReBRAC: 0.5)
    # std of the Gaussian noise added online to a deterministic actor's action (TD3's 0.1); a stochastic actor samples
    explore_noise: float = 0.1

    def __post_init__(self):
        check_types(self)
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if isinstance(value, float) and not math.isfinite(value):
                raise ValueError(f"{type(self).__name__}.{field.name} = {value!r} must be a finite number")
        widths = lambda h: len(h) > 0 and all(w > 0 for w in h)  # noqa: E731
        require(self, [
            ("gamma", 0.0 < self.gamma < 1.0, "must be in (0, 1) (a time-out's return tail is r / (1 - gamma))"),
            ("tau", 0.0 < self.tau <= 1.0, "must be in (0, 1]"),
            ("lam", 0.0 <= self.lam <= 1.0, "must be in [0, 1]"),
            ("actor_lr", self.actor_lr > 0, "must be positive"),
            ("critic_lr", self.critic_lr > 0, "must be positive"),
            ("pretrain_updates", self.pretrain_updates >= 0, "must be >= 0"),
            ("offline_updates", self.offline_updates is None or self.offline_updates >= 0, "must be >= 0 or None"),
            ("pretrain_auto_window", self.pretrain_auto_window > 0, "must be positive"),
            ("pretrain_auto_tol", self.pretrain_auto_tol >= 0, "must be >= 0"),
            ("hidden", widths(self.hidden), "must be positive layer widths"),
            ("actor_hidden", self.actor_hidden is None or widths(self.actor_hidden), "must be positive layer widths"),
            ("num_critics", self.num_critics >= 1, "must be >= 1"),
            ("layer_norm_eps", self.layer_norm_eps > 0, "must be positive"),
            ("init", self.init in INITS, f"must be one of {', '.join(INITS)}"),
            ("timeouts", self.timeouts in TIMEOUTS, f"must be one of {', '.join(TIMEOUTS)}"),
            ("replay", self.replay in REPLAY_MODES, f"must be one of {', '.join(REPLAY_MODES)}"),
            ("online_mix", 0.0 <= self.online_mix <= 1.0, "must be in [0, 1]"),
            ("explore_noise", self.explore_noise >= 0, "must be >= 0"),
        ])

    def auto_stop(self, monitor: tuple[str, ...]) -> AutoStop | None:
        """The stopping rule of a pre-training phase that watches `monitor`, or None when it is fixed-length."""
        return AutoStop(monitor, self.pretrain_auto_window, self.pretrain_auto_tol) if self.pretrain_auto else None

    def budget(self, study_updates: int) -> int:
        """The offline updates this variant makes: `offline_updates`, or the study's."""
        return study_updates if self.offline_updates is None else self.offline_updates

    def phases(self, total_updates: int) -> list[Phase]:
        """The phases of a run of `total_updates` updates, planned once (no networks needed; `Phase.update` None):
        pre-training, when there is any, then offline RL.  A family that plans otherwise overrides this; its
        algorithm gives each planned phase its update (`Algorithm.updates`)."""
        return joint_phases(self, total_updates)

    def needs(self) -> DataNeeds:
        """What the updates read from the data: by default the device form's fields, every row drawn but, with
        timeouts "drop", the rows a time limit cut; a family that reads more adds it."""
        return DataNeeds(cut_rows=self.timeouts != "drop")

    def arch(self) -> Arch:
        """The layer-building choices (LayerNorm form, initialisation); a family with a constant hidden bias adds it
        (`arch_with_bias`)."""
        return Arch(layer_norm_affine=self.layer_norm_affine, layer_norm_eps=self.layer_norm_eps, init=self.init)


def arch_with_bias(cfg: Config) -> Arch:
    """`cfg.arch()` with the family's constant hidden-layer bias (`hidden_bias`, a field of SACN's and ReBRAC's)."""
    return dataclasses.replace(Config.arch(cfg), hidden_bias=cfg.hidden_bias)


def require(cfg: Any, checks: list[tuple[str, bool, str]]) -> None:
    """Raise one line for the first (field, ok, what it must be) that is not ok."""
    for name, ok, message in checks:
        if not ok:
            raise ValueError(f"{type(cfg).__name__}.{name} = {getattr(cfg, name)!r} {message}")


def check_cql_fields(cfg: Any) -> None:
    """The uniform-action CQL penalty's and the loss balancing's fields, which both families have."""
    require(cfg, [("cql_actions", cfg.cql_actions >= 1, "must be >= 1"),
                  ("cql_temperature", cfg.cql_temperature > 0, "must be positive"),
                  ("balance", cfg.balance in BALANCES, f"must be one of {', '.join(BALANCES)}")])


def _typed(annotation: Any, value: Any) -> tuple[bool, Any, str]:
    """(value fits `annotation`, the value as the field stores it, what the field must be).  JSON's forms are
    accepted and converted: a list for a tuple, an integer for a float; so are numpy's scalars."""
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if origin in (typing.Union, types.UnionType):  # X | None
        if value is None and type(None) in args:
            return True, None, ""
        inner = [a for a in args if a is not type(None)]
        if len(inner) != 1:
            return True, value, ""
        ok, value, need = _typed(inner[0], value)
        return ok, value, need + (" or None" if type(None) in args else "")
    if annotation is bool:
        return isinstance(value, (bool, np.bool_)), bool(value) if isinstance(value, np.bool_) else value, \
            "must be True or False"
    if annotation is int:
        ok = isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_))
        return ok, int(value) if ok else value, "must be an integer"
    if annotation is float:
        ok = isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))
        try:
            return ok, float(value) if ok else value, "must be a number"
        except OverflowError:  # an integer too large for a float
            return False, value, "must be a finite number"
    if annotation is str:
        return isinstance(value, str), value, "must be a string"
    if origin is typing.Literal:
        need = f"must be {args[0]!r} or {args[1]!r}" if len(args) == 2 else f"must be one of {', '.join(args)}"
        return isinstance(value, str) and value in args, value, need
    if origin is tuple:
        element = args[0]
        need = (f"must be a tuple of {'integers' if element is int else 'numbers'}" if args[1:] == (...,) else
                f"must be a tuple of {len(args)} {'integers' if element is int else 'finite numbers'}")
        if not isinstance(value, (tuple, list)) or (args[1:] != (...,) and len(value) != len(args)):
            return False, value, need
        items = [_typed(element, x) for x in value]
        ok = all(fits for fits, _, _ in items) and all(
            math.isfinite(x) for _, x, _ in items if element is float and isinstance(x, float))
        return ok, tuple(x for _, x, _ in items) if ok else value, need
    return True, value, ""  # an annotation this check does not know: the config's own checks decide


def check_types(cfg) -> None:
    """Check every field of a config dataclass against its annotation, before the value checks, and store JSON's
    forms as the annotation says (see `_typed`), so a config read back from config.json equals the one written."""
    hints = typing.get_type_hints(type(cfg))
    for field in dataclasses.fields(cfg):
        value = getattr(cfg, field.name)
        ok, typed, need = _typed(hints[field.name], value)
        if not ok:
            raise ValueError(f"{type(cfg).__name__}.{field.name} = {value!r} {need}")
        if typed is not value:
            object.__setattr__(cfg, field.name, typed)  # frozen dataclass
