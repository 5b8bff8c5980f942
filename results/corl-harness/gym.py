"""The old gym API over gymnasium and offrl_jax's generated data, for running CORL's files unchanged (run.py,
run_finetune.py): `make`, `seed` (each reset after it takes the next seed), `reset` returning the observation, a
4-tuple `step` whose done is terminated or truncated, with old gym's info["TimeLimit.truncated"] at the time limit,
`_max_episode_steps` (offrl_jax's registry: 1,000 for MuJoCo), D4RL's normalised score, the observation and reward
wrappers, `spaces`.  `Env.env_steps` counts the steps taken while `Env.evaluating` is False: the online phase's env
steps when run_finetune.py marks CORL's evaluations."""
import numpy as np
from gymnasium import spaces  # noqa: F401 (gym.spaces.Box, in annotations)
from offrl_jax.data.catalogue import load
from offrl_jax.envs.registry import get_env_spec, make_env as _make, normalized_score

class _Env:
    env_steps = 0  # steps of every env of the process taken while not evaluating
    evaluating = False

    def __init__(self, name):
        self.dataset_name = name.replace("-v2", "")
        self.short = self.dataset_name.split("-")[0]
        self.env = _make(self.short)
        self._max_episode_steps = get_env_spec(self.short).max_episode_steps
        self._seed = 0
    def get_dataset(self):
        ds = load(self.dataset_name)
        return dict(observations=ds.observations, actions=ds.actions, rewards=ds.rewards,
                    next_observations=ds.next_observations, terminals=ds.terminals, timeouts=ds.timeouts)
    def seed(self, s): self._seed = s
    @property
    def action_space(self): return self.env.action_space
    @property
    def observation_space(self): return self.env.observation_space
    def reset(self):
        obs, _ = self.env.reset(seed=self._seed); self._seed += 1; return obs
    def step(self, a):
        obs, r, term, trunc, info = self.env.step(a)
        if not _Env.evaluating:
            _Env.env_steps += 1
        if trunc:
            info["TimeLimit.truncated"] = not term  # old gym's TimeLimit
        return obs, r, term or trunc, info
    def get_normalized_score(self, returns): return normalized_score(self.short, returns) / 100.0

def make(name): return _Env(name)

class _Wrap:
    def __init__(self, env): self._env = env
    def __getattr__(self, k): return getattr(self._env, k)
    def reset(self): return self.f_obs(self._env.reset())
    def step(self, a):
        o, r, d, i = self._env.step(a); return self.f_obs(o), self.f_rew(r), d, i

class wrappers:
    class TransformObservation(_Wrap):
        def __init__(self, env, f): super().__init__(env); self.f_obs = f; self.f_rew = lambda r: r
    class TransformReward(_Wrap):
        def __init__(self, env, f): super().__init__(env); self.f_rew = f; self.f_obs = lambda o: o
Env = _Env
