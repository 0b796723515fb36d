"""The OpenD planner: locate -> back-project -> approach -> close -> pull -> check.

Inputs the planner may use (nothing else): one RGB-D image of the front camera and its intrinsics
and pose (:class:`~opend_mj.camera.CameraView`), the instruction, and the hand's own state (its
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

from opend_mj.hands import (HANDS_DIR, HandSpec, grasp_pose_to_root_pose, mat_to_quat, orientation_for_handle,
                            quat_mul)
from opend_mj.solvers import HandleBox, HandleSolver

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
# Perception helpers
# --------------------------------------------------------------------------------------------------
@dataclass
class HandleEstimate:
    centre: np.ndarray  # world, metres: the handle's grip centre
    orientation: str  # "horizontal" | "vertical"
    kind: str  # "bar" | "knob"
    size: tuple[float, float]  # world extent along y and z (m)
    front_x: float
    panel_x: float

    def to_dict(self) -> dict:
        return {"centre": [round(float(x), 4) for x in self.centre], "orientation": self.orientation,
                "kind": self.kind, "size": [round(float(x), 4) for x in self.size],
                "front_x": round(self.front_x, 4), "panel_x": round(self.panel_x, 4)}


def _ray_plane_x(view, u: float, v: float, x: float) -> np.ndarray:
    """World point where the camera ray through pixel (u, v) meets the plane of constant x."""
    p1 = view.backproject(u, v, 1.0)
    d = p1 - view.pos
    if abs(d[0]) < 1e-9:
        return p1
    t = (x - view.pos[0]) / d[0]
    return view.pos + t * d


def refine_box_with_depth(box: HandleBox, depth: np.ndarray, view, margin_px: int = 12,
                          min_protrusion: float = 0.015, max_protrusion: float = 0.08) -> HandleBox:
    """Snap a solver's box to the handle that stands out of the panel in the depth image.

    Handles stand 3-4.5 cm proud of their door or drawer front. Around the box (grown by `margin_px`)
    the panel is the most common depth; pixels at least `min_protrusion` nearer are handle. The
    connected group of such pixels nearest the box centre becomes the box. Where there is none the
    box is returned unchanged.
    """
    from scipy import ndimage

    h, w = depth.shape
    u0 = int(max(0, math.floor(box.u0) - margin_px))
    v0 = int(max(0, math.floor(box.v0) - margin_px))
    u1 = int(min(w, math.ceil(box.u1) + margin_px))
    v1 = int(min(h, math.ceil(box.v1) + margin_px))
    if u1 - u0 < 3 or v1 - v0 < 3:
        return box
    vv, uu = np.meshgrid(np.arange(v0, v1) + 0.5, np.arange(u0, u1) + 0.5, indexing="ij")
    d = depth[v0:v1, u0:u1]
    if not np.isfinite(d).any():
        return box
    x = view.backproject(uu.ravel(), vv.ravel(), d.ravel())[:, 0].reshape(d.shape)
    panel_x = float(np.nanmedian(x))
    proud = (x < panel_x - min_protrusion) & (x > panel_x - max_protrusion)
    labels, n = ndimage.label(proud)
    if n == 0:
        return box
    uc, vc = box.centre
    best, best_dist = 0, np.inf
    for k in range(1, n + 1):
        rows, cols = np.nonzero(labels == k)
        if len(rows) < 3:
            continue
        dist = float(np.min(np.hypot(cols + u0 + 0.5 - uc, rows + v0 + 0.5 - vc)))
        if dist < best_dist:
            best, best_dist = k, dist
    if best == 0:
        return box
    rows, cols = np.nonzero(labels == best)
    return HandleBox(u0 + cols.min(), v0 + rows.min(), u0 + cols.max() + 1, v0 + rows.max() + 1,
                     orientation=box.orientation)


def estimate_handle(box: HandleBox, depth: np.ndarray, view, config: PlannerConfig) -> HandleEstimate | None:
    """Back-project the solver's box with the depth image into a 3D handle centre and orientation."""
    h, w = depth.shape
    u0, v0 = int(max(0, math.floor(box.u0))), int(max(0, math.floor(box.v0)))
    u1, v1 = int(min(w, math.ceil(box.u1))), int(min(h, math.ceil(box.v1)))
    if u1 <= u0 or v1 <= v0:
        return None
    vv, uu = np.meshgrid(np.arange(v0, v1) + 0.5, np.arange(u0, u1) + 0.5, indexing="ij")
    d = depth[v0:v1, u0:u1]
    ok = np.isfinite(d) & (d > 0.05)
    if ok.sum() < 1:
        return None
    pts = view.backproject(uu[ok], vv[ok], d[ok])
    xs = pts[:, 0]
    front_x = float(np.percentile(xs, 3))
    panel_x = float(np.percentile(xs, 95))
    centre_x = front_x + config.handle_radius
    uc, vc = box.centre
    centre = _ray_plane_x(view, uc, vc, centre_x)
    # world extent of the box on the handle's plane
    c00 = _ray_plane_x(view, box.u0, box.v0, centre_x)
    c11 = _ray_plane_x(view, box.u1, box.v1, centre_x)
    size_y, size_z = abs(c00[1] - c11[1]), abs(c00[2] - c11[2])
    long_, short = max(size_y, size_z), max(min(size_y, size_z), 1e-4)
    if box.orientation in ("horizontal", "vertical"):
        orientation = box.orientation
    else:
        orientation = "horizontal" if size_y >= size_z else "vertical"
    kind = "knob" if (long_ / short < config.knob_aspect and long_ < config.knob_size) else "bar"
    return HandleEstimate(centre=centre, orientation=orientation, kind=kind, size=(size_y, size_z),
                          front_x=front_x, panel_x=panel_x)


def hinge_side_from_instruction(instruction: str) -> str | None:
    """'left' / 'right' where the instruction names a side (double doors always do), else None."""
    words = instruction.lower().split()
    sides = [w for w in words if w in ("left", "right")]
    return sides[-1] if sides and "second" not in words and "middle" not in words else None


def infer_hinge_side(handle: HandleEstimate, depth: np.ndarray, view, tolerance: float = 0.03,
                     gap_pixels: int = 3) -> str | None:
    """Which side a single door hinges on, from the depth image alone.

    Along the image row through the handle, walk left and right over pixels that lie on the door's
    front plane (within `tolerance` of the panel seen behind the handle) until the plane ends; a handle
    sits near the free edge, so the hinge is on the side where the plane reaches farther.
    """
    h, w = depth.shape
    uc, vc = view.project(handle.centre[None, :])[0]
    if not (np.isfinite(uc) and np.isfinite(vc)):
        return None
    row = int(np.clip(vc, 0, h - 1))
    cols = np.arange(w) + 0.5
    points = view.backproject(cols, np.full(w, row + 0.5), depth[row])
    on_plane = np.abs(points[:, 0] - handle.panel_x) < tolerance
    start = int(np.clip(uc, 0, w - 1))

    def reach(step: int) -> float:
        col, misses, last = start, 0, start
        while 0 <= col < w and misses <= gap_pixels:
            if on_plane[col]:
                last, misses = col, 0
            else:
                misses += 1
            col += step
        return abs(float(points[last, 1] - handle.centre[1]))

    toward_left, toward_right = reach(-1), reach(+1)  # image-left is +y (the viewer's left)
    if max(toward_left, toward_right) < 0.05 or abs(toward_left - toward_right) < 0.02:
        return None
    return "left" if toward_left > toward_right else "right"


def target_kind_from_instruction(instruction: str) -> str:
    """door or drawer, from the instruction's words (Algorithm 1 form or a paraphrase)."""
    from opend_mj.language import describe_instruction

    return describe_instruction(instruction).kind


def _rotz(angle: float) -> np.ndarray:
    return np.array([math.cos(angle / 2), 0.0, 0.0, math.sin(angle / 2)])


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
        result.target_kind = target_kind_from_instruction(obs.instruction)

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
            quat = quat_mul(quat, _rotz(math.pi))  # fingers down (site frame: rotate about +z)
        if result.target_kind == "door" and cfg.flip_right_doors and self.spec.hand_type != "parallel_gripper":
            # Fingers point toward the hinge, so that the door's pull presses the handle into the finger
            # curl. The side comes from the instruction where it names one (double doors), else from
            # the depth image (single doors: the handle sits near the free edge).
            hinge = hinge_side_from_instruction(obs.instruction)
            if hinge is None and cfg.infer_hinge:
                hinge = infer_hinge_side(handle, obs.depth, obs.camera_view)
            result.events.append({"hinge_side": hinge})
            if hinge == "right":
                quat = quat_mul(quat, _rotz(math.pi))
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
            direction = -quat_to_axis_z(squat)
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
                        quat = orientation_for_handle_quat(quat0, math.radians(yaw))
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


def quat_to_axis_z(q) -> np.ndarray:
    from opend_mj.hands import quat_to_mat

    return quat_to_mat(q)[:, 2]


def orientation_for_handle_quat(quat0, yaw: float) -> np.ndarray:
    """``quat0`` turned by ``yaw`` about the world z axis."""
    q = quat_mul(_rotz(yaw), quat0)
    return q / np.linalg.norm(q)


__all__ = ["GRASP_FILE", "STAGES", "GraspProfile", "HandleEstimate", "Observation", "PlanResult", "Planner",
           "PlannerConfig", "Robot", "estimate_handle", "target_kind_from_instruction"]


# --------------------------------------------------------------------------------------------------
# Grasp search (`opend search-grasp`)
# --------------------------------------------------------------------------------------------------
def search_grasp(hand: str, cabinets_dir: Path, n_cabinets: int = 3, scales=(0.8, 1.0, 1.15),
                 depths=(-0.01, 0.0, 0.008), workers: int = 1) -> GraspProfile:
    """Grid search of finger closing (fraction of the spec's grasp profile) and grasp depth on the
    handles of the first ``n_cabinets`` training cabinets, as the paper did: the first setting (in
    grid order, scale 1 / depth 0 first) with the most opened targets, ties broken by mean open
    ratio. Returns the chosen :class:`GraspProfile` (not saved)."""
    from opend_mj.dataset import load_manifest
    from opend_mj.evaluation import make_jobs, run_jobs
    import tempfile

    manifest = load_manifest(Path(cabinets_dir))
    ids = [c["id"] for c in manifest.cabinets if c["split"] == "train"][:n_cabinets]
    base = make_jobs(Path(cabinets_dir), [hand], "oracle", split="train", cabinet_ids=ids)
    grid = sorted(((s, d) for s in scales for d in depths), key=lambda sd: (abs(sd[0] - 1.0), abs(sd[1])))
    trials = []
    with tempfile.TemporaryDirectory() as tmp:
        for k, (s, d) in enumerate(grid):
            jobs = [replace(j, planner_overrides=(("close_scale", s), ("grasp_depth", {"bar": d, "knob": d})),
                            use_grasp_file=False, seed=k) for j in base]
            out = Path(tmp) / f"trial_{k}.jsonl"
            run_jobs(jobs, out, workers=workers, progress=False)
            from opend_mj.evaluation import load_results
            recs = load_results(out)
            n_ok = sum(bool(r.get("success")) for r in recs)
            mean = float(np.mean([r.get("open_ratio", 0.0) or 0.0 for r in recs])) if recs else 0.0
            trials.append({"close_scale": s, "grasp_depth": d, "success": n_ok, "episodes": len(recs),
                           "mean_open_ratio": round(mean, 4)})
    best = max(trials, key=lambda t: (t["success"], t["mean_open_ratio"]))
    return GraspProfile(hand=hand, close_scale=best["close_scale"],
                        grasp_depth={"bar": best["grasp_depth"], "knob": best["grasp_depth"]},
                        search=trials)
