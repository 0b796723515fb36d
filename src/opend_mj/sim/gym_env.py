"""gymnasium environments: registered ids over the dataset, and a wrapper of one fixed episode.

Importing this module registers (see `opend_mj.sim.envs` for what an episode, an observation and an
action are)::

    import gymnasium as gym
    import opend_mj.sim.gym_env  # noqa: F401  (registers the ids below)

    env = gym.make("opend/OpenCabinet-v0", hand="allegro", split="train", cabinets="cabinets",
                   obs_mode="state")          # or "rgbd"; privileged=True adds the handle's box
    obs, info = env.reset(seed=0)            # samples cabinet, target, room and hand start
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    info["success"], info["open_ratio"], info["others_moved"]

    envs = gym.make_vec("opend/OpenCabinet-v0", num_envs=2, cabinets="cabinets")  # shared-memory workers

``opend/OpenDrawer-v0`` and ``opend/OpenDoor-v0`` sample drawers or doors only. Without importing
this module first, ``gym.make("opend_mj.sim.gym_env:opend/OpenCabinet-v0", ...)`` imports it.

`OpenDGymEnv` (below the registered environment) wraps one fixed episode:

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

from opend_mj.sim.spaces import action_space, observation_space
from opend_mj.sim.task import EpisodeSpec, TaskConfig, make_environment

_ARRAY_KEYS = ("rgb", "depth", "hand_joint_pos", "root_pos", "root_quat")

ENV_IDS = {"opend/OpenCabinet-v0": {}, "opend/OpenDrawer-v0": {"target_types": ("drawer",)},
           "opend/OpenDoor-v0": {"target_types": ("door",)}}


class OpenCabinetEnv(gym.Env):
    """A cabinet, a target, a room and a hand start sampled at each ``reset(seed=...)``.

    Keyword arguments: the fields of `opend_mj.sim.envs.EnvConfig` (``hand``, ``split``,
    ``cabinets``, ``cabinet_ids``, ``target_types``, ``obs_mode``, ``privileged``, ``instruction``,
    ``control``, ``reward_mode``, ``image_size``, ``time_limit``, ...). Observations are float32 (rgb
    uint8); ``info`` carries ``success``, ``open_ratio``, ``others_moved``, the episode and
    ``reward_terms``. ``reset(options={"cabinet": id, "target": joint, "room": k})`` fixes parts of
    the episode.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 60}

    def __init__(self, render_mode: str | None = None, **kwargs):
        from opend_mj.sim.envs import OpenDCore, make_config

        self.render_mode = render_mode
        self.core = OpenDCore(make_config(**kwargs))
        self.observation_space = observation_space(self.core)
        self.action_space = action_space(self.core)
        self.action_names = self.core.action_names()
        self.core.set_observation_order(self.observation_space.spaces)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        episode_seed = int(seed) if seed is not None else int(self.np_random.integers(2**31 - 1))
        obs, info = self.core.reset(episode_seed, options, dtype=np.float32)
        return obs, info  # float32 views of one vector, rgb uint8, depth float32, in the space's key order

    def step(self, action):
        obs, reward, terminated, truncated, info = self.core.step(action, dtype=np.float32)
        return obs, float(reward), terminated, truncated, info

    def render(self):
        return self.core.render()

    def close(self):
        self.core.close()


def register_envs() -> None:
    """Register the ids of `ENV_IDS` with gymnasium (done on import; repeated calls are no-ops)."""
    for env_id, kwargs in ENV_IDS.items():
        if env_id not in gym.registry:
            gym.register(id=env_id, entry_point="opend_mj.sim.gym_env:OpenCabinetEnv",
                         vector_entry_point="opend_mj.sim.vector_env:OpenDVectorEnv", kwargs=dict(kwargs))


register_envs()


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
