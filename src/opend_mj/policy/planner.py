"""The OpenD planner: locate -> back-project -> approach -> close -> pull -> check.

Inputs the planner may use (nothing else): one RGB-D image of the front camera and its intrinsics
and pose (:class:`~opend_mj.sim.camera.CameraView`), the instruction, and the hand's own state (its
grasp-site and root pose, its finger joints). It never reads the cabinet's joints, the target's kind
or handle from ``cabinet.json``: door vs drawer comes from the instruction's last word, the handle
from the handle solver's box and the depth image. The hand root moves only through the task action
(a mocap target that follows at bounded speed); the fingers hold the handle by contact and friction.

Everything but the handle solver is deterministic.

Pull strategies:

* ``straight`` (the paper's): pull the grasp site straight back along -x (the approach axis).
* ``arc`` (default): a compliant pull that lets the handle lead. Each control step the target is
  placed a short ``lead`` ahead of where the grasp site actually is, along the direction the site
  has actually been moving (low-pass filtered; -x at first). A drawer moves straight so nothing
  changes; a door's handle moves on a circle, the observed direction turns with it, and the hand
  turns its palm with it (approach axis = minus the motion direction) so the grip does not twist.
  Drawers are always pulled straight along -x (the drawer axis).
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Callable

import numpy as np

from opend_mj.language import hinge_side, target_kind
from opend_mj.policy.handle import HandleSolver
from opend_mj.policy.perception import (
    estimate_handle,
    infer_hinge_side,
    refine_box_with_depth,
)
from opend_mj.sim.hands import (
    HANDS_DIR,
    HandSpec,
    grasp_pose_to_root_pose,
    orientation_for_handle,
)
from opend_mj.transforms import (
    mat_to_quat,
    quat_axis_z,
    quat_mul,
    turn_about_z,
    yaw_quat,
)

GRASP_FILE = "grasp.json"
STAGES = ("locate", "approach", "grasp", "pull")


# --------------------------------------------------------------------------------------------------
# Configuration
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PlannerConfig:
    pull: str = "arc"  # "straight" | "arc" (doors; drawers always go straight)
    #: site distance (m) in front of the handle before moving in
    pregrasp_distance: float = 0.10
    #: free-space moves (m/s) and the final approach (m/s)
    move_speed: float = 0.6
    approach_speed: float = 0.15
    #: grasp depth (m) beyond the handle's estimated centre along the approach axis, per handle kind
    grasp_depth: dict = field(default_factory=lambda: {"bar": 0.0, "knob": 0.0})
    #: finger closing: fraction of the grasp profile (1 = the spec's profile), seconds to close
    close_scale: float = 1.0
    close_time: float | None = None  # None: the hand spec's
    settle_time: float = 0.3
    #: pull: speed (m/s), lead of the target ahead of the site (m), maximum travel (m)
    pull_speed: float = 0.15
    lead: float = 0.04
    drawer_travel: float = 0.45
    door_travel: float = 0.9
    #: door: stop turning once the motion direction turned by this much (deg)
    door_max_turn: float = 110.0
    #: stop pulling when the site moved less than ``stall_distance`` in ``stall_time`` seconds
    stall_time: float = 0.6
    stall_distance: float = 0.008
    #: direction low-pass: weight of the new observation per control step, and the minimum motion
    #: (m) over the window before a direction is believed
    direction_window: int = 6
    direction_min_motion: float = 0.004
    direction_gain: float = 0.35
    #: door: the hand's yaw = gain * (turn of the motion direction) + lead (deg, in the turn's sense);
    #: a hand that lags the door presses its fingertips into the panel on one side
    yaw_gain: float = 1.0
    yaw_lead_deg: float = 0.0
    #: door: pull this many degrees beyond the observed motion direction, in the sense of the turn
    pull_bias_deg: float = 0.0
    #: open the fingers at the end and back off
    release: bool = False
    #: doors named "right" in the instruction: dexterous fingers point to -y (toward the hinge)
    flip_right_doors: bool = True
    #: single doors (no side in the instruction): infer the hinge side from the depth image
    infer_hinge: bool = True
    #: per hand type: the grip is lost when a finger joint moved this much (m) from where it closed on
    #: the handle, and the pull stops there. Only parallel grippers: a dexterous hand's fingers move
    #: while they hold (a 0.6 rad check cut Allegro's train-split doors from 111 to 45 of 153).
    grip_lost_change: dict = field(default_factory=lambda: {"parallel_gripper": 0.012})
    #: snap a learned solver's box to the handle that stands out of the panel in the depth image
    #: (not the oracle's exact boxes: refining them lost 1-6 points on the test split)
    refine_with_depth: bool = True
    #: a door's pull direction may point back toward the cabinet (+x) at most this much (sin of angle)
    max_pull_toward_cabinet: float = 0.35
    #: an episode lasts at least this long (s of simulated time)
    min_time: float = 5.0
    #: handles whose image box aspect (long / short) is below this, and which are small, are knobs
    knob_aspect: float = 1.6
    knob_size: float = 0.055
    #: horizontal handles lower than this (m) are grasped with the fingers pointing down
    flip_below: float = 0.2
    #: handle radius assumed when turning the front surface seen in depth into a centre (m)
    handle_radius: float = 0.007

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class GraspProfile:
    """A hand's grasp tuning (``hands/<name>/grasp.json``, written by ``opend search-grasp``)."""

    hand: str
    close_scale: float = 1.0
    grasp_depth: dict = field(default_factory=lambda: {"bar": 0.0, "knob": 0.0})
    knob_orientation: str = "horizontal"
    search: list = field(default_factory=list)

    @classmethod
    def path_for(cls, hand: str, hands_dir: Path | None = None) -> Path:
        return Path(hands_dir or HANDS_DIR) / hand / GRASP_FILE

    @classmethod
    def load(cls, hand: str, hands_dir: Path | None = None) -> "GraspProfile | None":
        path = cls.path_for(hand, hands_dir)
        if not path.is_file():
            return None
        data = json.loads(path.read_text())
        names = set(cls.__dataclass_fields__)
        return cls(**{k: v for k, v in data.items() if k in names})

    def save(self, hands_dir: Path | None = None) -> Path:
        path = self.path_for(self.hand, hands_dir)
        path.write_text(json.dumps(asdict(self), indent=2) + "\n")
        return path

    def apply(self, config: PlannerConfig) -> PlannerConfig:
        return replace(config, close_scale=self.close_scale, grasp_depth=dict(self.grasp_depth))


# --------------------------------------------------------------------------------------------------
# What the planner sees and drives
# --------------------------------------------------------------------------------------------------
@dataclass
class Observation:
    rgb: np.ndarray
    depth: np.ndarray
    instruction: str
    camera_view: object  # CameraView


class Robot:
    """The planner's handle on an environment: the task action and the hand's own state only."""

    def __init__(self, env, on_step: Callable[[], None] | None = None):
        self.env = env
        self.physics = env.physics
        self.task = env.task
        self.spec: HandSpec = env.task.hand.spec
        self.on_step = on_step
        self.n_steps = 0
        # Indices read on every control step (physics.bind costs more than a physics substep).
        self._data = self.physics.data.ptr
        self._site_id = int(self.physics.bind(self.task.hand.grasp_site).element_id)
        self._finger_qpos = np.array([int(a) for a in self.physics.bind(self.task.hand.joints).qposadr])

    @property
    def control_dt(self) -> float:
        return self.task.control_timestep

    @property
    def time(self) -> float:
        return float(self._data.time)

    def site_pose(self) -> tuple[np.ndarray, np.ndarray]:
        d = self._data
        return d.site_xpos[self._site_id].copy(), mat_to_quat(d.site_xmat[self._site_id].reshape(3, 3))

    def site_pos(self) -> np.ndarray:
        """Where the grasp site is (the position of `site_pose`, without the orientation)."""
        return self._data.site_xpos[self._site_id].copy()

    def finger_qpos(self) -> np.ndarray:
        return self._data.qpos[self._finger_qpos]

    def step(self, site_pos, site_quat, fingers) -> None:
        """One control step toward a grasp-site target pose (converted to the root target)."""
        root_pos, root_quat = grasp_pose_to_root_pose(self.spec, site_pos, site_quat)
        self.env.step(self.task.make_action(root_pos, root_quat, fingers))
        self.n_steps += 1
        if self.on_step is not None:
            self.on_step()


# --------------------------------------------------------------------------------------------------
# The planner
# --------------------------------------------------------------------------------------------------
@dataclass
class PlanResult:
    """What the planner did and believes (no ground truth in here)."""

    stage_reached: str  # last stage started
    failed_stage: str | None  # the planner's own verdict (None: it believes it succeeded)
    box: dict | None = None
    handle: dict | None = None
    target_kind: str = ""
    pulled: float = 0.0  # how far the grasp site travelled while pulling (m)
    turned_deg: float = 0.0  # how much the pull direction turned (doors)
    events: list = field(default_factory=list)

    def to_dict(self) -> dict:
        return asdict(self)


class Planner:
    """Deterministic open-the-handle controller around a handle solver."""

    def __init__(self, solver: HandleSolver, spec: HandSpec, config: PlannerConfig = PlannerConfig(),
                 grasp: GraspProfile | None = None, on_stage: Callable[[str, dict], None] | None = None):
        self.solver = solver
        self.spec = spec
        self.grasp = grasp
        self.config = grasp.apply(config) if grasp is not None else config
        self.on_stage = on_stage

    # ---------------------------------------------------------------- helpers
    def _stage(self, result: PlanResult, name: str, **info) -> None:
        result.stage_reached = name
        result.events.append({"stage": name, **{k: v for k, v in info.items() if not isinstance(v, np.ndarray)}})
        if self.on_stage is not None:
            self.on_stage(name, info)

    def _move(self, robot: Robot, start, goal, quat, fingers, speed: float) -> None:
        """Straight-line move of the site target at ``speed`` (the mocap limit also applies)."""
        start, goal = np.asarray(start, float), np.asarray(goal, float)
        dist = float(np.linalg.norm(goal - start))
        n = max(1, int(math.ceil(dist / (speed * robot.control_dt))))
        for i in range(1, n + 1):
            robot.step(start + (goal - start) * i / n, quat, fingers)

    def _hold(self, robot: Robot, pos, quat, fingers, seconds: float) -> None:
        for _ in range(max(0, int(round(seconds / robot.control_dt)))):
            robot.step(pos, quat, fingers)

    def closed_profile(self, orientation: str) -> np.ndarray:
        pre = self.spec.pregrasp_profile(orientation)
        closed = self.spec.grasp_profile(orientation)
        return pre + self.config.close_scale * (closed - pre)

    # ---------------------------------------------------------------- stages
    def run(self, robot: Robot, obs: Observation) -> PlanResult:
        cfg = self.config
        result = PlanResult(stage_reached="locate", failed_stage=None)
        result.target_kind = target_kind(obs.instruction)

        # -- locate
        self._stage(result, "locate")
        box = self.solver.solve(obs.rgb, obs.depth, obs.instruction, obs.camera_view)
        if box is not None and cfg.refine_with_depth and not getattr(self.solver, "exact", False):
            result.events.append({"solver_box": box.to_dict()})
            box = refine_box_with_depth(box, obs.depth, obs.camera_view)
        result.box = box.to_dict() if box is not None else None
        handle = estimate_handle(box, obs.depth, obs.camera_view, cfg) if box is not None else None
        if handle is None:
            result.failed_stage = "locate"
            self._hold_until_min_time(robot, None)
            return result
        result.handle = handle.to_dict()

        # -- approach
        orientation = handle.orientation
        if handle.kind == "knob" and self.grasp is not None:
            orientation = self.grasp.knob_orientation
        elif handle.kind == "knob":
            orientation = "horizontal"
        quat = orientation_for_handle(orientation)
        if orientation == "horizontal" and handle.centre[2] < cfg.flip_below:
            quat = quat_mul(quat, yaw_quat(math.pi))  # fingers down (site frame: rotate about +z)
        if result.target_kind == "door" and cfg.flip_right_doors and self.spec.hand_type != "parallel_gripper":
            # Fingers point toward the hinge, so that the door's pull presses the handle into the finger
            # curl. The side comes from the instruction where it names one (double doors), else from
            # the depth image (single doors: the handle sits near the free edge).
            hinge = hinge_side(obs.instruction)
            if hinge is None and cfg.infer_hinge:
                hinge = infer_hinge_side(handle, obs.depth, obs.camera_view)
            result.events.append({"hinge_side": hinge})
            if hinge == "right":
                quat = quat_mul(quat, yaw_quat(math.pi))
        depth = float(cfg.grasp_depth.get(handle.kind, 0.0)) + self.spec.approach_offset * 0.0
        grasp_pos = handle.centre + np.array([depth, 0.0, 0.0])
        pre_pos = grasp_pos - np.array([cfg.pregrasp_distance, 0.0, 0.0])
        pre_fingers = self.spec.pregrasp_profile(orientation)
        self._stage(result, "approach", site_target=grasp_pos.tolist())
        site0, _ = robot.site_pose()
        # rotate in place (open hand), then move at the start depth, then to the pre-grasp, then in
        self._hold(robot, site0, quat, pre_fingers, 0.3)
        waypoint = np.array([min(site0[0], pre_pos[0]), pre_pos[1], pre_pos[2]])
        self._move(robot, site0, waypoint, quat, pre_fingers, cfg.move_speed)
        self._move(robot, waypoint, pre_pos, quat, pre_fingers, cfg.move_speed)
        self._hold(robot, pre_pos, quat, pre_fingers, 0.15)
        self._move(robot, pre_pos, grasp_pos, quat, pre_fingers, cfg.approach_speed)
        self._hold(robot, grasp_pos, quat, pre_fingers, 0.15)
        site, _ = robot.site_pose()
        err = float(np.linalg.norm(site - grasp_pos))
        if err > 0.03:  # blocked on the way in (the hand's own state says so)
            result.events.append({"approach_error": round(err, 4)})

        # -- close fingers
        self._stage(result, "grasp")
        closed = self.closed_profile(orientation)
        close_time = cfg.close_time if cfg.close_time is not None else self.spec.close_time
        n = max(1, int(round(close_time / robot.control_dt)))
        for i in range(1, n + 1):
            robot.step(grasp_pos, quat, pre_fingers + (closed - pre_fingers) * i / n)
        self._hold(robot, grasp_pos, quat, closed, cfg.settle_time)

        # -- pull
        self._stage(result, "pull")
        door = result.target_kind == "door" and cfg.pull == "arc"
        self._pull(robot, quat, closed, door, result)

        # -- hold (and optionally release), then check
        site, squat = robot.site_pose()
        if cfg.release:
            self._hold(robot, site, squat, closed, 0.2)
            self._hold(robot, site, squat, pre_fingers, 0.4)
            direction = -quat_axis_z(squat)
            self._move(robot, site, site + 0.08 * direction, squat, pre_fingers, cfg.approach_speed)
        self._hold_until_min_time(robot, (robot.site_pose()[0], squat, closed if not cfg.release else pre_fingers))
        self._stage(result, "check", pulled=round(result.pulled, 4), turned_deg=round(result.turned_deg, 2))
        if result.pulled < 0.03:
            result.failed_stage = "grasp"
        return result

    def _hold_until_min_time(self, robot: Robot, pose) -> None:
        if pose is None:
            pos, quat = robot.site_pose()
            fingers = self.spec.open_pose
        else:
            pos, quat, fingers = pose
        while robot.time < self.config.min_time - 1e-9:
            robot.step(pos, quat, fingers)

    def _pull(self, robot: Robot, quat0, fingers, door: bool, result: PlanResult) -> None:
        cfg = self.config
        dt = robot.control_dt
        start, _ = robot.site_pose()
        direction = np.array([-1.0, 0.0, 0.0])
        base_dir = direction.copy()
        target = start.copy()
        history = [start.copy()]
        travelled = 0.0
        travel_max = cfg.door_travel if door else cfg.drawer_travel
        stall_n = max(2, int(round(cfg.stall_time / dt)))
        quat = quat0
        turned = 0.0
        max_steps = int(round((travel_max / cfg.pull_speed + 3.0) / dt))
        grip = robot.finger_qpos()  # the fingers as they closed on the handle
        grip_tolerance = cfg.grip_lost_change.get(self.spec.hand_type)
        for k in range(max_steps):
            site = robot.site_pos()
            if grip_tolerance is not None and float(np.max(np.abs(robot.finger_qpos() - grip))) > grip_tolerance:
                # the handle forced the fingers open: the grip is lost. Stop here rather than keep
                # moving a hand that no longer holds anything (it would push the door shut again).
                result.events.append({"grip_lost_at": round(travelled, 4)})
                break
            history.append(site.copy())
            if door and len(history) > cfg.direction_window:
                motion = history[-1] - history[-1 - cfg.direction_window]
                motion[2] = 0.0
                norm = float(np.linalg.norm(motion))
                if norm > cfg.direction_min_motion:
                    new = direction + cfg.direction_gain * (motion / norm - direction)
                    new[2] = 0.0
                    cand = new / np.linalg.norm(new)
                    if cand[0] > cfg.max_pull_toward_cabinet:  # never pull back into the cabinet
                        cand[0] = cfg.max_pull_toward_cabinet
                        lateral = math.sqrt(max(1e-9, 1 - cand[0] ** 2))
                        cand[1] = math.copysign(lateral, cand[1] if abs(cand[1]) > 1e-9 else 1.0)
                        cand = cand / np.linalg.norm(cand)
                    ang = math.degrees(math.atan2(base_dir[0] * cand[1] - base_dir[1] * cand[0],
                                                  float(base_dir @ cand)))
                    if abs(ang) <= cfg.door_max_turn:
                        direction = cand
                        turned = ang
                        yaw = cfg.yaw_gain * ang + math.copysign(min(abs(ang), cfg.yaw_lead_deg), ang)
                        quat = turn_about_z(quat0, math.radians(yaw))
            pull_dir = direction
            if door and abs(turned) > 1.0 and cfg.pull_bias_deg:
                b = math.radians(math.copysign(cfg.pull_bias_deg, turned))
                c, sn = math.cos(b), math.sin(b)
                pull_dir = np.array([c * direction[0] - sn * direction[1], sn * direction[0] + c * direction[1], 0.0])
            # advance the target along the direction, never more than `lead` ahead of the site
            target = target + pull_dir * cfg.pull_speed * dt
            ahead = float((target - site) @ pull_dir)
            if ahead > cfg.lead:
                target = target - pull_dir * (ahead - cfg.lead)
            # keep the target on the line through the site along the direction (no sideways pull)
            lateral = (target - site) - pull_dir * float((target - site) @ pull_dir)
            target = target - lateral
            robot.step(target, quat, fingers)
            travelled = float(np.linalg.norm(site - start)) if not door else travelled + float(
                np.linalg.norm(history[-1] - history[-2]))
            if travelled >= travel_max:
                break
            if k > stall_n and float(np.linalg.norm(history[-1] - history[-1 - stall_n])) < cfg.stall_distance:
                break
        result.pulled = travelled
        result.turned_deg = turned


__all__ = ["GRASP_FILE", "STAGES", "GraspProfile", "Observation", "PlanResult", "Planner",
           "PlannerConfig", "Robot"]
