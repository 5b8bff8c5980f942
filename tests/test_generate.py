"""Dataset generation: SAC update / short training run, rollouts' episode flags, generate() -> minari, shipped
policies."""
from __future__ import annotations

import json

import jax
import numpy as np
import pytest

from offrl_jax.data.generate import generate, shipped_policies
from offrl_jax.data.generate.collect import POLICY_DIR, collect, load_policy, make_policy
from offrl_jax.data.generate.replay import load_replay
from offrl_jax.data.generate.sac import SACConfig, make_sac, train

needs_medium = pytest.mark.skipif("hopper-medium" not in shipped_policies(), reason="no shipped hopper-medium policy")


def _batch(rng: np.random.Generator, n: int, obs_dim: int = 11, act_dim: int = 3) -> dict[str, np.ndarray]:
    return {
        "observations": rng.normal(size=(n, obs_dim)).astype(np.float32),
        "actions": rng.uniform(-1, 1, (n, act_dim)).astype(np.float32),
        "rewards": rng.normal(size=n).astype(np.float32),
        "next_observations": rng.normal(size=(n, obs_dim)).astype(np.float32),
        "terminals": (rng.uniform(size=n) < 0.1).astype(np.float32),
        "timeouts": np.zeros(n, np.float32),
    }


TINY = SACConfig(hidden=(32, 32), batch_size=32, warmup_steps=100)  # shared: the jitted step compiles once


def test_sac_update_reduces_critic_loss():
    sac = make_sac(11, 3, TINY)
    state = sac.init(0)
    batch = _batch(np.random.default_rng(0), TINY.batch_size)
    obs = np.zeros(11, np.float32)
    losses = []
    for _ in range(100):
        state, info, action = sac.update_and_act(state, batch, obs)
        losses.append(float(info["critic_loss"]))
    assert np.asarray(action).shape == (3,)
    assert np.all(np.isfinite(losses))
    assert np.mean(losses[-5:]) < 0.5 * losses[0]
    # the temperature moves towards the target entropy and stays positive
    assert 0.0 < float(info["alpha"]) < 1.0


def test_sac_short_training_run(tmp_path, monkeypatch):
    run = train("hopper", 300, tmp_path, seed=0, cfg=TINY, eval_every=150, eval_episodes=1, progress=False,
                max_episode_steps=50)
    assert run["steps_done"] == 300 and run["stopped"] == "finished"
    assert [c["step"] for c in run["checkpoints"]] == [150, 300]
    log = [json.loads(line) for line in (tmp_path / "log.jsonl").read_text().splitlines()]
    assert len(log) == 2 and np.isfinite(log[-1]["eval_return"])
    replay = load_replay(tmp_path)
    assert len(replay["rewards"]) == 300
    ends = (replay["terminals"] + replay["timeouts"]) > 0
    # within an episode the next observation is the following row's observation
    assert np.array_equal(replay["next_observations"][:-1][~ends[:-1]], replay["observations"][1:][~ends[:-1]])
    assert len(load_replay(tmp_path, upto=150)["rewards"]) == 150
    params, meta = load_policy(tmp_path / "checkpoints" / "actor_0000300.msgpack")
    assert meta["hidden"] == [32, 32] and meta["obs_dim"] == 11 and meta["act_dim"] == 3
    # medium-replay stops at the first (version 0) medium checkpoint's step; full-replay is the whole run of the expert
    import offrl_jax.data.generate as gen

    fake = {"hopper-medium-v0": {"sac_step": 150, "sac_seed": 0, "file": "m"},
            "hopper-medium": {"sac_step": 250, "sac_seed": 0, "file": "m1"},
            "hopper-expert": {"sac_step": 150, "sac_seed": 0, "sac_run_steps": 300, "file": "e"}}
    monkeypatch.setattr(gen, "shipped_policies", lambda: fake)
    medium_replay, src = gen.build("hopper-medium-replay", sac_run=tmp_path, progress=False)
    full_replay, _ = gen.build("hopper-full-replay", sac_run=tmp_path, progress=False)
    assert len(medium_replay) == 150 and src["upto_step"] == 150 and len(full_replay) == 300
    assert medium_replay.timeouts[-1] + medium_replay.terminals[-1] == 1  # the cut episode ends there


def test_sac_resume_continues_from_the_last_saved_state(tmp_path):
    """A run stopped at 200 steps (or killed after it: a stray later replay chunk) resumes to 300: the replay is 300
    valid rows, the cut episode ends with a time-out, and the state (networks, optimisers, RNG) was reloaded."""
    train("hopper", 180, tmp_path, seed=0, cfg=TINY, eval_every=90, eval_episodes=1, progress=False,
          max_episode_steps=500)
    saved = (tmp_path / "state.msgpack").read_bytes()
    np.savez(tmp_path / "replay" / "0000180_0000200.npz", rewards=np.zeros(20))  # as if killed after step 180
    run = train("ignored", 300, tmp_path, progress=False, max_episode_steps=500, resume=True)
    assert run["steps_done"] == 300 and run["stopped"] == "finished" and run["resumed_at"] == [180]
    assert [c["step"] for c in run["checkpoints"]] == [90, 180, 270, 300]
    assert run["config"]["hidden"] == [32, 32]  # the run's own config, not the default
    replay = load_replay(tmp_path)
    assert len(replay["rewards"]) == 300
    assert replay["terminals"][179] + replay["timeouts"][179] == 1  # the interrupted episode is closed
    assert sorted(f.name for f in (tmp_path / "replay").glob("*.npz")) == [
        "0000000_0000090.npz", "0000090_0000180.npz", "0000180_0000270.npz", "0000270_0000300.npz"]
    assert (tmp_path / "state.msgpack").read_bytes() != saved
    with pytest.raises(FileNotFoundError, match="nothing to resume"):
        train("hopper", 10, tmp_path / "empty", resume=True, progress=False)


def test_collect_random_flags():
    limit = 25
    ds = collect("hopper", "random", 400, seed=0, num_envs=3, max_episode_steps=limit)
    assert len(ds) == 400
    assert not np.any((ds.terminals > 0) & (ds.timeouts > 0))
    ends = np.flatnonzero(ds.episode_ends)
    lengths = np.diff(np.concatenate([[-1], ends]))
    assert lengths.max() <= limit
    full = ends[:-1]  # the last episode may be cut by the transition budget
    full_len = lengths[:-1]
    timeouts, terminals = ds.timeouts[full] > 0, ds.terminals[full] > 0
    assert np.all(timeouts | terminals)
    assert np.all(full_len[timeouts] == limit)  # time-outs exactly at the time limit
    assert terminals.any() and timeouts.any()
    assert ds.terminals[ends[-1]] > 0 or ds.timeouts[ends[-1]] > 0
    # flags only at episode ends, and s_{t+1} = next row's s within episodes (also recorded at time-outs)
    assert (ds.terminals + ds.timeouts).sum() == len(ends)
    inner = np.ones(len(ds), bool)
    inner[ends] = False
    assert np.array_equal(ds.next_observations[inner], ds.observations[1:][inner[:-1]])
    assert not np.array_equal(ds.next_observations[ends[0]], ds.observations[ends[0] + 1])
    assert np.all(np.abs(ds.actions) <= 1.0)


@needs_medium
def test_shipped_checkpoint_shapes():
    meta_all = shipped_policies()
    for name, meta in meta_all.items():
        path = POLICY_DIR / meta["file"]
        assert path.stat().st_size < 1_000_000, name
    params, meta = load_policy("hopper-medium")
    dense = params["params"]["MLP_0"]
    assert dense["Dense_0"]["kernel"].shape == (11, 256)
    assert dense["Dense_1"]["kernel"].shape == (256, 256)
    assert dense["Dense_2"]["kernel"].shape == (256, 6)
    assert meta["obs_dim"] == 11 and meta["act_dim"] == 3 and list(meta["hidden"]) == [256, 256]
    act = make_policy(3, tuple(meta["hidden"]), stochastic=True)
    a = np.asarray(act(params, np.zeros((4, 11), np.float32), jax.random.PRNGKey(0), 0))
    assert a.shape == (4, 3) and np.all(np.abs(a) <= 1.0)


@needs_medium
def test_generate_hopper_medium_minari(tmp_path, monkeypatch):
    import minari

    out = generate("hopper-medium", transitions=2000, out_dir=tmp_path / "hopper-medium", progress=False, num_envs=4)
    assert out == tmp_path / "hopper-medium"
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path))
    ds = minari.load_dataset("hopper-medium")
    assert ds.total_steps == 2000
    episodes = list(ds.iterate_episodes())
    assert sum(len(ep.rewards) for ep in episodes) == 2000
    assert all(ep.terminations[-1] or ep.truncations[-1] for ep in episodes)
    assert ds.storage.metadata["ref_max_score"] == pytest.approx(3234.3)
    info = json.loads((out / "offrl_jax.json").read_text())
    assert info["env"] == "hopper" and info["seed"] == 0 and info["source"]["policy"]["file"]
    assert info["stats"]["transitions"] == 2000
    with pytest.raises(FileExistsError):
        generate("hopper-medium", transitions=2000, out_dir=out, progress=False)


@needs_medium
def test_default_cache_dir_is_a_minari_id_that_minari_lists(tmp_path, monkeypatch):
    import minari

    from offrl_jax.data.dataset import dataset_dir

    monkeypatch.setenv("OFFRL_JAX_CACHE", str(tmp_path))
    out = generate("hopper-medium", transitions=1000, progress=False, num_envs=2)
    assert out == tmp_path / "datasets" / "hopper-medium-v2" == dataset_dir("hopper-medium")  # its current version
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "datasets"))
    assert "hopper-medium-v2" in minari.list_local_datasets()
    assert minari.load_dataset("hopper-medium-v2").total_steps == 1000
    from offrl_jax.data import catalogue
    with pytest.warns(UserWarning, match="generated capped at 1,000 transitions"):  # a full-size run is told
        assert len(catalogue.load("hopper-medium")) == 1000
    monkeypatch.delenv("MINARI_DATASETS_PATH")
    with pytest.warns(UserWarning, match="capped"):  # its Minari id, as Minari writes it, names it too
        assert catalogue.load("hopper-medium-v2").name == "hopper-medium"
    legacy = tmp_path / "datasets" / "walker2d-medium"  # a cache from before the -v0 suffix is moved, not redone
    (legacy / "data").mkdir(parents=True)
    (legacy / "data" / "metadata.json").write_text("{}")
    assert dataset_dir("walker2d-medium") == tmp_path / "datasets" / "walker2d-medium-v0"
    assert (tmp_path / "datasets" / "walker2d-medium-v0" / "data" / "metadata.json").is_file()


@needs_medium
def test_an_earlier_version_stays_loadable_by_its_own_name(tmp_path, monkeypatch):
    """hopper-medium is at version 2; versions 0 and 1 (the policies behind the runs made before it) are made and
    cached under their own names, from their own shipped policies, and medium-expert follows the medium version it
    names."""
    from offrl_jax.data import catalogue
    from offrl_jax.data.dataset import DATASET_VERSIONS, dataset_dir, split_version
    from offrl_jax.data.generate import build, policy_name

    assert DATASET_VERSIONS["hopper-medium"] == 2
    assert split_version("hopper-medium") == ("hopper-medium", 2)
    assert split_version("hopper-medium-v0") == ("hopper-medium", 0)
    assert split_version("hopper-medium-replay") == ("hopper-medium-replay", 0)
    assert policy_name("hopper", "medium", 0) == "hopper-medium-v0"
    assert policy_name("hopper", "medium", 1) == "hopper-medium-v1"
    assert policy_name("hopper", "medium", 2) == policy_name("hopper", "medium") == "hopper-medium"
    assert policy_name("walker2d", "medium", 0) == "walker2d-medium"
    policies = shipped_policies()
    assert policies["hopper-medium-v0"]["sac_step"] == 210_000 and policies["hopper-medium-v1"]["sac_step"] == 170_000
    assert (policies["hopper-medium"]["sac_seed"], policies["hopper-medium"]["sac_step"]) == (2, 120_000)
    monkeypatch.setenv("OFFRL_JAX_CACHE", str(tmp_path))
    assert dataset_dir("hopper-medium-v0").name == "hopper-medium-v0" != dataset_dir("hopper-medium").name
    old, src_old = build("hopper-medium-v0", transitions=300, progress=False, num_envs=2)
    new, src_new = build("hopper-medium", transitions=300, progress=False, num_envs=2)
    assert src_old["policy"]["file"] == "hopper-medium-v0.msgpack"
    assert src_new["policy"]["file"] == "hopper-medium.msgpack"
    assert old.name == "hopper-medium-v0" and not np.array_equal(old.actions, new.actions)
    both, _ = build("hopper-medium-expert-v0", transitions=600, progress=False, num_envs=2)
    np.testing.assert_array_equal(both.observations[:300], old.observations)
    assert {"hopper-medium-v0", "hopper-medium-v1", "hopper-medium-expert-v1"} <= set(catalogue.KNOWN)
    with pytest.raises(catalogue.DatasetError, match="unknown dataset name"):
        catalogue.load("hopper-medium-v7", generate_if_missing=False)


@needs_medium
def test_ship_expert_picks_the_best_stochastic_of_the_top_candidates(tmp_path):
    """The top-2 train-eval checkpoints are re-run stochastically; the better one ships even though its train eval
    was lower, and a checkpoint outside the top 2 is never evaluated."""
    import shutil

    import flax

    from offrl_jax.data.generate.collect import actor_module
    from offrl_jax.data.generate.ship import ship

    run = tmp_path / "run"
    (run / "checkpoints").mkdir(parents=True)
    weak = actor_module(3, (256, 256)).init(jax.random.PRNGKey(0), np.zeros((1, 11), np.float32))
    (run / "checkpoints" / "a.msgpack").write_bytes(flax.serialization.to_bytes(weak))  # untrained: falls at once
    shutil.copyfile(POLICY_DIR / shipped_policies()["hopper-medium"]["file"], run / "checkpoints" / "b.msgpack")
    log = [{"step": 1000, "eval_return": 900.0, "normalized_score": 28.4, "checkpoint": "checkpoints/a.msgpack"},
           {"step": 2000, "eval_return": 800.0, "normalized_score": 25.3, "checkpoint": "checkpoints/b.msgpack"},
           {"step": 3000, "eval_return": 5.0, "normalized_score": 0.8, "checkpoint": "checkpoints/missing.msgpack"},
           {"step": 4000, "eval_return": 1.0, "normalized_score": 0.7, "checkpoint": "checkpoints/b.msgpack"}]
    (run / "log.jsonl").write_text("\n".join(json.dumps(e) for e in log) + "\n")
    (run / "run.json").write_text(json.dumps({"env": "hopper", "gym_id": "Hopper-v5", "seed": 0}))
    record = ship(run, "expert", episodes=2, dest=tmp_path / "policies", candidates=2)
    assert record["sac_step"] == 2000 and record["level"] == "expert"
    assert record["selection"].startswith("best stochastic return (2 episodes) of the 2 checkpoints")
    assert "2k" in record["selection"] and "1k" in record["selection"] and "4k" not in record["selection"]
    assert (tmp_path / "policies" / "hopper-expert.msgpack").exists()
    assert "hopper-expert" in json.loads((tmp_path / "policies" / "policies.json").read_text())


@pytest.mark.parametrize("name", sorted(n for n in shipped_policies() if n.endswith("-expert")))
def test_shipped_expert_behaves_like_an_expert(name):
    """Two full episodes of each shipped expert's stochastic policy (what its dataset is made of) score what
    policies.json records for it (20 episodes) and well above medium; medium-expert is the medium rows, then the
    expert rows."""
    from offrl_jax.data.generate import build
    from offrl_jax.envs.registry import normalized_score

    env = name.split("-")[0]
    ds, source = build(name, transitions=2000, progress=False, num_envs=2)
    ends = np.flatnonzero(ds.episode_ends) + 1
    returns = np.add.reduceat(ds.rewards, np.concatenate([[0], ends[:-1]]))
    assert len(ds) == 2000 and source["stochastic"]
    recorded = shipped_policies()[name]["stochastic_normalized_score"]
    medium_score = shipped_policies()[f"{env}-medium"]["stochastic_normalized_score"]
    assert abs(normalized_score(env, returns.mean()) - recorded) < 10 and recorded > medium_score + 20
    both, _ = build(f"{env}-medium-expert", transitions=2000, progress=False, num_envs=2)
    medium, _ = build(f"{env}-medium", transitions=1000, progress=False, num_envs=2)
    np.testing.assert_array_equal(both.observations[:1000], medium.observations)


def test_scratch_folders_of_killed_generations_are_removed(tmp_path):
    import os

    from offrl_jax.data.generate.write import _remove_stale_scratch

    dead = tmp_path / ".minari-tmp-hopper-medium-v0-999999999"
    alive = tmp_path / f".minari-tmp-hopper-medium-v0-{os.getpid()}"
    other = tmp_path / ".minari-tmp-walker2d-medium-v0-999999999"
    for d in (dead, alive, other):
        d.mkdir()
    _remove_stale_scratch(tmp_path / "hopper-medium-v0")
    assert not dead.exists() and alive.exists() and other.exists()


@needs_medium
def test_generate_into_a_relative_directory(tmp_path, monkeypatch):
    """`datasets generate NAME --out hm` (a relative path) writes ./hm, as an absolute one does."""
    monkeypatch.chdir(tmp_path)
    out = generate("hopper-medium", transitions=1000, out_dir="hm", progress=False, num_envs=2)
    assert out.resolve() == (tmp_path / "hm").resolve() and (tmp_path / "hm" / "offrl_jax.json").is_file()
    assert not list(tmp_path.glob(".minari-tmp-*"))


def test_the_first_n_rows_of_a_generated_dataset_are_what_generating_n_gives(monkeypatch):
    """--max-transitions N before the dataset is cached generates N transitions (the cut episode a time-out); after,
    it reads the cached dataset's first N rows: the same data, so a run's recorded SHA-256 holds either way."""
    from offrl_jax.data import catalogue
    from offrl_jax.data.generate import build
    from offrl_jax.run.provenance import fingerprint

    made, _ = build("hopper-medium", transitions=1500, progress=False)
    full, _ = build("hopper-medium", transitions=3000, progress=False)  # the cache's stand-in
    assert made.timeouts[-1] == 1 and full.timeouts[1499] == 0  # the cut is a time-out only where it was made
    monkeypatch.setattr(catalogue, "_load_generated", lambda *args: full)
    read = catalogue.load("hopper-medium", max_transitions=1500)
    assert fingerprint(read) == fingerprint(made)
    assert full.timeouts[1499] == 0  # the full dataset is left as it is
