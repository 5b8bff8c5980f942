"""Adroit: the original (D4RL / DAPG) dense reward functions for door, hammer and relocate.

gymnasium-robotics 1.2.1 (the refactor that added the sparse variants, Farama-Foundation/Gymnasium-Robotics PR 220
documents it) changed the dense reward of `AdroitHandDoor-v1`, `AdroitHandHammer-v1` and `AdroitHandRelocate-v1`
without a version bump: the first term, the hand-to-object distance penalty `reward -= 0.1 * ||palm - obj||`, became
`reward = 0.1 * ||palm - obj||`, a *bonus* for keeping the hand away.  So in gymnasium-robotics 1.2.1 - 1.4.2

    r_installed = r_original + 0.2 * ||palm - obj||        (obj: door handle / hammer body / ball)

Everything else (dynamics, observations, bonuses) is unchanged.  D4RL's datasets (door-human etc.), its reference
scores and the paper's re-computed random scores (Jelley et al., Table 4) all use the original reward:

  * door-human's recorded rewards equal the original reward read off the next recorded observation up to the
    velocity cost (residual in [-0.023, -2e-5], mean |.| 0.001); with the installed sign the mean |error| is 0.027.
  * on the same simulated states, installed - original = 0.2 * ||palm - handle|| to 4e-15 (tests/test_door_cloned.py;
    an open-loop replay of the demonstrations drifts: their first observations differ from the recorded initial
    states by up to 0.5 in the arm joints).
  * 100 uniform-random episodes (paper time limits, the seeds of experiments.adroit_random_scores): door -84.65 +-
    0.10 (paper -84.52; installed reward -68.75), hammer -857.21 +- 1.57 (-856.83; -833.45), relocate -39.10 +- 3.87
    (-37.95; +48.59).

`OriginalAdroitReward` wraps a door/hammer/relocate env and replaces the reward by the original one, recomputed from
the simulator state after each step, so it is right whichever gymnasium-robotics version is installed (on a fixed
version it changes nothing).  `info["installed_reward"]` keeps the env's own reward.  The pen reward was not changed,
so pen needs no wrapper (D4RL's pen_v0 also ended the episode when the pen dropped; gymnasium-robotics' does not, and
the paper's pen random score agrees with the non-terminating env).  Pinning gymnasium-robotics==1.2.0 instead is not
an option with this stack: it requires numpy<1.24, its envs do not register through `gym.register_envs`, and
MuJoCo 4 rejects its XML (`apirate` attribute).
"""
from __future__ import annotations

import gymnasium as gym
import numpy as np

TASKS = ("door", "hammer", "relocate")


def _task_of(env) -> str:
    name = type(env.unwrapped).__name__.lower()
    for task in TASKS:
        if task in name:
            return task
    raise ValueError(f"{type(env.unwrapped).__name__}: not an Adroit door/hammer/relocate env")


class _Ids:
    """MuJoCo ids the original reward functions need, looked up by name (independent of the env's attribute names)."""

    def __init__(self, task: str, model):
        import mujoco

        site = lambda n: mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, n)  # noqa: E731
        body = lambda n: mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, n)  # noqa: E731
        self.grasp = site("S_grasp")
        if task == "door":
            self.handle = site("S_handle")
            joint = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "door_hinge")
            self.hinge = int(model.jnt_qposadr[joint])
        elif task == "hammer":
            self.obj, self.tool, self.target, self.goal = body("Object"), site("tool"), site("S_target"), site(
                "nail_goal")
        else:
            self.obj, self.target = body("Object"), site("target")
        ids = [v for v in vars(self).values()]
        if min(ids) < 0:
            raise ValueError(f"{task}: a site/body/joint the original reward needs is missing from the model")


def original_reward(task: str, data, ids: _Ids) -> float:
    """The D4RL / DAPG (mj_envs *_v0) dense reward of `task` for the current MuJoCo `data` (after the step)."""
    palm = data.site_xpos[ids.grasp]
    if task == "door":
        door_pos = float(data.qpos[ids.hinge])
        reward = -0.1 * np.linalg.norm(palm - data.site_xpos[ids.handle])  # get to handle
        reward += -0.1 * (door_pos - 1.57) ** 2  # open door
        reward += -1e-5 * np.sum(data.qvel ** 2)  # velocity cost
        reward += 2.0 * (door_pos > 0.2) + 8.0 * (door_pos > 1.0) + 10.0 * (door_pos > 1.35)
    elif task == "hammer":
        obj, tool = data.xpos[ids.obj], data.site_xpos[ids.tool]
        target, goal = data.site_xpos[ids.target], data.site_xpos[ids.goal]
        nail_dist = np.linalg.norm(target - goal)
        reward = -0.1 * np.linalg.norm(palm - obj)  # get to hammer
        reward -= np.linalg.norm(tool - target)  # take hammer head to nail
        reward -= 10.0 * nail_dist  # make nail go inside
        reward -= 1e-2 * np.linalg.norm(data.qvel)  # velocity penalty
        reward += 2.0 * (obj[2] > 0.04 and tool[2] > 0.04)  # lifted the hammer
        reward += 25.0 * (nail_dist < 0.020) + 75.0 * (nail_dist < 0.010)  # hammered the nail
    elif task == "relocate":
        obj, target = data.xpos[ids.obj], data.site_xpos[ids.target]
        obj_dist = np.linalg.norm(obj - target)
        reward = -0.1 * np.linalg.norm(palm - obj)  # take hand to object
        if obj[2] > 0.04:  # object off the table
            reward += 1.0 - 0.5 * np.linalg.norm(palm - target) - 0.5 * obj_dist
        reward += 10.0 * (obj_dist < 0.1) + 20.0 * (obj_dist < 0.05)
    else:
        raise ValueError(f"{task}: no original reward (valid: {', '.join(TASKS)})")
    return float(reward)


class OriginalAdroitReward(gym.Wrapper):
    """Replace the dense reward of an Adroit door/hammer/relocate env by the original D4RL one (see module doc).

    Wrap the env `gym.make` returns (outside the TimeLimit is fine: the reward only reads the simulator state).
    Sparse-reward variants are refused: the wrapper would silently turn them dense.
    """

    def __init__(self, env: gym.Env):
        super().__init__(env)
        if getattr(env.unwrapped, "sparse_reward", False):
            raise ValueError("OriginalAdroitReward is for the dense-reward Adroit envs")
        self.task = _task_of(env)
        self._ids = _Ids(self.task, env.unwrapped.model)

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        info = dict(info, installed_reward=reward)
        return obs, original_reward(self.task, self.env.unwrapped.data, self._ids), terminated, truncated, info


def with_original_reward(env: gym.Env) -> gym.Env:
    """`env` wrapped in `OriginalAdroitReward` if it is a dense door/hammer/relocate env not wrapped yet, else `env`
    unchanged (pen, the MuJoCo locomotion envs, the sparse variants, an already wrapped env)."""
    try:
        _task_of(env)
    except ValueError:
        return env
    if getattr(env.unwrapped, "sparse_reward", False):
        return env
    inner = env
    while isinstance(inner, gym.Wrapper):
        if isinstance(inner, OriginalAdroitReward):
            return env
        inner = inner.env
    return OriginalAdroitReward(env)
