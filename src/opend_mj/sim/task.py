"""The OpenD task as a dm_control composer Task: room, cabinet, hand on a mocap weld, RGB-D camera.

One episode = one cabinet, one target (door or drawer) and its instruction, one hand, one seed. The
action is the hand root's target pose (position, quaternion w-x-y-z) and the finger joint targets.
The mocap body follows the root target at a bounded speed, interpolated over physics substeps, so
the root never teleports. The success checker reads the target joint: open ratio above the
threshold (20 % by default; drawer delta / drawer length, door angle / 180 degrees).
"""

from __future__ import annotations

import math
import os

os.environ.setdefault("MUJOCO_GL", "egl")

from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402

import mujoco  # noqa: E402
import numpy as np  # noqa: E402
from dm_control import composer  # noqa: E402
from dm_control.composer.observation import observable  # noqa: E402
from dm_env import specs  # noqa: E402

from opend_mj.sim.cabinet import Cabinet, Target  # noqa: E402
from opend_mj.sim.camera import camera_view, geom_box_corners, place_camera  # noqa: E402
from opend_mj.sim.hands import Hand, attach_with_mocap, orientation_for_handle  # noqa: E402
from opend_mj.sim.mocap_path import MocapPathPlanner  # noqa: E402
from opend_mj.sim.depth_sensor import fuse_depth  # noqa: E402
from opend_mj.sim.environment import (  # noqa: E402
    WARNING_IDS,
    WARNING_POSITIONS,
    WARNING_SLICE,
    OpenDEnvironment,
    warning_names,
)
from opend_mj.sim.perturb import DEFAULT_CONFIG, PerturbConfig, SceneShift  # noqa: E402
from opend_mj.sim.physics import PHYSICS  # noqa: E402
from opend_mj.sim.rooms import ROOM_NAMES, RoomArena  # noqa: E402
from opend_mj.sim.success import Outcome, SuccessChecker  # noqa: E402,F401  (Outcome: part of this module's API)


@dataclass(frozen=True)
class TaskConfig:
    """Everything about the task that is not the episode itself."""

    control_hz: float = 60.0
    #: Physics step (default 1/480 s: eight substeps per 60 Hz control step; see `sim.physics`).
    physics_timestep: float = PHYSICS.timestep
    time_limit: float = 15.0
    image_size: int = 256
    camera_fovy: float = 45.0
    #: Depth frames fused into the image the planner perceives the still scene from before it moves (a
    #: 30 Hz sensor's 8 frames: 0.27 s); its looks while the hand moves are one frame each
    depth_frames: int = 8
    camera_shift: tuple[float, float, float] = (0.0, 0.0, 0.0)
    light_scale: float = 1.0
    success_threshold: float = 0.2
    #: Another target "moved" if it opened by more than this fraction of its range.
    moved_threshold: float = 0.01
    max_root_speed: float = 0.75  # m/s
    max_root_angular_speed: float = 4.0  # rad/s
    #: Workspace box for root targets (world, metres) relative to the cabinet bounds.
    workspace_margin: float = 1.5
    enable_rgbd: bool = True
    #: True: the control step runs in compiled code (`opend_mj.sim.fast`) where it loads; the same
    #: numbers as the Python step, which runs otherwise (False, ``OPEND_FASTSTEP=0``, no compiler)
    compiled_step: bool = True
    #: A perturbation (`sim.perturb`: ``AXIS=LEVEL[,AXIS=LEVEL]``), drawn from the episode's seed; None: nominal
    perturb: str | None = None
    perturb_config: PerturbConfig = DEFAULT_CONFIG

    def __post_init__(self):
        if not (self.control_hz > 0 and self.physics_timestep > 0):
            raise ValueError(f"control_hz and physics_timestep must be positive, not {self.control_hz}, "
                             f"{self.physics_timestep}")
        substeps = 1.0 / self.control_hz / self.physics_timestep
        if substeps < 1 - 1e-6 or abs(substeps - round(substeps)) > 1e-6:
            raise ValueError(f"physics_timestep {self.physics_timestep:g} s must divide the control step "
                             f"1/{self.control_hz:g} s into a whole number of substeps (e.g. 1/480, 1/240, 1/120)")


@dataclass(frozen=True)
class EpisodeSpec:
    """One episode of the benchmark."""

    cabinet_dir: Path
    target_joint: str
    hand: str = "allegro"
    seed: int = 0
    room: int | None = None  # None: drawn from the seed
    instruction: str | None = None  # None: the target's instruction from cabinet.json

    def room_index(self) -> int:
        if self.room is not None:
            return int(self.room)
        return int(np.random.default_rng([self.seed, 9]).integers(len(ROOM_NAMES)))


class OpenCabinetTask(composer.Task):
    """Open the door or drawer that the instruction names. The task card:

    Randomised: the cabinet and target are the episode's (`EpisodeSpec`; the benchmark runs every
    target of a split, the environments draw one per reset). The room is one of nine
    (`EpisodeSpec.room`, else drawn from ``seed``); ``seed`` also draws its floor and wall
    materials, furniture and lights (`RoomArena`). Fixed: the cabinet (at the origin, front facing
    -x, every part closed at the start), the camera (in front of the cabinet, placed from its
    bounds, pitched 12 degrees down, ``camera_fovy`` 45 degrees, plus ``camera_shift`` m), the hand's
    start (between camera and cabinet, beside it and out of the camera's view, fingers open).
    ``light_scale`` scales every light (0.7: the paper's darker condition).

    Observed (observables): ``rgb`` (S x S x 3, uint8) and ``depth`` (S x S, planar metres) of the
    front camera, S = ``image_size`` (256 px; intrinsics and pose from `camera_view`); the
    ``instruction`` text; ``hand_joint_pos`` (finger joints, rad or m); ``root_pos`` (m, world) and
    ``root_quat`` (w, x, y, z) of the hand root; ``open_ratio`` (ground truth, for analysis: the
    benchmark never hands it to an agent).

    Action (`action_spec`, 7 + n floats): the root's target position (m, world, clipped to the
    cabinet's bounds +- ``workspace_margin``, 1.5 m), its target quaternion (w, x, y, z; normalised),
    n finger targets (the position actuators' units, clipped to their ranges). The mocap body moves
    toward the target at most ``max_root_speed`` (0.75 m/s) and ``max_root_angular_speed`` (4 rad/s),
    interpolated over the physics substeps, and the root follows it through a soft weld: nothing
    teleports. A non-finite action, a wrong shape or a zero quaternion raises.

    Success (`outcome`): the instructed target's open ratio above ``success_threshold`` (0.2;
    drawer travel / drawer length, door angle / 180 degrees). The outcome also gives the fraction of
    the joint's range (ManiSkill3's criterion: 0.75 or more) and the other targets that opened by
    more than ``moved_threshold`` (1 %) of their range. Reward: open ratio / threshold, at most 1.

    Time limit: ``time_limit``, 15 s of simulated time (900 control steps at ``control_hz`` 60 Hz;
    physics steps of 1/480 s, 8 per control step). The task ends no episode early; the environments
    end one on success, and `opend run` and the environments on a MuJoCo instability warning.
    """

    def __init__(self, episode: EpisodeSpec, config: TaskConfig = TaskConfig()):
        self.episode = episode
        self.config = config
        self._arena = RoomArena(room=episode.room_index(), seed=episode.seed, light_scale=config.light_scale)
        self.cabinet = Cabinet(Path(episode.cabinet_dir))
        self._arena.attach_cabinet(self.cabinet)
        self.target = self.cabinet.target(episode.target_joint)
        self.hand = Hand(episode.hand)
        self.mocap = attach_with_mocap(self._arena, self.hand)
        lo, hi = self.cabinet.bounds
        #: the perturbation's values for this scene (neutral without one)
        self.shift = SceneShift.draw(config.perturb, episode.seed, (lo, hi), config.perturb_config)
        self.instruction = self._instruction(episode.instruction)
        self.camera_pose, start = scene_geometry((lo, hi), config, self.shift)
        self.shift.check((lo, hi), self.camera_pose.pos, start, label=f"{self.cabinet.directory}")
        self.camera = self._arena.add_camera(self.camera_pose, name="front")
        self._handle_geoms = [g for t in self.cabinet.targets for g in t.handle_geoms]
        self.shift.apply_mjcf(self._arena, self.cabinet, self._handle_geoms)
        #: what turns each rendered depth image into the sensor's (None: the rendered one as it is)
        self.depth_sensor = self.shift.depth_sensor()
        self.checker = SuccessChecker(self.cabinet, self.target, config.success_threshold, config.moved_threshold)
        self._n_fingers = len(self.hand.actuators)
        self._workspace = (lo - config.workspace_margin, hi + config.workspace_margin)
        self._workspace_lists = tuple(np.asarray(b, float).tolist() for b in self._workspace)
        self._root_target = None
        self._path_pos = self._path_quat = None
        self._substep = 0
        self.start_pose = None
        self.set_timesteps(control_timestep=1.0 / config.control_hz, physics_timestep=config.physics_timestep)
        self._substeps = int(round(1.0 / config.control_hz / config.physics_timestep))
        #: the mocap's poses per substep, at bounded speed (m and rad per substep)
        self._planner = MocapPathPlanner(self._substeps, config.max_root_speed * config.physics_timestep,
                                         config.max_root_angular_speed * config.physics_timestep)
        #: Substeps of this control step whose mocap write changes the mocap pose: from there on the
        #: path's rows are all the same (the target is reached), so the rest run in one mj_step call.
        self._path_writes = 0
        #: the compiled step bound to this episode's physics (`sim.fast.binding.TaskStep`), or None
        self._fast = None
        #: the current control step's path was planned by `_fast` (else by `apply_action`)
        self._fast_planned = False
        self._action_shape = (7 + self._n_fingers,)
        self._add_observables()

    def set_target(self, joint: str, instruction: str | None = None) -> None:
        """Another target of the same cabinet (same scene, no recompile); applies from the next reset.

        ``instruction``: None for the target's own instruction (from cabinet.json).
        """
        import dataclasses

        self.target = self.cabinet.target(joint)
        self.episode = dataclasses.replace(self.episode, target_joint=joint, instruction=instruction)
        self.instruction = self._instruction(instruction)
        self.checker = SuccessChecker(self.cabinet, self.target, self.config.success_threshold,
                                      self.config.moved_threshold)
        self._index_cache = None

    def _instruction(self, given: str | None) -> str:
        """``given``, else the target's instruction as the instruction axis rewords it, else its own."""
        return given or self.shift.reword(self.target) or self.target.instruction

    # ------------------------------------------------------------------ composition
    @property
    def root_entity(self):
        return self._arena

    @property
    def arena(self) -> RoomArena:
        return self._arena

    def _index(self, physics) -> dict:
        """Indices into MjData of what the observables read, cached per compiled model."""
        cached = getattr(self, "_index_cache", None)
        if cached is None or cached[0] is not physics.model.ptr:
            ids = {"hand_qpos": np.array([int(physics.bind(j).qposadr) for j in self.hand.joints]),
                   "root": physics.model.name2id(self.hand.root_body.full_identifier, "body"),
                   "target_qpos": int(physics.bind(self.cabinet.joint_element(self.target.joint)).qposadr)}
            self._index_cache = cached = (physics.model.ptr, ids)
        return cached[1]

    def _cache_state(self, physics) -> None:
        """Raw MjData and the indices read on every control step (physics.bind on every step costs
        more than a physics substep). Refreshed after each compile and at each episode start."""
        ids = self._index(physics)
        self._data = physics.data.ptr
        self._hand_qpos, self._root_id, self._target_qpos = ids["hand_qpos"], ids["root"], ids["target_qpos"]

    def after_compile(self, physics, random_state):
        self.shift.apply_model(physics, self.cabinet, self._handle_geoms)
        self._cache_state(physics)

    def sense_depth(self, rgb: np.ndarray, depth: np.ndarray, frames: int = 1) -> np.ndarray:
        """The depth image solvers and agents receive for a render (the sensor's, under depth_noise);
        ``frames`` > 1: that many sensor frames of the still scene, fused (`depth_sensor.fuse_depth`)."""
        if self.depth_sensor is None:
            return depth
        return fuse_depth([self.depth_sensor(rgb, depth) for _ in range(max(1, frames))])

    def _add_observables(self) -> None:
        size = self.config.image_size
        obs = {}
        if self.config.enable_rgbd:
            obs["rgb"] = observable.MJCFCamera(self.camera, width=size, height=size)
            obs["depth"] = observable.MJCFCamera(self.camera, width=size, height=size, depth=True)
        obs["instruction"] = observable.Generic(lambda physics: np.array(self.instruction))
        obs["hand_joint_pos"] = observable.Generic(lambda physics: self._data.qpos[self._hand_qpos])
        obs["root_pos"] = observable.Generic(lambda physics: self._data.xpos[self._root_id].copy())
        obs["root_quat"] = observable.Generic(lambda physics: self._data.xquat[self._root_id].copy())
        obs["open_ratio"] = observable.Generic(lambda physics: np.array(self.open_ratio(physics)))
        for name, o in obs.items():
            o.enabled = True  # default schedule: computed once, at the last substep of a control step
            self._task_observables[name] = o

    @property
    def task_observables(self):
        return self._task_observables

    def __getattr__(self, name):  # composer.Task has no _task_observables until first use
        if name == "_task_observables":
            self._task_observables = {}
            return self._task_observables
        raise AttributeError(name)

    # ------------------------------------------------------------------ actions
    def action_spec(self, physics):
        ctrl = physics.bind(self.hand.actuators).ctrlrange
        lo, hi = self._workspace
        minimum = np.concatenate([lo, -np.ones(4), ctrl[:, 0]])
        maximum = np.concatenate([hi, np.ones(4), ctrl[:, 1]])
        names = ["root_x", "root_y", "root_z", "root_qw", "root_qx", "root_qy", "root_qz"] + [
            a.name for a in self.hand.actuators]
        return specs.BoundedArray(shape=minimum.shape, dtype=np.float64, minimum=minimum, maximum=maximum,
                                  name="\t".join(names))

    def make_action(self, root_pos, root_quat, fingers) -> np.ndarray:
        return np.concatenate([np.asarray(root_pos, float), np.asarray(root_quat, float), np.asarray(fingers, float)])

    def before_step(self, physics, action, random_state):
        action = np.asarray(action, dtype=float)
        if action.shape != self._action_shape:
            raise ValueError(f"action has shape {action.shape}, expected {self._action_shape}")
        # the fast test: a sum of finite numbers can only overflow, which the full test then clears
        if not math.isfinite(sum(action.tolist())) and not np.isfinite(action).all():
            raise ValueError(f"action has non-finite values: {action}")
        fast = self._fast
        if fast is not None:  # `apply_action` in compiled code
            fast.native[...] = action
            if fast.apply():
                raise ValueError("action quaternion has zero norm")
            target = fast.root_target.tolist()
            self._root_target = (tuple(target[:3]), np.array(target[3:]))
            self._substep = 0
            self._fast_planned = True
            return
        self.apply_action(action[:3].tolist(), action[3:7], action[7:])

    def apply_action(self, pos, quat: np.ndarray, fingers: np.ndarray) -> None:
        """`before_step` for an action already checked (finite, the right shape) and in parts: root
        target position (3 floats), quaternion (4-array, any norm above 1e-6) and finger targets
        (array; the actuators' units). Clips the root target to the workspace and the finger targets
        to the actuators' ranges, plans the mocap's path over the substeps, sets the controls."""
        norm = math.sqrt(float(quat.dot(quat)))  # quat @ quat (numpy's dot, without matmul's overhead)
        if norm < 1e-6:
            raise ValueError("action quaternion has zero norm")
        x, y, z = pos
        (lx, ly, lz), (hx, hy, hz) = self._workspace_lists
        if not (lx < x < hx and ly < y < hy and lz < z < hz):  # on or beyond a bound: numpy's clip
            lo, hi = self._workspace
            x, y, z = np.minimum(np.maximum(np.array(pos, float), lo), hi).tolist()
        target_quat = quat / norm
        self._root_target = ((x, y, z), target_quat)
        self._path_pos, self._path_quat, self._path_writes = self._planner.plan(
            *self.mocap_views, (x, y, z), target_quat)
        self._substep = 0
        self._fast_planned = False
        lo, hi = self._ctrl_range
        if self._ctrl_view is not None:
            np.minimum(np.maximum(fingers, lo, out=self._ctrl_buffer), hi, out=self._ctrl_view)
        else:
            self._data.ctrl[self._ctrl_index] = np.minimum(np.maximum(fingers, lo), hi)

    def before_substep(self, physics, action, random_state):
        i = self._substep
        self._substep += 1
        if self._fast_planned:
            self._fast.write_row(i)
            return
        if self._path_pos is not None:
            physics.data.mocap_pos[self._mocap_id] = self._path_pos[i]
        if self._path_quat is not None:
            physics.data.mocap_quat[self._mocap_id] = self._path_quat[i]

    def control_step(self, physics, action, cameras: bool = True) -> list[str]:
        """One control step: the action (`before_step`) and every substep (`fast_substeps`), in
        compiled code where it loads; the names of MuJoCo instability warnings it raised. What
        `environment.OpenDEnvironment.step` runs."""
        self.before_step(physics, action, None)
        return self.fast_substeps(physics, cameras)

    def fast_substeps(self, physics, cameras: bool = True) -> list[str]:
        """All substeps of one control step in a tight loop (`control_step`'s).

        Does exactly what `before_substep` + `physics.step()` do for each substep, without
        composer's per-substep Python hooks; once the mocap has reached its target pose (at once
        when it does not move) the remaining substeps are one ``mj_step(model, data, n)`` call.
        Afterwards the kinematics (bodies, sites, geoms, cameras, lights) are brought up to date
        with the new state, so that readers see where things are; this does not change the
        trajectory (each ``mj_step`` recomputes them first). With
        ``cameras=False`` only body, geom and site poses are brought up to date (``mj_kinematics``),
        not centre-of-mass quantities, cameras or lights: for readers that render nothing and read
        no camera (the state-only environments). Returns the names of MuJoCo instability warnings
        raised in this control step.
        """
        if self._fast_planned:  # planned by the compiled step: its substeps
            return warning_names(self._fast.substeps(cameras))
        model, data = self._model, self._data  # physics's, cached at the episode's start
        counts = self._warning_counts  # live view of the instability warnings' counters
        before = counts.tolist()
        path_pos, path_quat = self._path_pos, self._path_quat
        writes = self._path_writes if path_pos is not None or path_quat is not None else 0
        if writes:
            mocap_pos, mocap_quat = self.mocap_views
            step = mujoco.mj_step
            if path_pos is not None and path_quat is not None:  # moving and turning
                for i in range(writes):
                    mocap_pos[...] = path_pos[i]
                    mocap_quat[...] = path_quat[i]
                    step(model, data)
            else:
                rows, view = (path_pos, mocap_pos) if path_pos is not None else (path_quat, mocap_quat)
                for i in range(writes):
                    view[...] = rows[i]
                    step(model, data)
        if writes < self._substeps:  # the mocap pose no longer changes (mj_step leaves it alone): one call
            mujoco.mj_step(model, data, self._substeps - writes)
        mujoco.mj_kinematics(model, data)
        if cameras:
            mujoco.mj_comPos(model, data)
            mujoco.mj_camlight(model, data)
        after = counts.tolist()
        if after == before:  # the common case: no instability warning in this control step
            return []
        return [name for name, i in WARNING_POSITIONS if after[i] > before[i]]

    # ------------------------------------------------------------------ episode
    def initialize_episode(self, physics, random_state):
        self._cache_state(physics)
        if self.depth_sensor is not None:
            self.depth_sensor.count = 0  # each episode of a scene sees the same sensor draws
        self.cabinet.close_all(physics)
        pos, quat = self.initial_root_pose(physics)
        self.mocap.reset_pose(physics, pos, quat)
        self.hand.set_finger_qpos(physics, self.hand.spec.open_pose)
        self.hand.set_finger_targets(physics, self.hand.spec.open_pose)
        self._root_target = (pos, quat)
        self._path_pos = self._path_quat = None
        self._substep = 0
        self.physics_warnings: list[dict] = []
        self.start_pose = (pos.copy(), quat.copy())
        self._mocap_id = self.mocap.mocap_id(physics)
        self._ctrl_index = np.array([physics.model.name2id(a.full_identifier, "actuator")
                                     for a in self.hand.actuators])
        ranges = physics.model.actuator_ctrlrange[self._ctrl_index]
        self._ctrl_range = (ranges[:, 0], ranges[:, 1])
        # views of the rows every control step writes (this MjData's, refreshed at each episode)
        data, first = self._data, int(self._ctrl_index[0])
        contiguous = np.array_equal(self._ctrl_index, np.arange(first, first + len(self._ctrl_index)))
        self._ctrl_view = data.ctrl[first:first + len(self._ctrl_index)] if contiguous else None
        self._ctrl_buffer = np.zeros(len(self._ctrl_index))
        #: (mocap position, mocap quaternion): views of the mocap body's rows of MjData
        self.mocap_views = (data.mocap_pos[self._mocap_id], data.mocap_quat[self._mocap_id])
        self._model = physics.model.ptr
        #: a view of MjData's instability warning counters (`environment.WARNING_SLICE`)
        self._warning_counts = data.warning.number[WARNING_SLICE]
        self._fast, self._fast_planned = None, False
        if self.config.compiled_step:
            from opend_mj.sim.fast import ddot_pointer, library
            from opend_mj.sim.fast.binding import TaskStep

            lib = library()
            if lib is not None and TaskStep.supports(self):
                self._fast = TaskStep(lib, self, physics, ddot_pointer(), WARNING_IDS)

    def mocap_path(self) -> tuple[np.ndarray | None, np.ndarray | None, int]:
        """The mocap's path of the current control step: (position rows (n, 3) or None where the
        position does not move, quaternion rows (n, 4) or None where it does not turn, how many
        substeps change the pose), from whichever step planned it (compiled or Python)."""
        if self._fast_planned:
            return self._fast.path()
        pos = None if self._path_pos is None else np.array(self._path_pos, float)
        quat = None if self._path_quat is None else np.array(self._path_quat, float)
        return pos, quat, self._path_writes if pos is not None or quat is not None else 0

    def initial_root_pose(self, physics) -> tuple[np.ndarray, np.ndarray]:
        """Between camera and cabinet, beside the cabinet and out of the camera's view."""
        quat = orientation_for_handle("horizontal")
        view = camera_view(physics, self.camera.full_identifier, self.config.image_size, self.config.image_size)
        return (start_position(self.cabinet.bounds, view, self.config.image_size, self.shift.start_offset()),
                np.asarray(quat, float))

    def open_ratio(self, physics) -> float:
        """The instructed target's open ratio (what the success checker compares to the threshold)."""
        if physics.data.ptr is not self._data:  # not this task's current physics
            return self.target.open_ratio(float(physics.data.qpos[self._index(physics)["target_qpos"]]))
        return self.target.open_ratio(float(self._data.qpos[self._target_qpos]))

    def get_reward(self, physics) -> float:
        return float(min(1.0, self.open_ratio(physics) / self.config.success_threshold))

    def get_discount(self, physics) -> float:
        return 1.0

    def should_terminate_episode(self, physics) -> bool:
        return False

    # ------------------------------------------------------------------ for solvers and analysis
    def outcome(self, physics) -> Outcome:
        """The success checker's verdict on the current state."""
        return self.checker.check(physics)

    def camera_view(self, physics):
        """Intrinsics and pose of the front camera (what every handle solver may use)."""
        size = self.config.image_size
        return camera_view(physics, self.camera.full_identifier, size, size)

    def handle_corners(self, physics, target: Target | None = None) -> np.ndarray:
        """World corners of the (current) handle geoms of a target: ground truth for the oracle."""
        target = target or self.target
        names = [f"cabinet/{g}" for g in target.handle_geoms]
        return np.vstack([geom_box_corners(physics, n) for n in names])

    def handle_boxes(self, physics) -> dict[str, tuple[float, float, float, float] | None]:
        """Ground-truth image boxes (u0, v0, u1, v1) of every target's handle (oracle, training data)."""
        from opend_mj.sim.camera import box_in_image

        view = self.camera_view(physics)
        return {t.joint: box_in_image(self.handle_corners(physics, t), view) for t in self.cabinet.targets}


#: The hand root's start height (world z, m) stays within this range, whatever its offset.
START_HEIGHT = (0.25, 1.45)


def start_position(bounds, view, image_size: int, offset=(0.0, 0.0, 0.0)) -> np.ndarray:
    """The hand root's start (world, m): between camera and cabinet, beside the cabinet's +y side and
    out of the camera's view (``view``: a `sim.camera.CameraView`); ``offset`` (m; the hand_start
    perturbation's, `sim.perturb.HandStartAxis`) moves it back, out and up before it is pushed out
    of view."""
    lo, hi = (np.asarray(b, float) for b in bounds)
    dx, dy, dz = (float(v) for v in offset)
    x = lo[0] - 0.35 + dx
    z = float(np.clip((lo[2] + hi[2]) / 2, 0.3, 1.2))
    z = float(np.clip(z + dz, *START_HEIGHT)) if dz else z
    y = hi[1] + 0.25 + dy
    for _ in range(40):
        u, _v = view.project(np.array([[x, y, z]]))[0]
        if not np.isfinite(u) or u < -0.25 * image_size:
            break
        y += 0.05
    return np.array([x, y, z])


def scene_geometry(bounds, config: TaskConfig, shift: SceneShift):
    """(the front camera's pose, the hand's start position) of a scene, from the cabinet's bounds
    alone (no compile): what `SceneShift.check` needs before any episode runs."""
    from opend_mj.sim.camera import CameraIntrinsics, CameraView

    lo, hi = bounds
    pose = shift.move_camera(place_camera(lo, hi, fovy_deg=config.camera_fovy, shift=config.camera_shift))
    size = config.image_size
    view = CameraView(CameraIntrinsics.from_fovy(pose.fovy, size, size), np.asarray(pose.pos, float),
                      np.asarray(pose.rot, float))
    return pose, start_position(bounds, view, size, shift.start_offset())


def make_environment(episode: EpisodeSpec, config: TaskConfig = TaskConfig(), strip_singleton=True,
                     observations: bool = True):
    """A dm_control composer Environment for one episode (time limit from the config).

    ``observations=False``: ``step`` returns no observation (see `OpenDEnvironment`); ``reset``
    still does."""
    task = OpenCabinetTask(episode, config)
    return OpenDEnvironment(task, time_limit=config.time_limit, random_state=episode.seed,
                            strip_singleton_obs_buffer_dim=strip_singleton, raise_exception_on_physics_error=False,
                            observations=observations)
