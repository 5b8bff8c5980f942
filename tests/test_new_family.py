"""Adding a family is one file and one registry line: a throwaway family, written here into a module of its own
(its config, algorithm, ALGOS, ENV_DEFAULTS and PRESETS) and registered for the test only
(`offrl_jax.algos.register`), resolves, plans, trains offline, prints its `--dry-run` and fine-tunes online with
every arm through the normal entry points, no other file touched."""
from __future__ import annotations

import copy
import dataclasses
import importlib.util
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from offrl_jax import algos
from offrl_jax.run.results import read_curves

ROOT = Path(__file__).resolve().parents[1]
TOY = textwrap.dedent('''
    """A throwaway family: a deterministic actor trained by BC, its BC term weighted by `toy_weight` in offline RL."""
    import dataclasses
    from typing import ClassVar

    import jax
    import jax.numpy as jnp
    import optax
    from flax import struct

    from offrl_jax import losses as L
    from offrl_jax.algos.common import Algo, Algorithm, Family, Model, gradient_step, new_model, single
    from offrl_jax.algos.config import Config, require
    from offrl_jax.nets import DeterministicActor


    @dataclasses.dataclass(frozen=True)
    class ToyConfig(Config):
        toy_weight: float = 1.0  # weight of the toy's behaviour-cloning term in offline RL
        SWEEPABLE: ClassVar[tuple[str, ...]] = ("toy_weight",)

        def __post_init__(self):
            super().__post_init__()
            require(self, [("toy_weight", self.toy_weight >= 0, "must be >= 0")])


    @struct.dataclass
    class ToyState:
        actor: Model


    class Toy(Algorithm):
        def __init__(self, config, obs_dim, act_dim, num_transitions):
            self.cfg, self.obs_dim = config, obs_dim
            self.actor = DeterministicActor(act_dim, config.actor_hidden or config.hidden, config.actor_layer_norm,
                                            config.arch())
            self.tx = optax.adam(config.actor_lr)

        def init(self, key):
            return ToyState(actor=new_model(self.actor.init(key, jnp.zeros((1, self.obs_dim))), self.tx, False))

        def act(self, state, obs):
            return self.actor.apply(state.actor.params, obs)

        def step(self, rl):
            def update(state, batch, key):
                def loss_fn(params):
                    actions = self.actor.apply(params, batch["observations"])
                    bc = L.bc_loss(actions, batch["actions"])
                    weight = self.cfg.toy_weight if rl else 1.0
                    return weight * bc + 1e-3 * jnp.mean(actions ** 2), {"bc_loss": bc}

                actor, metrics = gradient_step(state.actor, self.tx, loss_fn)
                return state.replace(actor=actor), metrics

            return single(update)

        def updates(self):
            return {"pretrain": self.step(False), "offline_rl": self.step(True)}


    FAMILY = Family(ToyConfig, Toy)
    ALGOS = {"toy": Algo("toy", without_behaviour={"toy_weight": 0.0}), "toy_strong": Algo("toy", {"toy_weight": 3.0})}
    ENV_DEFAULTS = {("toy", "hopper"): {"toy_weight": 0.5}}
    PRESETS = {"toyset": {"toy": {"toy_weight": 2.0}}}
''')
# registers the toy before anything else reads the registry (as a name in FAMILY_FILES would), then runs a module
# as `python -m` does
RUN = textwrap.dedent('''
    import runpy, sys
    sys.path.insert(0, sys.argv[1])
    import offrl_jax, toy_family
    from offrl_jax import algos
    assert offrl_jax.__file__.startswith(sys.argv[2]), offrl_jax.__file__  # this tree's package
    algos.register("toy", toy_family)
    sys.argv = sys.argv[3:]
    runpy.run_module(sys.argv[0], run_name="__main__", alter_sys=True)
''')
TINY = ["--env", "hopper", "--max-transitions", "5000", "--updates", "200", "--pretrain-updates", "100",
        "--eval-every", "100", "--eval-episodes", "1", "--seeds", "1", "--hidden", "32", "32", "--parallel", "1"]


@pytest.fixture
def toy_dir(tmp_path):
    (tmp_path / "toy").mkdir()
    (tmp_path / "toy" / "toy_family.py").write_text(TOY)
    return tmp_path / "toy"


@pytest.fixture
def toy(toy_dir):
    """The toy family's module, registered in this process until the test ends (the registry restored after)."""
    spec = importlib.util.spec_from_file_location("toy_family", toy_dir / "toy_family.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    tables = (algos.FAMILIES, algos.ALGOS, algos.ENV_DEFAULTS, algos.PRESETS)
    saved = [copy.deepcopy(table) for table in tables]
    algos.register("toy", module)
    yield module
    for table, before in zip(tables, saved):  # in place: other modules hold these dicts
        table.clear()
        table.update(before)


def run(module: str, *args: str, toy_dir: Path) -> subprocess.CompletedProcess:
    env = os.environ | {"PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-c", RUN, str(toy_dir), str(ROOT / "offrl_jax"), module, *args],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=900)


def test_the_registry_takes_the_family_and_resolves_it(toy):
    defaults = {f.name: f.default for f in dataclasses.fields(toy.ToyConfig)}
    assert algos.resolve("toy", "").config == toy.ToyConfig(**defaults)  # the dataclass defaults, no env
    assert set(algos.resolve("toy", "").sources.values()) == {"default"}
    on_hopper = algos.resolve("toy", "hopper")
    assert on_hopper.config.toy_weight == 0.5 and on_hopper.sources["toy_weight"] == "per-env"
    assert algos.resolve("toy_strong", "").config.toy_weight == 3.0
    assert algos.resolve("toy", "hopper", preset="toyset").sources["toy_weight"] == "preset"
    assert algos.resolve("td3bc", "hopper", preset="toyset").config == algos.resolve("td3bc", "hopper").config
    with pytest.raises(ValueError, match="ToyConfig.toy_weight = -1.0 must be >= 0"):
        algos.make_config("toy", "hopper", toy_weight=-1.0)
    with pytest.raises(ValueError, match="'toy' is registered already"):
        algos.register("toy", toy)


def test_the_registry_is_restored_after_the_family_test():
    assert "toy" not in algos.FAMILIES and "toy" not in algos.ALGOS and "toyset" not in algos.PRESETS
    assert not any(key[0] == "toy" for key in algos.ENV_DEFAULTS)


def test_the_family_runs_offline_with_its_own_flag_and_prints_its_dry_run(toy_dir, tmp_path):
    out = tmp_path / "offline"
    done = run("experiments.mujoco_medium", "--algo", "toy", *TINY, "--toy-weight", "0.25", "--out", str(out),
               toy_dir=toy_dir)
    assert done.returncode == 0, done.stderr[-3000:]
    rows = read_curves(out / "curves.csv")
    assert {(r["variant"], r["phase"], r["update"]) for r in rows} >= {
        ("pretrained", "pretrain", 100), ("pretrained", "offline_rl", 200), ("scratch", "offline_rl", 200)}
    record = json.loads((out / "config.json").read_text())
    assert record["resolved"]["pretrained"]["toy_weight"] == 0.25
    assert record["sources"]["pretrained"]["toy_weight"] == "flag"
    assert {s["variant"] for s in json.loads((out / "summary.json").read_text())} == {"pretrained", "scratch"}

    dry = run("experiments.mujoco_medium", "--algo", "toy", *TINY, "--preset", "toyset", "--dry-run",
              toy_dir=toy_dir)
    assert dry.returncode == 0, dry.stderr[-3000:]
    assert "phases: pretrain 100, offline_rl 100" in dry.stdout, dry.stdout[-3000:]
    assert dry.stdout.count("toy_weight = 2.0  (preset)") == 2, dry.stdout[-3000:]  # both variants, its source


def test_the_family_fine_tunes_with_every_arm(toy_dir, tmp_path):
    out = tmp_path / "finetune"
    done = run("experiments.finetune", "--algo", "toy", *TINY, "--online-steps", "200", "--online-block", "100",
               "--online-eval-every", "200", "--out", str(out), toy_dir=toy_dir)
    assert done.returncode == 0, done.stderr[-3000:]
    rows = read_curves(out / "curves.csv")
    arms = {"pretrained", "scratch", "pretrain-only", "online-rl"}
    assert {r["variant"] for r in rows} == arms
    assert {r["variant"] for r in rows if r.get("env_steps") == 200} == arms  # each arm's online evaluation
    record = json.loads((out / "config.json").read_text())
    assert record["resolved"]["online-rl"]["toy_weight"] == 0.0  # its form without behaviour terms
    assert record["resolved"]["online-rl"]["offline_updates"] == 0
