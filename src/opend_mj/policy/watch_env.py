"""The watched front for gymnasium users: ``front_watch`` in the observations of the dataset's environments.

`FrontWatchWrapper` goes around an environment of ``opend/OpenCabinet-v0`` (or ``OpenDrawer-v0`` /
``OpenDoor-v0``) and adds ``front_watch``, the numbers the behaviour-cloning policy reads while it
acts (`policy.perception.watch`, names and units in `WATCH_NAMES` / `FrontWatcher`)::

    import gymnasium as gym
    import opend_mj.sim.gym_env  # noqa: F401  (registers the ids)
    from opend_mj.policy.watch_env import FrontWatchWrapper

    env = FrontWatchWrapper(gym.make("opend/OpenDrawer-v0", cabinets="cabinets"), solver="fasterrcnn", every=12)
    obs, info = env.reset(seed=0)       # the solver locates the instructed handle in the first image
    obs["front_watch"]                  # float32 (WATCH_DIM,), every step; a new depth image every 12

At reset the handle solver (a registered name, made once through `policy.factory.agent_solver`, which
refuses a solver that reads the simulator; or an object with ``solve(rgb, depth, instruction, view)``)
finds the instructed handle in the first RGB-D image (`policy.learned.bc_model.perceive_handle`) and a
`FrontWatcher` keeps that image. At control step ``k`` (the observation after ``k`` actions) where
``WatchConfig.looks_at(k)`` (every ``every`` steps) the watcher reads a new depth image; every step
it gives its vector with the grasp site of that step.

Inputs, all an agent's own (nothing of the cabinet's ground truth, whether or not the environment
is ``privileged``): the instruction (``info["instruction"]``, the text in every instruction mode),
the front camera's intrinsics and pose (`SceneReader.camera_view`, what ``camera_K`` and
``camera_pose`` hold), the images, the grasp site (``obs["grasp_site_pos"]``, the hand's own state;
read from the scene's proprioception where a wrapper below removed it) and the simulated time
(``info["sim_time"]``).

Images: in ``obs_mode="rgbd"`` the wrapper reads the observation's own images (the first for the
solver, then the depth of each look step; ``"depth"`` mode: its depth). Otherwise it renders what the observation lacks
through the scene's renderer (`SceneReader`): the first RGB-D image at reset, then a depth image
only on look steps, about one render per ``every`` steps (2 ms at 256 px on a CPU, plus
`front_motion`'s few ms). A depth image it renders is the task's sensor's (`OpenCabinetTask.sense_depth`),
as ``rgbd`` mode's is.

Where the solver finds no handle, ``front_watch`` is zeros on every step of the episode (``looked``
stays 0, and so do the grasp site numbers, which are otherwise relative to the handle);
`FrontWatchWrapper.located` says which. The wrapper adds nothing random: for a seed the numbers are
the environment's and the solver's (the shipped solvers are deterministic on one machine).

For several environments, wrap each: ``gym.vector.SyncVectorEnv([lambda: FrontWatchWrapper(gym.make(...))] * n)``
(`OpenDVectorEnv` of ``gym.make_vec`` steps cores of its own and takes no wrapper).
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np

from opend_mj.policy.perception.watch import WATCH_DIM, WATCH_NAMES, FrontWatcher, WatchConfig

#: The observation key the wrapper adds.
WATCH_KEY = "front_watch"
_WIDE = 1.0e4


def watch_space(config: WatchConfig = WatchConfig()) -> gym.spaces.Box:
    """The Box of ``front_watch``: flags in [0, 1], the shift within the front's ``max_shift``, turns
    within a right angle, the age non-negative, distances wide."""
    limit = config.front.max_shift
    bounds = {"looked": (0.0, 1.0), "seen": (0.0, 1.0), "shift": (-limit, limit),
              "turn_across": (-math.pi / 2, math.pi / 2), "turn_up": (-math.pi / 2, math.pi / 2), "age": (0.0, _WIDE)}
    low = np.array([bounds.get(n, (-_WIDE, _WIDE))[0] for n in WATCH_NAMES], np.float32)
    high = np.array([bounds.get(n, (-_WIDE, _WIDE))[1] for n in WATCH_NAMES], np.float32)
    return gym.spaces.Box(low, high, (WATCH_DIM,), np.float32)


class FrontWatchWrapper(gym.Wrapper):
    """``front_watch`` (`WATCH_DIM` float32, `WATCH_NAMES`) added to the observations of an environment
    over the dataset (`sim.gym_env.OpenCabinetEnv`, as ``gym.make`` returns it, wrapped or not).

    ``solver``: a registered handle solver's name (``fasterrcnn``, ``cliport``; ``solver_options``
    go to it) or an object with ``solve(rgb, depth, instruction, view)``; ``every``: control steps
    between looks (`WatchConfig.every`); ``config``: the whole `WatchConfig` instead (its ``every``
    then rules). After each reset: `percept` (the located handle, or None), `watcher` (None where
    nothing was located), `located`.
    """

    def __init__(self, env: gym.Env, solver="fasterrcnn", every: int = 12, config: WatchConfig | None = None,
                 **solver_options):
        super().__init__(env)
        core = getattr(env.unwrapped, "core", None)
        if core is None or not hasattr(core, "scene"):
            raise TypeError("FrontWatchWrapper wraps an environment over the dataset (opend/OpenCabinet-v0, "
                            f"OpenDrawer-v0, OpenDoor-v0), not {type(env.unwrapped).__name__}")
        self.core = core
        self.config = config if config is not None else WatchConfig(every=int(every))
        if isinstance(solver, str):
            from opend_mj.policy.factory import agent_solver

            self._factory = agent_solver(solver, **solver_options)  # refuses a ground-truth solver now
            self._solver = None
        else:
            if getattr(solver, "needs_ground_truth", False):
                raise ValueError(f"{type(solver).__name__} reads the simulator's ground truth: "
                                 "the watched front takes an agent's solver")
            self._factory, self._solver = None, solver
        spaces = dict(env.observation_space.spaces)
        spaces[WATCH_KEY] = watch_space(self.config)
        self.observation_space = gym.spaces.Dict(spaces)
        self._order = tuple(self.observation_space.spaces)
        self.percept = None
        self.watcher: FrontWatcher | None = None
        self._step = 0

    @property
    def solver(self):
        """The handle solver (a registered one is made on first use)."""
        if self._solver is None:
            self._solver = self._factory()
        return self._solver

    @property
    def located(self) -> bool:
        """Whether the solver located the instructed handle in this episode's first image."""
        return self.watcher is not None

    # ------------------------------------------------------------------ inputs
    def _site(self, obs: dict) -> np.ndarray:
        site = obs.get("grasp_site_pos")
        if site is None:  # removed by a wrapper below: the hand's own state, from the scene
            site = self.core.scene.proprio()["grasp_site_pos"]
        return np.asarray(site, float)

    def _first_images(self, obs: dict) -> tuple[np.ndarray, np.ndarray]:
        if "rgb" in obs and "depth" in obs:
            return np.asarray(obs["rgb"]), np.asarray(obs["depth"], np.float32)
        rgb, depth = self.core.scene.render()
        return rgb, np.asarray(depth, np.float32)

    def _depth(self, obs: dict) -> np.ndarray:
        if "depth" in obs:
            return np.asarray(obs["depth"], np.float32)
        scene = self.core.scene
        if getattr(scene.task, "depth_sensor", None) is None:  # no sensor model: the rendered depth is the sensor's
            return scene.render_depth()
        return np.asarray(scene.render()[1], np.float32)

    def _with_watch(self, obs: dict, vector: np.ndarray) -> dict:
        obs = dict(obs)
        obs[WATCH_KEY] = vector
        return {key: obs[key] for key in self._order}

    # ------------------------------------------------------------------ gymnasium
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        from opend_mj.policy.learned.bc_model import perceive_handle

        obs, info = self.env.reset(seed=seed, options=options)
        self._step = 0
        rgb, depth = self._first_images(obs)
        view = self.core.scene.camera_view()
        self.percept = perceive_handle(self.solver, rgb, depth, info["instruction"], view)
        self.watcher = (FrontWatcher.from_percept(depth, view, self.percept, self.config)
                        if self.percept is not None else None)
        return self._with_watch(obs, self._vector(obs, info)), info

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        self._step += 1
        if self.watcher is not None and self.config.looks_at(self._step):
            self.watcher.look(self._depth(obs), self._site(obs), float(info["sim_time"]))
        return self._with_watch(obs, self._vector(obs, info)), reward, terminated, truncated, info

    def _vector(self, obs: dict, info: dict) -> np.ndarray:
        if self.watcher is None:
            return np.zeros(WATCH_DIM, np.float32)
        return self.watcher.vector(self._site(obs), float(info["sim_time"]))


__all__ = ["FrontWatchWrapper", "WATCH_KEY", "watch_space"]
