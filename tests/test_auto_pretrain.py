"""Pre-training that ends itself (`--pretrain-updates auto`): the stopping rule by hand, the hand-over moving the
unused updates to offline RL, every member handing over together, and a resume that ends where the whole run does."""
from types import SimpleNamespace

import jax.numpy as jnp
import numpy as np
import pytest

from offrl_jax.algos import make_algorithm, make_config
from offrl_jax.algos.common import AutoStop, DataNeeds, Phase
from offrl_jax.driver import Driver, check_call_grid


def test_rule_by_hand():
    rule = AutoStop(("a", "b"), window=10, tol=0.01)
    assert not rule.converged(None, {"a": np.array([1.0]), "b": np.array([1.0])})  # one window is not a trend
    # a: 100 -> 99.5 is 0.5 % better (< 1 %), b: 10 -> 9.8 is 2 % better: not yet
    prev, cur = {"a": np.array([100.0]), "b": np.array([10.0])}, {"a": np.array([99.5]), "b": np.array([9.8])}
    assert not rule.converged(prev, cur)
    cur["b"] = np.array([9.95])  # 0.5 %: both flat
    assert rule.converged(prev, cur)
    # every member must be flat; a loss that got worse counts as flat; negative losses use |previous|
    assert not rule.converged({"a": np.array([100.0, 100.0]), "b": np.array([10.0, 10.0])},
                              {"a": np.array([99.9, 90.0]), "b": np.array([10.0, 10.0])})
    assert rule.converged({"a": np.array([-5.0]), "b": np.array([1.0])}, {"a": np.array([-5.01]), "b": np.array([2.0])})


def counter_algo(cap=1000, rest=500, flat_at=(500, 500)):
    """A fake algorithm: state = update count; 'loss' falls by 1 per update until member m's flat_at[m], then stays."""
    flat = jnp.asarray(flat_at, jnp.float32)

    def pretrain(state, batch, key):
        count, member = state
        return (count + 1, member), {"loss": 1000.0 - jnp.minimum(count, flat[member])}

    def offline(state, batch, key):
        return (state[0] + 1, state[1]), {"loss": jnp.zeros(())}

    phases = [Phase("pretrain", pretrain, cap, auto_stop=AutoStop(("loss",), window=100, tol=0.01)),
              Phase("offline_rl", offline, rest)]
    algo = SimpleNamespace(cfg=SimpleNamespace(needs=DataNeeds),  # reads the device form alone
                           init=lambda key: (jnp.zeros(()), jnp.zeros((), jnp.int32)))
    return algo, phases


def data():
    return {k: jnp.zeros((10, 1)) for k in ("observations", "next_observations", "actions")} | {
        k: jnp.zeros(10) for k in ("rewards", "terminals", "timeouts", "returns")}


def members(driver):
    states = driver.init()
    return (states[0], jnp.arange(len(driver.members), dtype=jnp.int32))


def test_phase_ends_when_flat_for_every_member_and_the_budget_moves_to_offline_rl():
    algo, phases = counter_algo(flat_at=(300, 500))
    driver = Driver(algo, data(), seeds=(0, 1))
    chunks = list(driver.run(phases, 200, members(driver)))
    # member 1 is flat from 500: window [500, 600) equals 500 vs [400, 500)'s 549.5 (9 % better); [600, 700) is
    # flat against [500, 600): the phase ends at 700 for both members, not at member 0's earlier plateau
    ends = [c.update for c in chunks if c.ended]
    assert ends == [700]
    assert [c.update for c in chunks if c.phase == "pretrain"] == [200, 400, 600, 700]
    assert chunks[-1].update == 1500 and chunks[-1].phase == "offline_rl"  # same total budget
    np.testing.assert_array_equal(chunks[-1].states[0], [1500, 1500])
    assert [c.update for c in chunks if c.phase == "offline_rl"] == [800, 1000, 1200, 1400, 1500]


def test_resume_mid_phase_and_after_the_hand_over_end_where_the_whole_run_does():
    algo, phases = counter_algo(flat_at=(500, 500))
    driver = Driver(algo, data(), seeds=(0, 1))
    whole, saved = [], {}
    for c in driver.run(phases, 200, members(driver)):
        whole.append(c)
        saved[c.update] = tuple(np.array(x) for x in c.states)  # the next chunk donates these buffers
    for resume_at in (400, 600, 800):  # inside pre-training (after whole windows), and after the hand-over
        chunk = next(c for c in whole if c.update == resume_at)
        ended = {c.phase: c.update for c in whole if c.ended and c.update <= resume_at}
        rest = list(driver.run(phases, 200, saved[resume_at], resume_at, 0.0, ended, chunk.metrics))
        assert [(c.phase, c.update, c.ended) for c in rest] == [(c.phase, c.update, c.ended) for c in whole
                                                                if c.update > resume_at]


def test_window_must_divide_the_evaluation_interval():
    _, phases = counter_algo()
    with pytest.raises(ValueError, match="multiple of that window"):
        check_call_grid(phases, 250)


def test_td3bc_and_edac_phases_carry_the_rule(tiny_dataset):
    td3 = make_algorithm(make_config("td3bc", "hopper", pretrain_auto=True, pretrain_updates=4000), 3, 2, 10)
    (pre, rl) = td3.phases(10_000)
    assert pre.auto_stop.monitor == ("bc_loss", "mc_error") and pre.steps == 4000 and rl.auto_stop is None
    edac = make_algorithm(make_config("edac", "hopper", pretrain_auto=True, num_critics=2), 3, 2, 10)
    actor, critic, _ = edac.phases(30_000)
    assert actor.auto_stop.monitor == ("soft_bc_loss",) and critic.auto_stop.monitor == ("mc_error",)
    assert make_algorithm(make_config("td3bc", "hopper"), 3, 2, 10).phases(20_000)[0].auto_stop is None
    with pytest.raises(ValueError, match="multiple of policy_delay"):
        make_config("td3bc", "hopper", pretrain_auto=True, pretrain_auto_window=999)


def test_cli_auto_and_cap():
    from experiments import mujoco_medium

    p = mujoco_medium.make_parser()
    # the self-ending phase checks its losses every 1k updates: the evaluation interval must be a multiple of it
    o = mujoco_medium.build(p.parse_args(["--pretrain-updates", "auto:30000", "--eval-every", "5000"])) \
        .variants[0].given()
    assert o["pretrain_auto"] is True and o["pretrain_updates"] == 30000
    o = mujoco_medium.build(p.parse_args(["--pretrain-updates", "auto", "--eval-every", "5000"])) \
        .variants[0].given()
    assert o["pretrain_auto"] is True and "pretrain_updates" not in o
    with pytest.raises(SystemExit):
        p.parse_args(["--pretrain-updates", "auto:x"])


def test_run_study_records_the_hand_over(tmp_path, tiny_dataset):
    import json

    from offrl_jax.run.results import read_curves
    from offrl_jax.run.runner import run_study
    from offrl_jax.run.study import Study, Variant

    # tol 1: any window that is not worse by more than 100 % is "flat", so pre-training ends at its 2nd window
    variant = Variant.of("auto", "td3bc", pretrain_auto=True, pretrain_auto_window=100, pretrain_auto_tol=1.0,
                         pretrain_updates=400, hidden=(16, 16))
    study = Study(name="t", dataset="synthetic", env="hopper", variants=(variant,), seeds=(0,), updates=600,
                  eval_every=100, eval_episodes=1, batch_size=32)
    run_study(study, tmp_path, tiny_dataset, progress=False)
    rows = read_curves(tmp_path / "curves.csv")
    assert [(r["phase"], r["update"]) for r in rows if r.get("phase_ended")] == [("pretrain", 200)]
    assert [r["update"] for r in rows if r["phase"] == "offline_rl"] == [300, 400, 500, 600]
    (summary,) = json.loads((tmp_path / "summary.json").read_text())
    assert summary["pretrain_updates"] == 200
    # a resume with nothing left to train (say after a stop in a later variant) keeps where pre-training ended
    run_study(study, tmp_path, tiny_dataset, resume=True, progress=False)
    (summary,) = json.loads((tmp_path / "summary.json").read_text())
    assert summary["pretrain_updates"] == 200
