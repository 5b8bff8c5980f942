"""The online phase as a phase of a run: its settings, each family's online values and exploration, the loop on the
driver's member axis, and `experiments.finetune` end to end (run, resume inside the online phase, refusals)."""
import json
import os
import shutil
import signal
import subprocess
import sys
import time

import h5py
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from flax import serialization

from offrl_jax.algos import make_algorithm, make_config
from offrl_jax.data.device import device_data
from offrl_jax.driver import Driver
from offrl_jax.online.config import OnlineConfig
from offrl_jax.online.envs import exploration_policy
from offrl_jax.online.loop import online_phase, run_online
from offrl_jax.run.results import read_curves
from tests.entry import ROOT, run_module


@pytest.mark.parametrize("kwargs, fragment", [
    (dict(steps=1500, block=1000), "multiple of the block"),
    (dict(steps=2000, block=1000, eval_every=500), "multiple of the block"),
    (dict(steps=2000, block=1000, warmup=2000), "leaves no step"),
    (dict(steps=2000, block=1000, utd=0), "positive integer"),
    (dict(steps=2000, block=1000, capacity=-1), ">= 0"),
    (dict(steps=True, block=1000), "positive integer"),
])
def test_online_config_refuses_inconsistent_settings(kwargs, fragment):
    with pytest.raises(ValueError, match=fragment):
        OnlineConfig(**kwargs)


def test_online_config_counts_updates_and_sizes_the_buffer():
    online = OnlineConfig(steps=5000, block=1000, utd=2, warmup=1000)
    assert online.updates() == 8000  # 2 updates for each of the 4000 steps after the warm-up
    assert online.rows(horizon=1000) == 5000  # every step kept
    assert OnlineConfig(steps=1000, block=500).rows(horizon=1000) == 1499  # an episode ending in a block must fit
    with pytest.raises(ValueError, match="at least 1499"):
        OnlineConfig(steps=1000, block=500, capacity=1000).rows(horizon=1000)


def test_rebrac_online_values_follow_corls_schedule():
    config = make_config("rebrac", "hopper", hidden=(8, 8), actor_beta=0.4)
    algo = make_algorithm(config, 3, 2, 10)
    for progress, factor in ((0.0, 1.0), (0.25, 0.75), (0.5, 0.5), (0.9, 0.5)):  # linear to the floor of 0.5
        values = algo.online_values(jnp.float32(progress))
        assert float(values["critic_beta"]) == 0.0
        np.testing.assert_allclose(float(values["actor_beta"]), 0.4 * factor, rtol=1e-6)


def test_the_online_phase_at_an_update_carries_the_schedule(tiny_dataset):
    config = make_config("rebrac", "hopper", hidden=(8, 8), pretrain="none", actor_beta=0.4)
    algo = make_algorithm(config, tiny_dataset.obs_dim, tiny_dataset.act_dim, len(tiny_dataset))
    online = OnlineConfig(steps=1000, block=500)
    phase, phase_at = online_phase(algo, 200, online)
    assert (phase.name, phase.steps, phase.updates_per_call) == ("online", 1000, 2)
    seen = {}
    original = type(algo).phases

    def spy(self, total):
        seen["actor_beta"], seen["critic_beta"] = float(self.cfg.actor_beta), float(self.cfg.critic_beta)
        return original(self, total)

    type(algo).phases = spy
    try:
        phase_at(None, jnp.int32(200 + 250))  # a quarter of the online updates done
    finally:
        type(algo).phases = original
    np.testing.assert_allclose(seen["actor_beta"], 0.3, rtol=1e-6)
    assert seen["critic_beta"] == 0.0


def test_bc_alone_cannot_go_online(tiny_dataset):
    algo = make_algorithm(make_config("bc", "hopper", hidden=(8, 8)), tiny_dataset.obs_dim, tiny_dataset.act_dim, 10)
    with pytest.raises(ValueError, match="no offline-RL phase"):
        online_phase(algo, 100, OnlineConfig(steps=1000, block=500))


def test_a_stochastic_actor_explores_with_its_sample_a_deterministic_one_with_noise(tiny_dataset):
    obs_dim, act_dim = tiny_dataset.obs_dim, tiny_dataset.act_dim
    mean, std = np.zeros(obs_dim, np.float32), np.ones(obs_dim, np.float32)
    obs, keys = jnp.ones((2, obs_dim)) * 0.3, jax.vmap(jax.random.PRNGKey)(jnp.arange(2))
    sacn = make_algorithm(make_config("edac", "hopper", hidden=(8, 8), num_critics=2), obs_dim, act_dim, 10)
    states = jax.vmap(sacn.init)(keys)
    sampled = exploration_policy(sacn.act, mean, std, 0.0, sacn.explore)(states, keys, obs, 7)
    expected = jax.vmap(lambda s, k, o: sacn.sample_policy(s.actor.params, o, jax.random.fold_in(k, 7))[0])(
        states, keys, obs)
    np.testing.assert_allclose(np.asarray(sampled), np.asarray(expected), rtol=1e-6)
    iql = make_algorithm(make_config("iql", "hopper", hidden=(8, 8), deterministic=True), obs_dim, act_dim, 10)
    states = jax.vmap(iql.init)(keys)
    noisy = exploration_policy(iql.act, mean, std, 0.5, iql.explore)(states, keys, obs, 7)
    plain = jax.vmap(iql.act)(states, obs)
    eps = jax.vmap(lambda k: jax.random.normal(jax.random.fold_in(k, 7), (act_dim,)))(keys)
    np.testing.assert_allclose(np.asarray(noisy), np.clip(np.asarray(plain + 0.5 * eps), -1, 1), rtol=1e-5)


def test_the_warm_up_collects_without_updating_then_updates_run(tiny_dataset):
    config = make_config("td3bc", "hopper", hidden=(16, 16), pretrain="none", target="max_mc")
    algo = make_algorithm(config, tiny_dataset.obs_dim, tiny_dataset.act_dim, len(tiny_dataset))
    form = device_data(tiny_dataset, config.gamma)
    driver = Driver(algo, form.arrays, (0, 1), batch_size=16)
    handover = list(driver.run(algo.phases(100), 100))[-1]
    handover.states = jax.device_get(handover.states)  # the next update call takes over the device buffers
    online = OnlineConfig(steps=600, block=200, warmup=200, eval_every=200)
    chunks = []
    for chunk in run_online(driver, algo, online, "hopper", form, handover.states, 100, handover.seconds):
        chunk.states = jax.device_get(chunk.states)
        chunks.append(chunk)
    assert [c.env_steps for c in chunks] == [200, 400, 600]
    assert [c.update for c in chunks] == [100, 300, 500]  # no update in the warm-up, then 200 per block (utd 1)
    for a, b in zip(jax.tree.leaves(chunks[0].states), jax.tree.leaves(handover.states)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert any(not np.allclose(a, b) for a, b in zip(jax.tree.leaves(chunks[-1].states),
                                                     jax.tree.leaves(handover.states)))
    assert set(chunks[-1].metrics) >= {"critic_loss", "actor_loss", "train_score", "train_episodes", "finite"}
    assert all(c.metrics["train_episodes"].sum() > 0 for c in chunks)  # an untrained hopper falls: episodes end


TINY = ["--env", "hopper", "--updates", "400", "--eval-every", "200", "--seeds", "2", "--max-transitions", "20000",
        "--online-steps", "600", "--online-block", "300", "--online-eval-every", "300", "--hidden", "16", "16",
        "--eval-episodes", "1", "--parallel", "1", "--no-progress", "--arms", "pretrained", "scratch",
        "--pretrain-updates", "200"]


def rewind_to_first_online_checkpoint(path, update: int) -> None:
    """Make a run's last checkpoint what a stop after its first online evaluation (env step 300) had left, without
    the online state of that point (the phase then starts again from the hand-over)."""
    payload = serialization.msgpack_restore(path.read_bytes())
    payload["history"] = json.dumps([r for r in json.loads(payload["history"]) if r.get("env_steps", 0) <= 300])
    payload["update"] = update
    path.write_bytes(serialization.msgpack_serialize(payload))


def test_finetune_runs_end_to_end_and_a_resume_inside_the_online_phase_recomputes_it(tmp_path):
    out = tmp_path / "run"
    done = run_module("experiments.finetune", *TINY, "--out", out)
    assert done.returncode == 0, done.stderr
    rows = read_curves(out / "curves.csv")
    online_rows = [r for r in rows if r["phase"] == "online"]
    assert {(r["variant"], r["env_steps"]) for r in online_rows} == {(v, s) for v in ("pretrained", "scratch")
                                                                      for s in (300.0, 600.0)}
    assert max(r["update"] for r in online_rows) == 400 + 600
    saved = json.loads((out / "config.json").read_text())
    assert saved["online"] == {"steps": 600, "block": 300, "utd": 1, "warmup": 0, "capacity": 0, "eval_every": 300}
    assert saved["sources"]["pretrained"]["replay"] == "default"
    summary = json.loads((out / "summary.json").read_text())
    assert [len(s["online"]["final"]["per_seed"]) for s in summary] == [2, 2]
    assert "Online phase (600 env steps per seed" in done.stdout and (out / "online.png").stat().st_size > 0
    # as if killed after the first online evaluation: the last checkpoint holds the rows up to env step 300
    rewind_to_first_online_checkpoint(out / "checkpoints" / "pretrained.msgpack", update=700)
    resumed = run_module("experiments.finetune", "--resume", out, "--no-progress", "--parallel", "1")
    assert resumed.returncode == 0, resumed.stderr
    assert "starts again from the hand-over" in resumed.stderr
    again = read_curves(out / "curves.csv")
    key = lambda r: (r["variant"], r["seed"], r["update"], r.get("env_steps"))  # noqa: E731
    assert sorted((key(r), r["score"]) for r in again) == sorted((key(r), r["score"]) for r in rows)


@pytest.mark.slow  # one of the suite's longest (1-5 min on 2 busy cores); -m slow runs it
def test_a_run_killed_inside_the_online_phase_goes_on_from_its_last_checkpoint_exactly(tmp_path):
    """SIGKILL after the first online evaluation: --resume restores every env's MuJoCo state, the episodes under way
    and the online buffers, and continues from that env step; the curves equal the uninterrupted run's."""
    args = [a for a in TINY if a != "scratch"] + ["--online-steps", "900"]  # one arm, 3 online evaluations
    full, killed = tmp_path / "full", tmp_path / "killed"
    assert run_module("experiments.finetune", *args, "--out", full).returncode == 0
    assert not (full / "checkpoints" / "pretrained.online.msgpack").exists()  # removed once the phase is done
    proc = subprocess.Popen([sys.executable, "-m", "experiments.finetune", *map(str, args), "--out", str(killed)],
                            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    saved, deadline = killed / "checkpoints" / "pretrained.online.msgpack", time.time() + 300
    curves_csv = killed / "curves.csv"  # written after the checkpoint: an online row there means both are saved
    while time.time() < deadline and proc.poll() is None and not (
            curves_csv.exists() and ",online," in curves_csv.read_text()):
        time.sleep(0.02)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert saved.exists() and not (killed / "summary.json").exists()
    # killed between the next online state's write and its checkpoint's (a poll that slept long), the two disagree
    # and the phase starts again from the hand-over instead; either way the curves are the same
    checkpoint = serialization.msgpack_restore((killed / "checkpoints" / "pretrained.msgpack").read_bytes())
    agree = json.loads(serialization.msgpack_restore(saved.read_bytes())["key"])["update"] == checkpoint["update"]
    resumed = run_module("experiments.finetune", "--resume", killed, "--no-progress", "--parallel", "1")
    assert resumed.returncode == 0, resumed.stderr
    message = "the online phase goes on from env step" if agree else "starts again from the hand-over"
    assert message in resumed.stderr, resumed.stderr
    key = lambda r: (r["variant"], r["seed"], r["update"], r.get("env_steps"))  # noqa: E731
    curves = lambda out: sorted((key(r), r["score"], r.get("train_score")) for r in read_curves(out / "curves.csv"))  # noqa: E731
    assert curves(killed) == curves(full)
    # the online env steps recorded as datasets: the same rows as the uninterrupted run's, read as hopper data
    from offrl_jax.data.readers import read_d4rl_hdf5

    for seed in (0, 1):
        name = f"online/hopper-pretrained-seed{seed}.hdf5"
        mine, theirs = read_d4rl_hdf5(killed / name), read_d4rl_hdf5(full / name)
        assert mine.env == "hopper" and len(mine.rewards) == 900
        for field in ("observations", "actions", "rewards", "terminals", "timeouts", "next_observations"):
            np.testing.assert_array_equal(getattr(mine, field), getattr(theirs, field))
    # the run replays from its config.json, and acts from the hand-over and from its last checkpoint
    replay = tmp_path / "replay"
    assert run_module("experiments.finetune", "--config", full, "--out", replay, "--no-progress").returncode == 0
    assert curves(replay) == curves(full)
    from offrl_jax.policy import load_policy

    handover, last = load_policy(full, "pretrained", checkpoint="handover"), load_policy(full, "pretrained")
    assert (handover.update, last.update) == (400, 400 + 900)
    obs = np.zeros((3, 11), np.float32)
    assert handover(obs).shape == last(obs).shape == (3, 3) and not np.allclose(handover(obs), last(obs))


@pytest.mark.parametrize("args, fragment", [
    (["--online-steps", "1500", "--online-block", "1000"], "multiple of the block"),
    (["--online-mix", "1.5"], "online_mix"),
    (["--utd", "0"], "positive integer"),
    (["--algo", "bc"], "no offline-RL phase"),
    (["--pretrain-updates", "auto"], "pretrain-only"),
    (["--env", "door", "--level", "medium"], "door's levels: human, cloned"),
    (["--replay", "sometimes"], "invalid choice"),
    (["--algo", "iql", "--arms", "online-rl"], "no form without its behaviour terms"),
    (["--buffer-capacity", "500"], "give a capacity of at least 1999"),  # before the offline phases, not after
    # a flag that would do nothing: the mix where the replay does not mix, noise where the actor samples
    (["--replay", "online-only", "--online-mix", "0.3"], "replay online-only, which does not mix"),
    (["--replay", "append", "--online-mix", "0.3"], "replay append, which does not mix"),
    (["--algo", "iql", "--online-mix", "0.2"], "replay append, which does not mix"),  # IQL's own replay
    (["--algo", "edac", "--explore-noise", "0.3"], "actor is stochastic"),
    (["--algo", "iql", "--no-deterministic", "--explore-noise", "0.3"], "actor is stochastic"),
    (["--algo", "cql", "--calibration-online", "off"], "no variant of hopper-medium-cql bounds its CQL penalty"),
    (["--algo", "calql", "--arms", "online-rl", "--calibration-online", "off"], "bounds its CQL penalty"),
    (["--variant", "pretrained"], "--variant chooses among the variants of a finished run given with --from"),
    (["--from", "somewhere", "--variant", "pretrained", "pretrained"], "a variant is named twice"),
    # what the int32 update counter cannot count: the online updates, and with the offline ones
    (["--online-steps", "400", "--online-block", "200", "--utd", "10000000"], "past what the update counter holds"),
    (["--online-steps", "400", "--online-block", "200", "--utd", "5368700"], "its offline and online updates"),
])
def test_finetune_refuses_bad_online_settings_in_one_line(tmp_path, args, fragment):
    result = run_module("experiments.finetune", *args, "--out", tmp_path / "x")
    assert result.returncode == 2
    assert fragment in result.stderr and len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert not (tmp_path / "x").exists()


def test_an_actor_samples_or_takes_the_exploration_noise():
    from experiments.finetune import samples

    def config(algo, **kw):
        return make_config(algo, "hopper", hidden=(8, 8), **kw)

    assert not samples(config("td3bc"), "hopper") and not samples(config("rebrac"), "hopper")
    assert not samples(config("iql", deterministic=True), "hopper")  # noise: its action is deterministic
    assert samples(config("edac"), "hopper") and samples(config("iql", deterministic=False), "hopper")
    assert samples(config("cql"), "hopper") and samples(config("calql"), "hopper")


def test_fewer_online_steps_than_the_default_block_shrink_it_to_fit():
    dry = run_module("experiments.finetune", "--online-steps", "400", "--dry-run")
    assert dry.returncode == 0, dry.stderr
    assert "400 env steps per seed after the offline phases (400 updates), blocks of 400" in dry.stdout
    assert "evaluation every 400 env steps" in dry.stdout
    warm = run_module("experiments.finetune", "--online-steps", "400", "--warmup-steps", "100", "--dry-run")
    assert warm.returncode == 0 and "blocks of 100, utd 1, warm-up 100" in warm.stdout, warm.stderr
    given = run_module("experiments.finetune", "--online-steps", "400", "--online-block", "1000", "--dry-run")
    assert given.returncode == 2 and "must be a multiple of the block (1000" in given.stderr  # a block given stays


def test_online_measures_by_hand():
    """Two seeds, an online phase of 1000 env steps evaluated every 100: the hand-over, the dip in the first 10 %,
    the final score, the gain and the episode-weighted training score, computed by hand."""
    from offrl_jax.run.online_summary import summarize_online

    rows = [{"variant": "a", "seed": s, "phase": "offline_rl", "update": 50, "score": h}
            for s, h in ((0, 40.0), (1, 30.0))]
    for step, (s0, s1), (t0, t1), (e0, e1) in ((100, (35.0, 33.0), (20.0, 10.0), (1, 3)),
                                               (200, (30.0, 40.0), (30.0, 50.0), (3, 1)),
                                               (1000, (60.0, 70.0), (40.0, 20.0), (0, 2))):
        rows += [{"variant": "a", "seed": 0, "phase": "online", "update": 50 + step, "score": s0, "env_steps": step,
                  "train_score": t0, "train_episodes": e0},
                 {"variant": "a", "seed": 1, "phase": "online", "update": 50 + step, "score": s1, "env_steps": step,
                  "train_score": t1, "train_episodes": e1}]
    from offrl_jax.run.results import pretrain_ends_of

    assert pretrain_ends_of(rows) == {"a": 0}  # online rows are no pre-training
    (a,) = summarize_online(rows, ["a"], (0, 1), 1000, behaviour=36.0)
    assert a["handover"]["per_seed"] == [40.0, 30.0]
    assert a["dip"]["per_seed"] == [-5.0, 3.0]  # only the evaluation at 100 is in the first 10 %
    assert a["final"]["per_seed"] == [60.0, 70.0] and a["gain"]["per_seed"] == [20.0, 40.0]
    np.testing.assert_allclose(a["train_score"]["per_seed"], [(20 + 90) / 4, (30 + 50 + 40) / 6])
    behaviour, best = a["reach"]
    # seed 0 hands over at 40, above the behaviour's 36: there at env step 0 (then 35 and 30 online, 60 at 1000)
    assert behaviour["env_steps"] == [0, 200] and behaviour["censored"] == [False, False]
    assert best["score"] == pytest.approx(0.9 * 65.0) and best["env_steps"] == [1000, 1000]
    # a negative best: 90 % of it lies below it (-11 for -10), which the best variant reaches
    negative = [{"variant": "a", "seed": s, "phase": "offline_rl", "update": 50, "score": -20.0} for s in (0, 1)]
    negative += [{"variant": "a", "seed": s, "phase": "online", "update": 150, "score": -12.0, "env_steps": 100}
                 for s in (0, 1)]
    (a,) = summarize_online(negative, ["a"], (0, 1), 100)
    (best,) = a["reach"]
    assert best["score"] == pytest.approx(-13.2) and best["env_steps"] == [100, 100] and not any(best["censored"])


def test_warm_up_evaluations_keep_the_hand_over_on_the_update_axis():
    """Evaluations during the warm-up share the hand-over's update: against updates the hand-over's score stays,
    against env steps (the online measures) every evaluation is there."""
    from offrl_jax.run.online_summary import online_curves
    from offrl_jax.run.results import score_matrix

    rows = [{"variant": "a", "seed": 0, "phase": "offline_rl", "update": 50, "score": 40.0, "seconds": 1.0},
            {"variant": "a", "seed": 0, "phase": "online", "update": 50, "score": 10.0, "seconds": 2.0,
             "env_steps": 100},
            {"variant": "a", "seed": 0, "phase": "online", "update": 150, "score": 60.0, "seconds": 3.0,
             "env_steps": 200}]
    updates, _, scores = score_matrix(rows, "a")
    assert updates.tolist() == [50, 150] and scores.tolist() == [[40.0, 60.0]]
    curves = online_curves(rows, "a", (0,))
    assert curves["handover"].tolist() == [40.0] and curves["scores"].tolist() == [[10.0, 60.0]]
    from offrl_jax.run.results import best_scores

    assert best_scores(rows[:2]) == {"a": 40.0} and best_scores(rows) == {"a": 60.0}  # not the two averaged


def test_warm_up_evaluations_are_read_back_beside_the_hand_over_row(tmp_path):
    """A warm-up that reaches the first online evaluations writes rows at the hand-over's update, each at its env
    step: curves.csv reads them back (report and --resume), and a row repeated at the same env step is refused."""
    from offrl_jax.run.results import write_curves

    rows = [{"variant": "a", "algo": "td3bc", "seed": s, "phase": "offline_rl", "update": 300, "seconds": 1.0,
             "score": 40.0} for s in (0, 1)]
    rows += [{"variant": "a", "algo": "td3bc", "seed": s, "phase": "online", "update": 300, "seconds": 2.0,
              "score": 10.0, "env_steps": step} for step in (200, 400) for s in (0, 1)]
    write_curves(tmp_path / "curves.csv", rows)
    assert len(read_curves(tmp_path / "curves.csv")) == 6
    write_curves(tmp_path / "curves.csv", rows + rows[-1:])
    with pytest.raises(ValueError, match="seed 1 has two rows at update 300 \\(env step 400\\)"):
        read_curves(tmp_path / "curves.csv")


@pytest.mark.slow  # one of the suite's longest (1-5 min on 2 busy cores); -m slow runs it
def test_finetune_from_a_finished_offline_run_starts_at_its_checkpoint(tmp_path):
    offline = tmp_path / "offline"
    argv = ["--env", "hopper", "--updates", "400", "--eval-every", "200", "--seeds", "2", "--max-transitions",
            "20000", "--hidden", "16", "16", "--eval-episodes", "1", "--parallel", "1", "--no-progress",
            "--pretrain-updates", "200"]
    assert run_module("experiments.mujoco_medium", *argv, "--out", offline).returncode == 0
    refused = run_module("experiments.finetune", "--from", offline, "--alpha", "3", "--out", tmp_path / "x")
    assert refused.returncode == 2 and "--alpha cannot be given" in refused.stderr and not (tmp_path / "x").exists()
    refused = run_module("experiments.finetune", "--from", offline, "--variant", "nope", "--out", tmp_path / "x")
    assert refused.returncode == 2 and "--variant nope" in refused.stderr
    out = tmp_path / "online"
    done = run_module("experiments.finetune", "--from", offline, "--variant", "pretrained", "--online-steps", "600",
                      "--online-block", "300", "--online-eval-every", "300", "--replay", "append", "--parallel", "1",
                      "--no-progress", "--out", out)
    assert done.returncode == 0, done.stderr
    before = read_curves(offline / "curves.csv")
    after = read_curves(out / "curves.csv")
    first = [(r["seed"], r["update"], r["score"]) for r in before if r["variant"] == "pretrained"]
    assert [(r["seed"], r["update"], r["score"]) for r in after if r["phase"] != "online"] == first
    assert {r["env_steps"] for r in after if r["phase"] == "online"} == {300.0, 600.0}
    saved = json.loads((out / "config.json").read_text())
    assert saved["start_from"] == str(offline.resolve()) and [v["label"] for v in saved["variants"]] == ["pretrained"]
    assert saved["resolved"]["pretrained"]["replay"] == "append"
    # its hand-over is the offline run's last checkpoint, kept as any fine-tuning run keeps it
    from offrl_jax.policy import load_policy

    assert load_policy(out, "pretrained", checkpoint="handover").update == 400
    # a resume from the first online checkpoint without its online state starts the phase again from there
    rewind_to_first_online_checkpoint(out / "checkpoints" / "pretrained.msgpack", update=700)
    resumed = run_module("experiments.finetune", "--resume", out, "--no-progress", "--parallel", "1")
    assert resumed.returncode == 0 and "starts again from the hand-over" in resumed.stderr, resumed.stderr
    no_time = lambda rows: [{k: v for k, v in r.items() if k != "seconds"} for r in rows]  # noqa: E731
    assert no_time(read_curves(out / "curves.csv")) == no_time(after)
    # as if killed after its hand-over was saved and before its first online evaluation: no last checkpoint yet,
    # curves.csv has the offline rows; the policy acts from the hand-over, and --resume goes on from there
    from offrl_jax.run.results import write_curves

    (out / "checkpoints" / "pretrained.msgpack").unlink()
    (out / "summary.json").unlink()
    shutil.rmtree(out / "online")
    write_curves(out / "curves.csv", [r for r in after if r["phase"] != "online"])
    assert load_policy(out, "pretrained").update == 400
    resumed = run_module("experiments.finetune", "--resume", out, "--no-progress", "--parallel", "1")
    assert resumed.returncode == 0, resumed.stderr
    assert no_time(read_curves(out / "curves.csv")) == no_time(after)
    refused = run_module("offrl_jax.rollout", offline, "--checkpoint", "handover")  # never fine-tuned
    assert refused.returncode == 2 and "no online phase (it was never fine-tuned)" in refused.stderr, refused.stderr


def test_finetune_from_refuses_what_is_not_a_finished_run_before_writing(tmp_path):
    """--from a missing directory, a file, an empty directory, a run stopped before the end of its offline phases,
    or --out the run itself: one line saying what --from wants, and no --out created."""
    from experiments.mujoco_medium import build, make_parser
    from offrl_jax.run.results import write_curves

    (tmp_path / "file").write_text("x")
    (tmp_path / "empty").mkdir()
    stopped = tmp_path / "stopped"
    stopped.mkdir()
    study = build(make_parser().parse_args(["--updates", "400", "--eval-every", "200", "--seeds", "2",
                                            "--pretrain-updates", "200", "--hidden", "16", "16"]))
    (stopped / "config.json").write_text(study.to_json())
    write_curves(stopped / "curves.csv", [{"variant": v, "algo": "td3bc", "seed": s, "phase": "offline_rl",
                                           "update": 200, "seconds": 1.0, "score": 10.0}
                                          for v in ("pretrained", "scratch") for s in (0, 1)])
    out = tmp_path / "out"
    for source, fragment in ((tmp_path / "missing", "it does not exist; --from takes the directory of a finished"),
                             (tmp_path / "file", "it is not a directory"),
                             (tmp_path / "empty", "it holds no config.json"),
                             (stopped, "pretrained stopped at update 200 of 400, so its offline phases are not "
                                       f"finished: finish them first (--resume {stopped})")):
        refused = run_module("experiments.finetune", "--from", source, "--out", out)
        assert refused.returncode == 2 and fragment in refused.stderr, refused.stderr
        assert len(refused.stderr.strip().splitlines()) == 1 and not out.exists()
    refused = run_module("experiments.finetune", "--from", stopped, "--out", stopped, "--overwrite")
    assert refused.returncode == 2 and "is the run given with --from" in refused.stderr, refused.stderr


def test_the_online_rl_arm_has_no_offline_phase_and_no_behaviour_term(tmp_path):
    out = tmp_path / "run"
    argv = TINY[:TINY.index("--arms")]  # the tiny run's flags before its arms and pre-training
    done = run_module("experiments.finetune", *argv, "--arms", "online-rl", "--seeds", "1", "--out", out)
    assert done.returncode == 0, done.stderr
    rows = read_curves(out / "curves.csv")
    assert [(r["phase"], r["update"], r.get("env_steps")) for r in rows] == [
        ("offline_rl", 0, None), ("online", 300, 300.0), ("online", 600, 600.0)]  # the initial policy, then online
    resolved = json.loads((out / "config.json").read_text())["resolved"]["online-rl"]
    assert (resolved["offline_updates"], resolved["bc_weight"], resolved["pretrain"]) == (0, 0.0, "none")
    assert (out / "checkpoints" / "online-rl.handover.msgpack").is_file()
    before = (out / "config.json").read_text()
    longer = run_module("experiments.finetune", "--resume", out, "--updates", "800", "--no-progress")
    assert longer.returncode == 2 and "cannot be extended on resume" in longer.stderr.strip().splitlines()[-1]
    assert (out / "config.json").read_text() == before  # nothing rewritten with a budget it never trained


def test_a_member_that_diverges_online_is_left_out_and_the_others_finish(tmp_path):
    out = tmp_path / "run"
    argv = TINY[:TINY.index("--arms")]
    argv[argv.index("--online-steps") + 1] = "1500"  # past hopper's 1000-step time limit after the divergence
    done = run_module("experiments.finetune", *argv, "--arms", "online-rl", "--alpha", "2.5", "1e38", "--out", out)
    assert done.returncode == 0, done.stderr  # the huge alpha's actor blows up at its first online updates
    assert "diverged: td3bc" in done.stderr and "phase online" in done.stderr
    summary = {s["variant"]: s for s in json.loads((out / "summary.json").read_text())}
    assert summary["online-rl alpha=1e+38"]["seeds_diverged"] == [0, 1]
    assert summary["online-rl alpha=2.5"]["seeds_diverged"] == []
    assert all(x is not None for x in summary["online-rl alpha=2.5"]["online"]["final"]["per_seed"])
    with h5py.File(out / "online" / "hopper-online-rl alpha=1e+38-seed0.hdf5") as f:  # not stepped once diverged
        rewards = f["rewards"][:]
    assert len(rewards) == 1500 and np.isnan(rewards[300:]).all() and np.isfinite(rewards[:300]).all()



def test_an_algorithms_online_rl_arm_is_the_form_its_registry_entry_declares(monkeypatch):
    """The fine-tuning study's online-rl arm is the algorithm without its behaviour terms as its `ALGOS` entry
    declares them (`without_behaviour`): a new entry that declares a form gets the arm, with those values."""
    import argparse

    from experiments import finetune
    from offrl_jax import algos
    from offrl_jax.algos.common import Algo

    monkeypatch.setitem(algos.ALGOS, "td3bc_alpha5", Algo("td3bc", {"alpha": 5.0},
                                                          without_behaviour={"bc_weight": 0.0, "alpha": 1.0}))
    args = finetune.make_parser().parse_args(["--algo", "td3bc_alpha5", "--env", "hopper"])
    study = finetune.build(argparse.Namespace(**vars(args), typed=frozenset()))
    arms = {v.label: study.config(v.label) for v in study.variants}
    assert "online-rl" in arms
    assert (arms["online-rl"].bc_weight, arms["online-rl"].alpha) == (0.0, 1.0)
    assert arms["scratch"].bc_weight == 1.0
