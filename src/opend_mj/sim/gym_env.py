"""A gymnasium-compatible wrapper of the OpenD task, for RL users.

    env = OpenDGymEnv(EpisodeSpec(Path("cabinets/proc_0004"), "joint_0", "allegro", seed=0))
    obs, info = env.reset(seed=0)
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())

Observations are a dict of arrays (rgb, depth, hand_joint_pos, root_pos, root_quat); the instruction
is in `info["instruction"]` (and `env.instruction`); `info["outcome"]` holds the success checker's
verdict. `reset(seed=...)` rebuilds the episode with that seed (room and lighting follow it).
"""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np

from opend_mj.sim.task import EpisodeSpec, TaskConfig, make_environment

_ARRAY_KEYS = ("rgb", "depth", "hand_joint_pos", "root_pos", "root_quat")


class OpenDGymEnv(gym.Env):
    metadata = {"render_modes": ["rgb_array"], "render_fps": 60}

    def __init__(self, episode: EpisodeSpec, config: TaskConfig = TaskConfig(), render_mode: str | None = None):
        self.episode = episode
        self.config = config
        self.render_mode = render_mode
        self._env = make_environment(episode, config)
        spec = self._env.action_spec()
        self.action_space = gym.spaces.Box(spec.minimum.astype(np.float32), spec.maximum.astype(np.float32),
                                           dtype=np.float32)
        obs_spec = self._env.observation_spec()
        spaces = {}
        for key in _ARRAY_KEYS:
            if key not in obs_spec:
                continue
            s = obs_spec[key]
            if key == "rgb":
                spaces[key] = gym.spaces.Box(0, 255, s.shape, np.uint8)
            else:
                spaces[key] = gym.spaces.Box(-np.inf, np.inf, s.shape, np.float32 if key == "depth" else np.float64)
        self.observation_space = gym.spaces.Dict(spaces)
        self._last_rgb = None

    @property
    def instruction(self) -> str:
        return self._env.task.instruction

    def _obs(self, timestep) -> dict:
        obs = {k: np.asarray(timestep.observation[k]) for k in self.observation_space.spaces}
        self._last_rgb = obs.get("rgb")
        return obs

    def _info(self) -> dict:
        return {"instruction": self.instruction, "outcome": self._env.task.outcome(self._env.physics).to_dict()}

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        if seed is not None and seed != self.episode.seed:
            self._env.close()
            self.episode = dataclasses.replace(self.episode, seed=int(seed))
            self._env = make_environment(self.episode, self.config)
        return self._obs(self._env.reset()), self._info()

    def step(self, action):
        timestep = self._env.step(np.asarray(action, dtype=np.float64))
        info = self._info()
        terminated = bool(info["outcome"]["success"])
        truncated = bool(timestep.last()) and not terminated
        return self._obs(timestep), float(timestep.reward or 0.0), terminated, truncated, info

    def render(self):
        return self._last_rgb

    def close(self):
        self._env.close()
