"""Environments over the whole dataset: each reset samples a cabinet, a target, a room and a hand start.

`OpenDCore` is the engine behind the gymnasium environments (`opend_mj.sim.gym_env`, ids
``opend/OpenCabinet-v0``, ``opend/OpenDrawer-v0``, ``opend/OpenDoor-v0``) and the dm_env one
(`OpenDDmEnv` here). One episode is one (cabinet, target) pair of a split of a compiled dataset, one
of the nine rooms with one of ``room_variants`` appearance seeds, and the hand's benchmark start
(beside the cabinet, out of the camera's view) shifted by up to ``start_noise`` metres per axis and
turned by up to ``start_yaw_noise`` radians about z. Everything is drawn from the reset seed, so
``reset(seed=s)`` gives the same episode and the same first observation every time.

Compiled scenes are reused as `opend run` reuses them: a scene is keyed by (cabinet, room,
appearance seed); another target of the same cabinet is set with ``Task.set_target`` and a full
reset, which gives the same state as a scene of its own. The last ``max_scenes`` scenes are kept.

Observations (``obs_mode``): ``"state"`` renders nothing; ``"rgb"``, ``"depth"`` and ``"rgbd"`` add
that much of the front camera's image (``image_size`` square, e.g. 128 or 256) and its intrinsics
and pose. ``privileged=True`` adds ground truth (the instructed handle's
box and the open ratio) for RL from state; the benchmark's agents never get it. See the README's
"Environments" section for the table of keys and action dimensions per hand, and docs/environments.md
for the step's cost, the vector environment and the two success criteria.

Actions (``control``): ``"delta"`` (default): ``6 + n_fingers`` numbers in [-1, 1]: root
translation in the world frame (x 1.25 cm: the root's top speed of 0.75 m/s over one 1/60 s control
step), root rotation as a world-frame rotation vector (x 0.0667 rad: 4 rad/s over one step), both
applied to the current mocap pose (the pose the root is being pulled to), then one number per finger
actuator mapping [-1, 1] onto its control range (absolute joint targets). ``"absolute"``: the task's
own action: root target position (m, world), root quaternion (w, x, y, z), finger targets (the
actuators' units). The root only ever moves through the mocap body, at bounded speed; the fingers
through their position actuators.
"""

from __future__ import annotations

import collections
import math
import os
from dataclasses import dataclass, field, replace
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import dm_env  # noqa: E402
import numpy as np  # noqa: E402
from dm_env import specs  # noqa: E402

from opend_mj.assets.layout import CABINET_JSON, load_manifest  # noqa: E402
from opend_mj.language.onehot import INSTRUCTION_DIM, instruction_onehot  # noqa: E402
from opend_mj.sim.fast.binding import LAST, NAN, WARNING_BITS  # noqa: E402
from opend_mj.sim.hands import touch_parts  # noqa: E402
from opend_mj.sim.rewards import REWARD_MODES, DenseRewardConfig, dense_reward, sparse_reward  # noqa: E402
from opend_mj.sim.rooms import ROOM_NAMES  # noqa: E402
from opend_mj.sim.actions import ABSOLUTE_ROOT_HIGH, ABSOLUTE_ROOT_LOW, ActionAdapter  # noqa: E402,F401
from opend_mj.sim.scene_reader import PROPRIO_KEYS, SceneReader  # noqa: E402,F401  (SceneReader: re-exported)
from opend_mj.sim.environment import OpenDEnvironment, warning_names  # noqa: E402
from opend_mj.sim.task import EpisodeSpec, OpenCabinetTask, TaskConfig  # noqa: E402
from opend_mj.transforms import turn_about_z  # noqa: E402

OBS_MODES = ("state", "rgb", "depth", "rgbd")
CONTROLS = ("delta", "absolute")
INSTRUCTION_MODES = ("onehot", "text")

#: The keys an agent may read (the paper's inputs: RGB-D, camera, instruction, the hand's own state:
#: `PROPRIO_KEYS`).
CAMERA_KEYS = ("rgb", "depth", "camera_K", "camera_pose")
#: Ground truth, only with ``privileged=True`` (never handed to a benchmark agent).
PRIVILEGED_KEYS = ("handle_pos", "handle_size", "open_ratio")


@dataclass(frozen=True)
class EnvConfig:
    """Everything an environment over the dataset is built from (the keyword arguments of gym.make)."""

    hand: str = "allegro"
    split: str = "train"  # "train" | "test" | "all"
    cabinets: str = "cabinets"  # a compiled dataset (with manifest.json)
    cabinet_ids: tuple[str, ...] | None = None  # restrict to these cabinets
    target_types: tuple[str, ...] = ("drawer", "door")
    obs_mode: str = "state"
    privileged: bool = False
    instruction: str = "onehot"  # "onehot" (14 numbers) | "text" (gymnasium Text)
    control: str = "delta"
    reward_mode: str = "dense"
    image_size: int = 256
    time_limit: float = 15.0  # s of simulated time (900 control steps at 60 Hz)
    physics_timestep: float | None = None  # None: TaskConfig's (1/480 s)
    success_threshold: float = 0.2  # the paper's: open ratio above it
    #: ManiSkill3's criterion instead: success when the target opened at least this fraction of its
    #: joint range (ManiSkill3 uses 0.75); None: the paper's open ratio above `success_threshold`
    range_success: float | None = None
    terminate_on_success: bool = True
    room_variants: int = 8  # appearance seeds per room
    start_noise: float = 0.05  # m, per axis, around the benchmark's hand start
    start_yaw_noise: float = 0.15  # rad
    max_scenes: int = 4  # compiled scenes kept for reuse
    #: False: the reference step (`sim.reference.ReferenceStep`: the episode's dm_env step, every
    #: observation read on its own), which the default step is tested against, bit for bit; slower
    lean_step: bool = True
    #: with the lean step: the whole control step in one compiled call where `opend_mj.sim.fast`
    #: loads (the same numbers as the lean Python step, which runs with False)
    compiled_step: bool = True
    dense: DenseRewardConfig = field(default_factory=DenseRewardConfig)

    def __post_init__(self):
        checks = {"obs_mode": OBS_MODES, "control": CONTROLS, "instruction": INSTRUCTION_MODES,
                  "reward_mode": REWARD_MODES, "split": ("train", "test", "all")}
        for name, allowed in checks.items():
            if getattr(self, name) not in allowed:
                raise ValueError(f"{name} must be one of {allowed}, not {getattr(self, name)!r}")
        if not set(self.target_types) <= {"drawer", "door"} or not self.target_types:
            raise ValueError(f"target_types must name drawer and/or door, not {self.target_types!r}")
        if self.range_success is not None and not 0.0 < self.range_success <= 1.0:
            raise ValueError(f"range_success must be a fraction of the joint range in (0, 1], not {self.range_success}")
        if self.room_variants < 1 or self.max_scenes < 1 or self.image_size < 16:
            raise ValueError("room_variants and max_scenes must be >= 1 and image_size >= 16")

    def task_config(self) -> TaskConfig:
        config = TaskConfig(enable_rgbd=False, image_size=self.image_size, time_limit=self.time_limit,
                            success_threshold=self.success_threshold,
                            compiled_step=self.compiled_step and self.lean_step)
        if self.physics_timestep is not None:
            config = replace(config, physics_timestep=float(self.physics_timestep))
        return config


@dataclass(frozen=True)
class SampledEpisode:
    """One episode of an environment over the dataset (all drawn from ``seed``)."""

    seed: int
    cabinet: str
    cabinet_dir: str
    joint: str
    target_type: str
    instruction: str
    split: str
    room: int
    scene_seed: int
    start_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    start_yaw: float = 0.0

    @property
    def scene_key(self) -> tuple:
        return (self.cabinet_dir, self.room, self.scene_seed)


class EpisodeSampler:
    """(cabinet, target) pairs of a split of a compiled dataset, and episodes drawn from a seed."""

    def __init__(self, config: EnvConfig):
        self.config = config
        root = Path(config.cabinets)
        manifest = load_manifest(root)
        ids = set(config.cabinet_ids) if config.cabinet_ids is not None else None
        self.pairs: list[tuple[dict, dict, str]] = []
        for cab, tgt in manifest.targets(config.split):
            if ids is not None and cab["id"] not in ids:
                continue
            if tgt.get("type") not in config.target_types:
                continue
            cab_dir = root / cab.get("path", cab["id"])
            if not (cab_dir / CABINET_JSON).is_file():
                cab_dir = root / cab["id"]
            self.pairs.append((cab, tgt, str(cab_dir)))
        if not self.pairs:
            raise ValueError(f"no {'/'.join(config.target_types)} targets in split {config.split!r} of {root}"
                             + (f" among cabinets {sorted(ids)}" if ids is not None else ""))

    def sample(self, seed: int) -> SampledEpisode:
        c = self.config
        rng = np.random.default_rng([int(seed), 16])
        cab, tgt, cab_dir = self.pairs[int(rng.integers(len(self.pairs)))]
        room = int(rng.integers(len(ROOM_NAMES)))
        scene_seed = int(rng.integers(c.room_variants))
        offset = rng.uniform(-c.start_noise, c.start_noise, 3) if c.start_noise > 0 else np.zeros(3)
        yaw = float(rng.uniform(-c.start_yaw_noise, c.start_yaw_noise)) if c.start_yaw_noise > 0 else 0.0
        return SampledEpisode(seed=int(seed), cabinet=cab["id"], cabinet_dir=cab_dir, joint=tgt["joint"],
                              target_type=tgt["type"], instruction=tgt["instruction"], split=cab["split"],
                              room=room, scene_seed=scene_seed, start_offset=tuple(float(x) for x in offset),
                              start_yaw=yaw)

    def fixed(self, seed: int, options: dict) -> SampledEpisode:
        """The sampled episode with the fields ``options`` names replaced (cabinet, target, room, ...)."""
        episode = self.sample(seed)
        if "cabinet" in options or "target" in options:
            cabinet, joint = options.get("cabinet", episode.cabinet), options.get("target")
            match = [(c, t, d) for c, t, d in self.pairs if c["id"] == cabinet and joint in (None, t["joint"])]
            if not match:
                raise ValueError(f"no target {options.get('target', '(any)')!r} of cabinet {cabinet!r} in this "
                                 f"environment's split and target types")
            cab, tgt, cab_dir = match[0]
            episode = replace(episode, cabinet=cab["id"], cabinet_dir=cab_dir, joint=tgt["joint"],
                              target_type=tgt["type"], instruction=tgt["instruction"], split=cab["split"])
        changes = {k: options[k] for k in ("room", "scene_seed", "start_yaw") if k in options}
        if "start_offset" in options:
            changes["start_offset"] = tuple(float(x) for x in options["start_offset"])
        return replace(episode, **changes)


class StartPoseTask(OpenCabinetTask):
    """The benchmark task with the hand's start shifted (position offset, yaw about z) at reset."""

    start_offset = (0.0, 0.0, 0.0)
    start_yaw = 0.0

    def initial_root_pose(self, physics):
        pos, quat = super().initial_root_pose(physics)
        if any(self.start_offset):
            pos = pos + np.asarray(self.start_offset, float)
        if self.start_yaw:
            quat = turn_about_z(quat, self.start_yaw)
        return pos, quat


class OpenDCore:
    """The engine of the environments over the dataset: sampling, scenes, observations, rewards.

    The step is one compiled call (`sim.fast.binding.EnvStep`) where the compiled step loads, else
    the Python step with the same numbers: the task's own action handling and its tight substep loop
    (no composer hooks, no observation buffers), only body, geom and site poses brought up to date
    when nothing renders, and every float observation written into one preallocated vector through
    indices bound once per scene (`SceneReader.fill`); the observation dict holds views into one
    copy of that vector in the dtype asked for. ``lean_step=False`` runs the reference step instead
    (`sim.reference.ReferenceStep`), which tests compare the step with, to the bit.
    """

    def __init__(self, config: EnvConfig):
        self.config = config
        self.sampler = EpisodeSampler(config)
        self.task_config = config.task_config()
        self.adapter = ActionAdapter(config.hand, self.task_config)
        self.spec = self.adapter.spec
        self._scenes: collections.OrderedDict[tuple, SceneReader] = collections.OrderedDict()
        self.scene: SceneReader | None = None
        self.episode: SampledEpisode | None = None
        self._needs_reset = True
        self.steps = 0
        self.scenes_built = 0
        layout = self.observation_layout()
        self._float_keys: list[tuple[str, slice, tuple[int, ...]]] = []
        offset = 0
        for key, (shape, kind) in layout.items():
            if kind == "float" and key != "depth":
                size = int(np.prod(shape, dtype=int))
                self._float_keys.append((key, slice(offset, offset + size), shape))
                offset += size
        self._slices = {key: sl for key, sl, _ in self._float_keys}
        # the float vector's keys, then the text instruction and the images (not in the vector)
        self.set_observation_order([key for key, _, _ in self._float_keys]
                                   + [k for k, (_, kind) in layout.items() if kind != "float" or k == "depth"])
        #: every float observation but depth, float64, at the offsets of `_slices`
        self._flat = np.zeros(offset)
        self._rgb = config.obs_mode in ("rgb", "rgbd")
        self._depth = config.obs_mode in ("depth", "rgbd")
        self._rgbd = config.obs_mode != "state"  # the step brings cameras up to date for rendering
        self._delta = config.control == "delta"
        #: the compiled step of the current episode (`sim.fast.binding.EnvStep`), or None
        self._fast = None
        #: with ``lean_step=False``: the reference step (`sim.reference.ReferenceStep`)
        self._reference = None
        if not config.lean_step:
            from opend_mj.sim.reference import ReferenceStep

            self._reference = ReferenceStep(self)

    def set_observation_order(self, keys) -> None:
        """The key order of the observation dicts `observe` returns (e.g. the gymnasium space's).

        Keys of the float vector become views of one copy of it (reshaped only where they are not
        flat); images and the text instruction follow in this order.
        """
        self._order = tuple(keys)
        floats = {key: (sl, shape) for key, sl, shape in self._float_keys}
        self._float_plan = [(key, *floats[key]) if len(floats[key][1]) != 1 else (key, floats[key][0], None)
                            for key in self._order if key in floats]
        #: every float key is a flat slice: (key, slice) pairs, no reshapes
        self._flat_plan = ([(key, sl) for key, sl, _ in self._float_plan]
                           if all(shape is None for _, _, shape in self._float_plan) else None)
        #: every key is a float of the vector (state mode, one-hot instruction): the views alone
        self._floats_only = len(self._float_plan) == len(self._order)

    @property
    def control_dt(self) -> float:
        return 1.0 / self.task_config.control_hz

    @property
    def flat_size(self) -> int:
        """Length of the float observation vector (`flat_layout`)."""
        return len(self._flat)

    def flat_layout(self) -> list[tuple[str, slice, tuple[int, ...]]]:
        """(key, slice of the float vector, shape) of every float observation but depth."""
        return list(self._float_keys)

    # ------------------------------------------------------------------ scenes
    def _scene(self, episode: SampledEpisode) -> SceneReader:
        key = episode.scene_key
        scene = self._scenes.get(key)
        if scene is not None:
            self._scenes.move_to_end(key)
            return scene
        while len(self._scenes) >= self.config.max_scenes:
            _, old = self._scenes.popitem(last=False)
            old.close()
            old.env.close()
        spec = EpisodeSpec(cabinet_dir=Path(episode.cabinet_dir), target_joint=episode.joint,
                           hand=self.config.hand, seed=episode.scene_seed, room=episode.room)
        task = StartPoseTask(spec, self.task_config)
        env = OpenDEnvironment(task, time_limit=self.task_config.time_limit, random_state=episode.scene_seed,
                               strip_singleton_obs_buffer_dim=True, raise_exception_on_physics_error=False)
        scene = SceneReader(env, self.config.image_size)
        scene.bind_layout(self._slices)
        self._scenes[key] = scene
        self.scenes_built += 1
        return scene

    # ------------------------------------------------------------------ episode
    def reset(self, seed: int, options: dict | None = None, dtype=np.float64) -> tuple[dict, dict]:
        episode = self.sampler.fixed(seed, options) if options else self.sampler.sample(seed)
        scene = self._scene(episode)
        task = scene.task
        if task.target.joint != episode.joint or task.episode.instruction is not None:
            task.set_target(episode.joint)
        task.start_offset, task.start_yaw = episode.start_offset, episode.start_yaw
        scene.env.reset()
        scene.probe.start()
        self._fast = None
        if task._fast is not None:
            from opend_mj.sim.fast.binding import EnvStep
            if EnvStep.supports(scene):
                self._fast = EnvStep(task._fast, scene, self._flat, self.adapter, self._delta, self._rgbd,
                                     self.config.privileged)
        self.scene, self.episode = scene, episode
        self._needs_reset = False
        self.steps = 0
        flat, sl = self._flat, self._slices
        flat[:] = 0.0
        if self.config.instruction == "onehot":
            flat[sl["instruction"]] = instruction_onehot(episode.instruction)
        if self.config.obs_mode != "state":
            for key, value in scene.camera_arrays().items():
                flat[sl[key]] = value.ravel()
        reference = self._reference
        terms = self._judge(reference.terms() if reference is not None else scene.fill(flat, self.config.privileged))
        dense_reward(terms, self.config.success_threshold, self.config.dense)  # fills reach / open / others
        return self.observe(dtype), self._info(terms)

    def native_action(self, action) -> np.ndarray:
        """The task's own action for ``action`` in this environment's control mode."""
        if self.config.control == "absolute":
            return np.asarray(action, dtype=np.float64)
        return self.adapter.from_delta(action, *self.scene.task.mocap_views)

    def step(self, action, dtype=np.float64, observe: bool = True) -> tuple[dict | None, float, bool, bool, dict]:
        """One control step: (observation, reward, terminated, truncated, info); float observations
        in ``dtype`` (rgb stays uint8, depth float32). ``observe=False`` returns None for the
        observation: the caller reads the float vector (`flat`) and `images` itself."""
        if self._needs_reset:
            raise RuntimeError("the episode is over (or never started): call reset() first")
        scene = self.scene
        task = scene.task
        c = self.config
        fast = self._fast
        status = fast.step(action) if fast is not None else None
        if status is not None:  # the compiled step ran (and filled the vector and the terms)
            if status & (WARNING_BITS | NAN):
                warnings = warning_names(status & WARNING_BITS) or ["NaN"]
                task.physics_warnings.append({"time": float(scene._data.time), "warnings": warnings})
            last = bool(status & LAST)
            terms = fast.terms(status)
        elif self._reference is not None:
            last, terms = self._reference.step(action)
        else:  # the Python step: the same numbers as the compiled one
            if self._delta:  # the task's action in parts (`delta_parts` checks it as before_step does)
                task.apply_action(*self.adapter.delta_parts(action, *task.mocap_views))
            else:
                task.before_step(scene.physics, self.native_action(action), None)
            warnings = task.fast_substeps(scene.physics, cameras=self._rgbd)
            data = scene._data
            qpos = data.qpos
            if not warnings and not math.isfinite(float(qpos.dot(qpos))) and not np.isfinite(qpos).all():
                warnings = ["NaN"]
            if warnings:
                task.physics_warnings.append({"time": float(data.time), "warnings": warnings})
            last = bool(data.time >= self.task_config.time_limit)
            terms = scene.fill(self._flat, c.privileged)
        if c.range_success is not None:
            self._judge(terms)
        self.steps += 1
        warnings = task.physics_warnings
        if warnings:
            warnings = list(warnings)
            reward, terminated, truncated = 0.0, True, False
        else:
            reward = self._reward(terms)
            terminated = bool(terms.success and c.terminate_on_success)
            truncated = last and not terminated
        if terminated or truncated:
            self._needs_reset = True
        if c.reward_mode == "sparse":
            dense_reward(terms, c.success_threshold, c.dense)
        info = self._info(terms)
        if warnings:
            info["physics_warnings"] = warnings
        obs = self.observe(dtype) if observe else None
        return obs, reward, terminated, truncated, info

    def _judge(self, terms):
        """Success by this environment's criterion (the paper's is the probe's own)."""
        if self.config.range_success is not None:
            terms.success = bool(terms.range_ratio >= self.config.range_success)
        return terms

    def _reward(self, terms) -> float:
        if self.config.reward_mode == "sparse":
            return sparse_reward(terms)
        return dense_reward(terms, self.config.success_threshold, self.config.dense)

    def _info(self, terms) -> dict:
        ep = self.episode
        return {"success": bool(terms.success), "open_ratio": float(terms.open_ratio),
                "others_moved": bool(terms.others_moved), "instruction": ep.instruction, "cabinet": ep.cabinet,
                "target": ep.joint, "target_type": ep.target_type, "room": ep.room, "episode_seed": ep.seed,
                "sim_time": float(self.scene._data.time), "reward_terms": terms.to_dict()}

    def observe(self, dtype=np.float64) -> dict:
        """This environment's observation of the current state (after `reset` or `step`): float
        arrays in ``dtype``, rgb uint8, depth float32."""
        c = self.config
        if self._reference is not None:
            obs = self._reference.observe(dtype)
        else:  # views of one copy of the float vector, which the step filled
            flat = self._flat.astype(dtype)
            if self._flat_plan is not None:
                obs = {key: flat[sl] for key, sl in self._flat_plan}
            else:
                obs = {key: flat[sl] if shape is None else flat[sl].reshape(shape)
                       for key, sl, shape in self._float_plan}
            if self._floats_only:
                return obs
        if c.instruction == "text":
            obs["instruction"] = self.episode.instruction
        obs.update(self.images())
        return {key: obs[key] for key in self._order}

    @property
    def flat(self) -> np.ndarray:
        """The float observation vector of the current state (float64, `flat_layout`; lean step only:
        valid after `reset` and `step`). Read-only to callers."""
        return self._flat

    def images(self) -> dict[str, np.ndarray]:
        """What the observation mode renders, now: rgb (uint8 HxWx3) and/or depth (float32 HxW, m)."""
        mode, scene = self.config.obs_mode, self.scene
        if mode == "rgbd":
            rgb, depth = scene.render()
            return {"rgb": rgb, "depth": depth}
        if mode == "rgb":
            return {"rgb": scene.render_rgb()}
        if mode == "depth":
            return {"depth": scene.render_depth()}
        return {}

    def render(self) -> np.ndarray:
        return self.scene.render_rgb() if self.scene is not None else None

    def close(self) -> None:
        for scene in self._scenes.values():
            scene.close()
            scene.env.close()
        self._scenes.clear()
        self.scene = None

    # ------------------------------------------------------------------ spaces (as plain shapes)
    def observation_layout(self) -> dict[str, tuple[tuple[int, ...], str]]:
        """key -> (shape, kind): kind is "float", "uint8" or "text"."""
        n = self.adapter.n_fingers
        size = self.config.image_size
        layout = {"hand_qpos": ((n,), "float"), "hand_qvel": ((n,), "float"), "root_pos": ((3,), "float"),
                  "root_quat": ((4,), "float"), "root_vel": ((6,), "float"), "grasp_site_pos": ((3,), "float"),
                  "grasp_site_quat": ((4,), "float"), "mocap_pos": ((3,), "float"), "mocap_quat": ((4,), "float"),
                  "touch": ((len(touch_parts(self.spec)),), "float"), "time": ((1,), "float")}
        layout["instruction"] = ((), "text") if self.config.instruction == "text" else ((INSTRUCTION_DIM,), "float")
        if self.config.obs_mode in ("rgb", "rgbd"):
            layout["rgb"] = ((size, size, 3), "uint8")
        if self.config.obs_mode in ("depth", "rgbd"):
            layout["depth"] = ((size, size), "float")
        if self.config.obs_mode != "state":
            layout.update({"camera_K": ((3, 3), "float"), "camera_pose": ((4, 4), "float")})
        if self.config.privileged:
            layout.update({"handle_pos": ((3,), "float"), "handle_size": ((3,), "float"),
                           "open_ratio": ((1,), "float")})
        return layout

    def action_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        if self.config.control == "absolute":
            return self.adapter.absolute_bounds()
        return -np.ones(self.adapter.delta_dim), np.ones(self.adapter.delta_dim)

    def action_names(self) -> list[str]:
        fingers = list(self.spec.actuator_names)
        if self.config.control == "absolute":
            return ["root_x", "root_y", "root_z", "root_qw", "root_qx", "root_qy", "root_qz"] + fingers
        return ["d_root_x", "d_root_y", "d_root_z", "rot_x", "rot_y", "rot_z"] + fingers


def make_config(**kwargs) -> EnvConfig:
    """An `EnvConfig` from keyword arguments (lists become tuples; cabinets may be a Path)."""
    for key in ("cabinet_ids", "target_types"):
        if key in kwargs and kwargs[key] is not None and not isinstance(kwargs[key], tuple):
            value = kwargs[key]
            kwargs[key] = (value,) if isinstance(value, str) else tuple(value)
    if "cabinets" in kwargs:
        kwargs["cabinets"] = str(kwargs["cabinets"])
    return EnvConfig(**kwargs)


class OpenDDmEnv(dm_env.Environment):
    """The same environment through the dm_env API (for dm_control / Acme users).

    ``reset()`` starts the next episode of a seeded sequence (episode k uses a seed drawn from
    ``seed``); ``reset_with_seed(s)`` starts the episode of seed ``s`` (the gymnasium environment's
    ``reset(seed=s)``). Observations, actions, rewards and ``info`` (``env.info``) are the gymnasium
    environment's; the last step of an episode has discount 0 when it terminated (success or a
    physics failure) and 1 when the time ran out.
    """

    def __init__(self, seed: int = 0, **kwargs):
        self.core = OpenDCore(make_config(**kwargs))
        self._seeds = np.random.default_rng(seed)
        self._done = True
        self.info: dict = {}

    def reset(self) -> dm_env.TimeStep:
        return self.reset_with_seed(int(self._seeds.integers(2**31 - 1)))

    def reset_with_seed(self, seed: int, options: dict | None = None) -> dm_env.TimeStep:
        obs, self.info = self.core.reset(seed, options)
        self._done = False
        return dm_env.restart(obs)

    def step(self, action) -> dm_env.TimeStep:
        if self._done:
            return self.reset()
        obs, reward, terminated, truncated, self.info = self.core.step(action)
        if terminated:
            self._done = True
            return dm_env.termination(reward, obs)
        if truncated:
            self._done = True
            return dm_env.truncation(reward, obs)
        return dm_env.transition(reward, obs)

    def observation_spec(self):
        out = {}
        for key, (shape, kind) in self.core.observation_layout().items():
            if kind == "text":
                out[key] = specs.StringArray(shape=shape, name=key)
            else:
                out[key] = specs.Array(shape=shape, dtype=np.uint8 if kind == "uint8" else np.float64, name=key)
        return out

    def action_spec(self):
        low, high = self.core.action_bounds()
        return specs.BoundedArray(shape=low.shape, dtype=np.float64, minimum=low, maximum=high,
                                  name="\t".join(self.core.action_names()))

    def close(self) -> None:
        self.core.close()
