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

from opend_mj.language import InstructionNotUnderstood, hinge_side, target_kind
from opend_mj.policy.handle import HandleSolver, centres_overlap
from opend_mj.policy.perception import (
    door_edges,
    estimate_handle,
    front_motion,
    infer_hinge_side,
    measure_handle,
    one_of_paired_handles,
    refine_box_with_depth,
    snaps_to_depth,
)
from opend_mj.sim.hands import (
    HANDS_DIR,
    HandSpec,
    HandTouch,
    grasp_pose_to_root_pose,
    orientation_for_handle,
)
from opend_mj.transforms import (
    axis_angle_quat,
    mat_to_quat,
    quat_axis_z,
    quat_mul,
    turn_about_z,
    yaw_quat,
)

GRASP_FILE = "grasp.json"
STAGES = ("locate", "approach", "grasp", "pull", "recover")


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
    #: door, without a hinge: once the pull direction turned at least ``door_turn_back_after``
    #: (deg), a direction that turns back by ``door_turn_back`` (deg) from the farthest turn is not
    #: taken (a door opens one way). At the door's stop the hand is pushed aside, and the direction,
    #: and the hand's yaw that follows it, swung round and dragged the door shut (45271's door at
    #: 91 degrees: the yaw went round 200 degrees, the door closed to 28). None: always taken.
    door_turn_back: float | None = 30.0
    door_turn_back_after: float = 30.0
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
    #: ... only vertical bars: the fingers round a horizontal bar point up (down where a neighbour
    #: closer than ``neighbour_clear`` (m) is above it and there is more room below)
    horizontal_doors_unflipped: bool = True
    neighbour_clear: float = 0.10
    #: single doors (no side in the instruction): infer the hinge side from the depth image
    infer_hinge: bool = True
    #: per hand type: the grip is lost when a finger joint moved this much (m) from where it closed on
    #: the handle, and the pull stops there. Only parallel grippers: a dexterous hand's fingers move
    #: while they hold (a 0.6 rad check cut Allegro's train-split doors from 111 to 45 of 153).
    grip_lost_change: dict = field(default_factory=lambda: {"parallel_gripper": 0.012})
    #: snap a learned solver's box to the handle that stands out of the panel in the depth image
    #: (not the oracle's exact boxes: refining them lost 1-6 points on the test split; nor a box
    #: that is a depth proposal already: snapping it again lost 3 of 382 real train-part episodes)
    refine_with_depth: bool = True
    #: a box over a pair of pulls (its centre bare panel, two handles in depth) -> the nearer pull
    one_of_paired_handles: bool = True
    #: a door's pull direction may point back toward the cabinet (+x) at most this much (sin of angle)
    max_pull_toward_cabinet: float = 0.35
    #: an episode lasts at least this long (s of simulated time)
    min_time: float = 5.0
    #: handles whose image box aspect (long / short) is below this, and which are small, are knobs
    knob_aspect: float = 1.6
    knob_size: float = 0.055
    #: horizontal handles lower than this (m) are grasped with the fingers pointing down
    flip_below: float = 0.2
    #: handles lower than ``low_handle_height`` (m; a bar or knob a few cm above the floor): the grasp
    #: site goes this much (m) above the handle's centre, per hand, so that the open fingers pointing
    #: down clear the floor on the way in and close over the bar from above (tuned on the real train
    #: part's 12 low handles: Shadow 4 -> 8 at 3 cm, Allegro 0 -> 5 at 6 cm; the Skeleton opens 8
    #: without; the gripper's 21 cm body meets the floor whatever the lift: it pitches instead)
    low_handle_height: float = 0.10
    low_handle_lift: dict = field(default_factory=lambda: {"shadow": 0.03, "allegro": 0.06})
    #: the lowest grasp site (m above the floor, per hand): the Skeleton's fingers, pointing down
    #: behind a bar, strike the floor below a site this low and the approach stalls 3-4 cm short
    #: (the real train part's handles 3.0-4.0 cm up, two door bars, a drawer bar and a knob: lost by
    #: every solver, opened by every one with the site at 5 cm; one bar 4.1 cm up, opened without,
    #: lost with it: the Skeleton is on an edge there, opened at 4.5 and 6 cm, lost at 5 and 5.5)
    min_grasp_height: dict = field(default_factory=lambda: {"skeleton": 0.05})
    #: low horizontal bars: the approach is pitched down by this much (deg, per hand), from above and
    #: in front, so that a body wide along the finger axis (the gripper's, 21 cm) clears the floor
    #: below and the door behind. Tuned on the real train part (Franka: 150 -> 152-155 of 191 at
    #: 35 deg; 20 deg: 152, 45: 151, 60-90: 152, the body then meets the door)
    low_handle_pitch: dict = field(default_factory=lambda: {"franka": 35.0})
    #: largest half-thickness of a bar: the grip centre is the front seen in depth plus the measured
    #: half thickness, at most this (m)
    handle_radius: float = 0.007
    #: grasp style: a bar whose stand-off gap (m) is below this is pinched rather than wrapped
    pinch_gap: dict = field(default_factory=lambda: {"parallel_gripper": 0.0, "dexterous": 0.012})
    #: parallel gripper: a finger's width outside its pad (m), the margin kept to a neighbour (m), and
    #: the least clearance between an open pad and the bar (m)
    gripper_finger_width: float = 0.021
    neighbour_margin: float = 0.005
    gripper_min_clearance: float = 0.008
    #: closed loop: grasp tries per episode, the episode's time budget (s), the time one more try needs
    max_grasp_tries: int = 3
    max_time: float = 24.0
    attempt_time: float = 3.0
    #: verification: after closing, pull back this far (m) at this speed (m/s); the grip holds when
    #: at least ``hold_parts`` fingers (per hand type; the thumb counts, the palm does not) still press
    #: on something with more than ``touch_min`` N (fingertips that pressed on the panel behind a thin
    #: bar leave it when the hand pulls back; fingers round a handle do not)
    verify_grasp: bool = True
    probe_distance: float = 0.04
    probe_min: float = 0.012
    probe_speed: float = 0.08
    touch_min: float = 0.3
    #: touch is judged over a window (s): held when a finger touched in at least ``touch_hits`` of
    #: its control steps (contacts on a held bar come and go from one step to the next)
    touch_window: float = 0.15
    touch_hits: int = 3
    hold_parts: dict = field(default_factory=lambda: {"parallel_gripper": 2, "dexterous": 1})
    load_excludes: tuple = ("palm", "wrist", "other")
    #: during the pull: no touch at all (palm included) for this long (s) ...
    slip_time: float = 0.4
    #: ... and the hand moved this far (m) since it last touched: a lightly damped drawer yanked by
    #: the fingers coasts along with the hand, out of contact, for a while
    slip_distance: float = 0.1
    #: drawers too? (off: a drawer yanked out of contact coasts on, and pulling on finds it again
    #: more often than a re-grasp does; drawers are re-grasped only when the first grasp held nothing)
    drawer_slips: bool = False
    #: a grip lost beyond this much travel (drawers, m) or turn (doors, degrees) is a finished pull
    drawer_done: float = 0.25
    door_done_deg: float = 80.0
    #: re-grasp: back off this far (m); where the grip last held, go this much deeper per try (m)
    backoff_distance: float = 0.06
    regrasp_deeper: float = 0.008
    #: with nothing held yet, the n-th re-grasp goes this far (m) along the approach axis from the
    #: first grasp (a thin bar seen in a few pixels may be nearer or farther than estimated)
    regrasp_offsets: tuple = (-0.012, 0.010)
    #: a deliberate miss of the first grasp (m, world offset; tests of the re-grasp)
    first_grasp_offset: tuple | None = None
    #: doors lost after opening at least ``push_min_turn`` degrees: push them open from inside
    push_recovery: bool = True
    push_min_turn: float = 8.0
    #: a hinge fitted to the handle's path is believed when within this (m) of the one seen in depth
    hinge_agreement: float = 0.12
    push_radius_range: tuple = (0.12, 1.2)
    push_clearance: float = 0.14
    push_entry_fraction: float = 0.45
    push_radius_fraction: float = 0.85
    push_to_deg: float = 125.0
    #: doors with a hinge seen in depth: pull along the circle about it (the tangent at the grasp
    #: site, whatever the site slid to along a bar) instead of the observed motion direction; fall
    #: back to the observed direction when the handle moves more than ``hinge_disagree_deg`` off it
    #: doors: stop pulling once the site came back toward the cabinet (+x) this far (m) from the
    #: farthest it got (None: never)
    door_back_stop: float | None = 0.03
    hinge_pull: bool = True
    hinge_radius_range: tuple = (0.12, 1.2)
    hinge_disagree_deg: float = 40.0
    hinge_check_distance: float = 0.03
    #: Kind seen in the pull (learned solvers only: the oracle's box is the named handle). Once the
    #: held handle travelled ``kind_check_distance`` (m), its path tells its kind: a drawer slides
    #: straight, a door's handle swings on a circle. The turn (deg) between the path's first and
    #: last ``kind_chord`` (m) at or above ``kind_door_turn`` is a door's, at or below
    #: ``kind_drawer_turn`` a drawer's. A handle of the other kind than the instruction's is the
    #: wrong one: it is pushed back, let go, and the solver is asked again with what was seen
    #: (``solver.solve(..., observed=...)``), at most ``max_target_tries`` handles per episode.
    verify_kind: bool = True
    kind_check_distance: float = 0.12
    kind_chord: float = 0.03
    kind_door_turn: float = 8.0
    kind_drawer_turn: float = 2.0
    kind_door_tilt: float = 30.0
    kind_drawer_tilt: float = 10.0
    #: a turn above this (deg) within ``kind_check_distance`` is no door's (its hinge would be less
    #: than ~17 cm from the handle) but a hand sliding along its bar: unclear (two drawers of the
    #: real train part's oracle pulls turned 38-81 degrees so, one of them a broken cabinet)
    kind_door_turn_max: float = 30.0
    #: the kinds whose sighting gives a handle up. Only "door" (a drawer was named, the handle
    #: swung): the oracle's drawer pulls turned at most 4.1 degrees on the real train part (284
    #: pulls, but for two hands sliding 38-81 degrees along a bar) and 6.3 on the procedural train
    #: split (490; a hand twisting on a vertical pull as the load comes on), its door pulls 8 or
    #: more in about half (real) and 90 % (procedural) of the cases; while 4-10 % of the real doors
    #: per hand moved straight within 1 degree for 12 cm (a hand sliding along its bar), so
    #: "drawer" is only logged.
    kind_retry_on: tuple = ("door",)
    #: The front seen moving (a robot that can look again: :func:`perception.front_motion` between
    #: the first image and one taken at the check): a front whose shift toward the camera grows
    #: across it, or up it (a flap hinged at its bottom edge), by ``front_door_slope`` (m per m, the
    #: tangent of its angle) or more turned about a hinge; one level within ``front_drawer_slope``
    #: both ways that came ``front_drawer_shift`` (m) or more toward the camera slid out. From the
    #: oracle's pulls, all four hands, as named and with each handle pulled as the other kind
    #: (`tools/front_stats.py [--swap]`; the rest unclear: too little seen or moved): real train
    #: part (764 + 764): doors 344 of 436 turned, drawers 276 of 328 level; pulled as the other
    #: kind, doors 316 turned, drawers 288 level; procedural train split (1108 + 1108): doors 604 of
    #: 612, drawers 490 of 496; pulled as the other kind, doors 553 turned, drawers 475 level. The
    #: one wrong reading of the 3744: a drawer pulled as a door read turned (a 10 cm sliver beside
    #: the hand, which gives nothing up: a door was named). No other came within 0.07 of the other
    #: kind's threshold. A flap tips top first, so only ``up`` > 0 counts for a door (drawers
    #: pulled as doors tipped bottom first by up to 0.09). ``front_retry_on``: the kinds whose
    #: sighting by the front gives a handle up.
    front_door_slope: float = 0.1
    front_drawer_slope: float = 0.05
    front_drawer_shift: float = 0.05
    front_retry_on: tuple = ("drawer", "door")
    #: (3: on the real train part CLIPort gave up both bars of a double door for a lone "drawer" in
    #: 6 episodes, 11.3-11.8 s into the 24 s budget, and had no try left for the drawer)
    max_target_tries: int = 3
    #: time (s) a new handle needs (approach, grasp, a pull)
    retarget_time: float = 6.0

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

    def __init__(self, env, on_step: Callable[[], None] | None = None,
                 look: Callable[[], np.ndarray] | None = None):
        self.env = env
        #: a new depth image from the episode's camera (the one that took the first observation),
        #: or None where the robot cannot look again
        self.look = look
        self.physics = env.physics
        self.task = env.task
        self.spec: HandSpec = env.task.hand.spec
        self.on_step = on_step
        self.n_steps = 0
        # Indices read on every control step (physics.bind costs more than a physics substep).
        self._data = self.physics.data.ptr
        self._site_id = int(self.physics.bind(self.task.hand.grasp_site).element_id)
        self._finger_qpos = np.array([int(a) for a in self.physics.bind(self.task.hand.joints).qposadr])
        self._touch = HandTouch(self.task.hand, self.physics)  # the hand's own state

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

    def contact_touch(self) -> dict[str, float]:
        """Normal force (N) on each part of the hand from things that are not the hand (`HandTouch`)."""
        return self._touch.read()

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
    regrasps: int = 0  # grasps tried after the first
    grasp_style: str = ""
    shape: dict | None = None  # the handle as measured in depth
    pushed: bool = False  # a lost door was pushed open from inside
    #: handles given up because their motion showed the other kind than the instruction's:
    #: [{"box": [...], "kind": "door" | "drawer"}, ...]
    wrong_kind: list = field(default_factory=list)
    events: list = field(default_factory=list)

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class GraspChoice:
    """One grasp: the style chosen from the handle's shape, the site pose and the finger targets."""

    style: str  # "hook" (behind a bar with room), "pinch" (a bar close to its panel), "wrap" (a knob)
    orientation: str
    quat: np.ndarray
    pos: np.ndarray
    pre: np.ndarray
    closed: np.ndarray
    attempt: int = 0

    @property
    def axis(self) -> np.ndarray:
        """The approach direction (site +z)."""
        return quat_axis_z(self.quat)

    def to_dict(self) -> dict:
        return {"style": self.style, "orientation": self.orientation, "attempt": self.attempt,
                "pos": [round(float(x), 4) for x in self.pos]}


@dataclass
class PullState:
    """What a pull knows and keeps across re-grasps: its direction, turn and the held track."""

    quat0: np.ndarray
    direction: np.ndarray = field(default_factory=lambda: np.array([-1.0, 0.0, 0.0]))
    base_dir: np.ndarray = field(default_factory=lambda: np.array([-1.0, 0.0, 0.0]))
    turned: float = 0.0
    travelled: float = 0.0
    track: list = field(default_factory=list)  # site positions while the grip held
    last_held: tuple | None = None  # (site pos, site quat) the last time the grip held
    #: doors: the hinge (world x, y) the pull turns about, the handle's start angle about it and the
    #: sense of opening (+1 / -1); None until a pull starts with a hinge seen in depth
    hinge: np.ndarray | None = None
    angle0: float = 0.0
    sense: float = 0.0
    opened: float = 0.0  # the largest door angle (deg) reached while the grip held
    peak_turn: float = 0.0  # the pull direction's farthest turn (deg, signed) without a hinge
    held_back: bool = False  # a direction turning back from ``peak_turn`` was not taken
    #: where the latest pull's held path starts in ``track``, and the kind (and turn, deg) it showed
    pull_start: int = 0
    seen_kind: str | None = None
    seen_by: str = ""  # "path" (the held handle's) or "front" (the camera's)
    seen_turn: float = 0.0


class Planner:
    """Deterministic open-the-handle controller around a handle solver.

    Stages (each a method): :meth:`locate` (solver box -> 3D handle), :meth:`perceive` (shape from
    depth), :meth:`choose_grasp`, :meth:`approach`, :meth:`close_and_verify` (touch sensors: does
    the hand hold?), :meth:`pull` (until done or the grip slips), :meth:`recover` (back off and
    grasp again; a door that started to open and was lost is pushed open from inside). With a
    learned solver, a handle whose pull shows the other kind than the instruction's (a drawer was
    named and the handle swings like a door's) is taken back, let go, and the solver asked again
    with what was seen (:meth:`kind_from_track`, :meth:`push_back`)."""

    def __init__(self, solver: HandleSolver, spec: HandSpec, config: PlannerConfig = PlannerConfig(),
                 grasp: GraspProfile | None = None, on_stage: Callable[[str, dict], None] | None = None):
        self.solver = solver
        self.spec = spec
        self.grasp = grasp
        self.config = grasp.apply(config) if grasp is not None else config
        self.on_stage = on_stage
        #: the episode's first observation and the handle being pulled (the front check reads them)
        self._first: Observation | None = None
        self._pulled_handle = None

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

    def holding(self, robot: Robot) -> tuple[bool, dict]:
        """Whether the hand holds something, from touch: at least ``hold_parts`` fingers (thumb
        not) press on something other than the hand (a thumb alone can hook a bar)."""
        touch = robot.contact_touch()
        parts = [k for k, v in touch.items()
                 if v > self.config.touch_min and k not in self.config.load_excludes]
        need = self.config.hold_parts.get(self.spec.hand_type, 1)
        return len(parts) >= need, touch

    def _time_left(self, robot: Robot) -> float:
        return self.config.max_time - robot.time

    # ---------------------------------------------------------------- stages
    def run(self, robot: Robot, obs: Observation) -> PlanResult:
        cfg = self.config
        result = PlanResult(stage_reached="locate", failed_stage=None)
        try:
            result.target_kind = target_kind(obs.instruction)
        except InstructionNotUnderstood as exc:  # refused, never guessed: the robot does not move
            result.stage_reached = result.failed_stage = "language"
            result.events.append({"language": exc.reason})
            self._hold_until_min_time(robot, None)
            return result
        self._first = obs  # the image a pulled front's motion is measured against
        observed: tuple = ()
        handle, box = self.locate(robot, obs, result)
        if handle is None:
            result.failed_stage = "locate"
            self._hold_until_min_time(robot, None)
            return result
        while True:
            status, state, grasp = self.open_handle(robot, obs, handle, box, result)
            if status != "wrong_kind":
                break
            # the handle moved as the other kind: push it back, let go, ask the solver again
            seen = state.seen_kind
            observed = observed + ((box.as_tuple(), seen),)
            result.wrong_kind.append({"box": [round(x, 2) for x in box.as_tuple()], "kind": seen,
                                      "by": state.seen_by, "turn_deg": round(state.seen_turn, 1)})
            self.push_back(robot, grasp, state)
            if len(observed) >= cfg.max_target_tries or self._time_left(robot) < cfg.retarget_time:
                status = "not_held"
                break
            new_handle, new_box = self.locate(robot, obs, result, observed)
            if new_handle is None or centres_overlap([new_box.as_tuple()], [b for b, _ in observed]).any():
                status = "not_held"
                break
            self._look_again(robot, obs)  # only where another handle is pulled
            handle, box = new_handle, new_box
        result.pulled = state.travelled
        result.turned_deg = state.turned
        result.grasp_style = grasp.style

        # -- hold (and optionally release), then check
        site, squat = robot.site_pose()
        fingers = grasp.closed if status == "done" else self.spec.pregrasp_profile(grasp.orientation)
        if cfg.release and status == "done":
            pre = self.spec.pregrasp_profile(grasp.orientation)
            self._hold(robot, site, squat, grasp.closed, 0.2)
            self._hold(robot, site, squat, pre, 0.4)
            self._move(robot, site, site - 0.08 * quat_axis_z(squat), squat, pre, cfg.approach_speed)
            fingers = pre
        self._hold_until_min_time(robot, (robot.site_pose()[0], robot.site_pose()[1], fingers))
        self._stage(result, "check", pulled=round(result.pulled, 4), turned_deg=round(result.turned_deg, 2),
                    regrasps=result.regrasps)
        if status == "not_held" and result.pulled < 0.03 and not result.pushed:
            result.failed_stage = "grasp"
        elif status != "done" and not result.pushed:
            result.failed_stage = "pull"
        return result

    def _look_again(self, robot: Robot, obs: Observation) -> None:
        """A new image for the next pulled front's motion to be measured against: a wrong handle
        pushed back may leave its part ajar (a drawer a few cm out), which the first image would
        show as the next front's motion (a drawer strip 7 cm out, read level across a door it
        spans). The solver keeps reading the first image."""
        depth = _look(robot)
        if depth is not None:
            self._first = replace(obs, depth=depth)

    def open_handle(self, robot: Robot, obs: Observation, handle, box, result: PlanResult):
        """Perceive, grasp and pull one handle, grasping again where the grip is lost: (status,
        pull state, last grasp); status "done", "slipped", "not_held" or "wrong_kind" (its motion
        showed the other kind than the instruction's)."""
        cfg = self.config
        self._pulled_handle = handle
        shape = self.perceive(handle, box, obs, result)
        grasp = self.choose_grasp(handle, shape, obs, result)
        door = result.target_kind == "door" and cfg.pull == "arc"
        state = PullState(quat0=grasp.quat)
        status = "not_held"
        for attempt in range(cfg.max_grasp_tries):
            if attempt > 0 and self._time_left(robot) < cfg.attempt_time:
                break
            grasp.attempt = attempt
            if attempt > 0:
                result.regrasps += 1
            self.approach(robot, grasp, result, first=attempt == 0 and not result.wrong_kind)
            if not self.close_and_verify(robot, grasp, result):
                status = "not_held"
                self.back_off(robot, grasp)
                grasp = self.next_grasp(grasp, handle, shape, state, result)
                continue
            status = self.pull(robot, grasp, door, state, result)
            if status == "wrong_kind":
                return status, state, grasp
            if status == "slipped" and (abs(state.turned) >= cfg.door_done_deg if door
                                        else state.travelled >= cfg.drawer_done):
                status = "done"  # lost at the end of the travel (the part's stop pulled the hand off)
            if status == "done":
                break
            if door and cfg.push_recovery:
                arc = self.door_arc(state)
                if arc is not None and math.degrees(arc[4]) >= cfg.push_min_turn:
                    self.back_off(robot, grasp)
                    break  # an opened door is pushed open from inside (below), not grasped again
            self.back_off(robot, grasp)
            grasp = self.next_grasp(grasp, handle, shape, state, result)
        if door and status != "done" and cfg.push_recovery:
            self.recover_door(robot, state, result)
        return status, state, grasp

    def checks_kind(self) -> bool:
        """Whether pulls watch the handle's kind: a learned solver that can be asked again."""
        return (self.config.verify_kind and not getattr(self.solver, "needs_ground_truth", False)
                and getattr(self.solver, "accepts_observed", False))

    def kind_from_track(self, track: list) -> tuple[str | None, float | None, float | None]:
        """(kind, turn, tilt) of a held handle's path (site positions): the turn (deg) between the
        path's first and last ``kind_chord`` seen from above, the tilt (deg) between them seen from
        the side. "drawer" for a path straight both ways, "door" for one that turns (a side-hinged
        door) or tilts much (a flap hinged at its bottom edge), None where too short or unclear."""
        cfg = self.config
        pts = np.asarray(track, float)
        if len(pts) < 3:
            return None, None, None
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
        if s[-1] < cfg.kind_check_distance:
            return None, None, None
        i0 = int(np.searchsorted(s, cfg.kind_chord))
        i1 = int(np.searchsorted(s, s[-1] - cfg.kind_chord, side="right")) - 1
        d0, d1 = pts[i0] - pts[0], pts[-1] - pts[max(0, i1)]
        h0, h1 = float(np.linalg.norm(d0[:2])), float(np.linalg.norm(d1[:2]))
        if h0 < 1e-6 or h1 < 1e-6:
            return None, None, None
        turn = abs(math.degrees(math.atan2(d0[0] * d1[1] - d0[1] * d1[0], float(d0[:2] @ d1[:2]))))
        tilt = abs(math.degrees(math.atan2(d1[2], h1) - math.atan2(d0[2], h0)))
        if cfg.kind_door_turn <= turn <= cfg.kind_door_turn_max or tilt >= cfg.kind_door_tilt:
            return "door", turn, tilt
        if turn <= cfg.kind_drawer_turn and tilt <= cfg.kind_drawer_tilt:
            return "drawer", turn, tilt
        return None, turn, tilt

    def judge_kind(self, robot, site, state: PullState, result: PlanResult) -> bool | None:
        """The held handle's kind, from its path and from the front seen moving (both logged in
        ``result.events``): True where it is the other kind than the instruction's and is to be
        given up (``state.seen_kind``, ``seen_by``, ``seen_turn`` set), False where not, None
        where the path does not tell yet."""
        seen, turn, tilt = self.kind_from_track(state.track[state.pull_start:])
        if turn is None:
            return None
        result.events.append({"kind_seen": seen, "turn_deg": round(turn, 2), "tilt_deg": round(tilt, 2)})
        front = self.front_seen(robot, site)
        front_kind = self.kind_from_front(front)
        if front is not None:
            result.events.append({"front_seen": front, "front_kind": front_kind})
        wrong = self.wrong_kind(result.target_kind, seen, front_kind)
        if wrong is None or not self.checks_kind():
            return False
        state.seen_kind, state.seen_by = wrong
        state.seen_turn = turn
        return True

    def wrong_kind(self, named: str, path_kind: str | None, front_kind: str | None) -> tuple[str, str] | None:
        """(kind, what showed it: "front" or "path") where the pulled handle is of another kind than
        the ``named`` one, else None. The path and the front must not disagree, but for a named
        door: pulled as a door, the hand is steered round a circle whatever the part does, so the
        path's "door" shows nothing and does not stand against the front's "drawer". (The oracle's
        pulls on the train sets, `tools/front_stats.py --swap`: a drawer's handle pulled for a named
        door is then given up in 288 of 328 pulls on the real train part, 278 when the path's
        "door" stood against the front, and in 475 of 496 on the procedural one, 438 before; no
        handle pulled as what it is was given up, either way.)"""
        cfg = self.config
        path_shows = None if named == "door" and path_kind == "door" else path_kind
        if front_kind in cfg.front_retry_on and front_kind != named and path_shows in (None, front_kind):
            return front_kind, "front"
        if path_kind in cfg.kind_retry_on and path_kind != named and front_kind in (None, path_kind):
            return path_kind, "path"
        return None

    def kind_from_front(self, front: dict | None) -> str | None:
        """"door" for a front that turned, "drawer" for one that slid out level, None where unclear
        (or not seen)."""
        cfg = self.config
        if front is None:
            return None
        if abs(front["across"]) >= cfg.front_door_slope or front["up"] >= cfg.front_door_slope:
            return "door"
        if max(abs(front["across"]), abs(front["up"])) <= cfg.front_drawer_slope \
                and front["shift"] >= cfg.front_drawer_shift:
            return "drawer"
        return None

    def front_seen(self, robot, site) -> dict | None:
        """How the pulled handle's front moved since the first image (:func:`front_motion`), where
        the robot can look again."""
        handle, first = self._pulled_handle, self._first
        if handle is None or first is None or first.depth is None:
            return None
        depth = _look(robot)
        if depth is None:
            return None
        seen = front_motion(first.depth, depth, first.camera_view, handle.centre, handle.panel_x, site)
        return None if seen is None else {k: round(v, 4) if isinstance(v, float) else v for k, v in seen.items()}

    def push_back(self, robot: Robot, g: GraspChoice, state: PullState) -> None:
        """Take a wrong handle back along the path it came (still held), then let go and back off:
        the part closes again (a drawer pulled as a door may stay a little out: the hand slid
        along its bar) and leaves the way to the next handle free."""
        cfg = self.config
        site, squat = robot.site_pose()
        path = [site] + [np.asarray(p, float) for p in reversed(state.track[state.pull_start:])]
        for a, b in zip(path[:-1], path[1:]):
            if float(np.linalg.norm(b - a)) > 1e-4:
                self._move(robot, a, b, squat, g.closed, cfg.pull_speed)
        self.back_off(robot, g)

    def locate(self, robot: Robot, obs: Observation, result: PlanResult, observed: tuple = ()):
        """The solver's box (snapped to the handle in depth for learned solvers) -> 3D handle;
        ``observed``: (box, kind) of handles whose motion showed their kind (a solver that takes them)."""
        cfg = self.config
        self._stage(result, "locate")
        if observed:
            box = self.solver.solve(obs.rgb, obs.depth, obs.instruction, obs.camera_view, observed=observed)
        else:
            box = self.solver.solve(obs.rgb, obs.depth, obs.instruction, obs.camera_view)
        if cfg.refine_with_depth and snaps_to_depth(self.solver, box):
            result.events.append({"solver_box": box.to_dict()})
            box = refine_box_with_depth(box, obs.depth, obs.camera_view)
        if box is not None and cfg.one_of_paired_handles:
            single = one_of_paired_handles(box, obs.depth)
            if single is not None:  # a pair of pulls under one box: take the nearer one
                result.events.append({"paired_handles_box": box.to_dict()})
                box = single
        result.box = box.to_dict() if box is not None else None
        handle = estimate_handle(box, obs.depth, obs.camera_view, cfg) if box is not None else None
        if handle is not None:
            result.handle = handle.to_dict()
        return handle, box

    def perceive(self, handle, box, obs: Observation, result: PlanResult):
        """Thickness, length, stand-off gap and free space around the handle, measured in depth."""
        shape = measure_handle(handle, box, obs.depth, obs.camera_view)
        result.shape = shape.to_dict()
        return shape

    def choose_grasp(self, handle, shape, obs: Observation, result: PlanResult) -> GraspChoice:
        """Orientation from the handle and the instruction; style from the measured shape."""
        cfg = self.config
        orientation = handle.orientation
        if handle.kind == "knob":
            orientation = self.grasp.knob_orientation if self.grasp is not None else "horizontal"
        low = handle.centre[2] < cfg.low_handle_height
        quat = orientation_for_handle(orientation)
        neighbour_above = result.target_kind == "door" and self._neighbour_above(shape)
        if orientation == "horizontal" and (handle.centre[2] < cfg.flip_below or neighbour_above):
            quat = quat_mul(quat, yaw_quat(math.pi))  # fingers down (site frame: rotate about +z)
        flip_doors = cfg.flip_right_doors and (orientation == "vertical" or not cfg.horizontal_doors_unflipped)
        if result.target_kind == "door" and flip_doors and self.spec.hand_type != "parallel_gripper":
            # Fingers point toward the hinge, so that the door's pull presses the handle into the finger
            # curl. The side comes from the instruction where it names one (double doors), else from
            # the depth image (single doors: the handle sits near the free edge).
            hinge = hinge_side(obs.instruction)
            if hinge is None and cfg.infer_hinge:
                hinge = infer_hinge_side(handle, obs.depth, obs.camera_view)
            result.events.append({"hinge_side": hinge})
            if hinge == "right":
                quat = quat_mul(quat, yaw_quat(math.pi))
        self._hinge = None
        if result.target_kind == "door":
            self._hinge = self.hinge_from_depth(handle, obs, result)
        style = self.grasp_style(handle, shape)
        depth = float(cfg.grasp_depth.get(style, cfg.grasp_depth.get(_STYLE_KIND[style], 0.0)))
        pos = handle.centre + np.array([depth, 0.0, 0.0])
        pitch = float(cfg.low_handle_pitch.get(self.spec.name, 0.0))
        if pitch and low and orientation == "horizontal":
            quat = quat_mul(axis_angle_quat((0.0, 1.0, 0.0), math.radians(pitch)), quat)
            result.events.append({"low_handle_pitch": pitch})
        lift = float(cfg.low_handle_lift.get(self.spec.name, 0.0))
        if lift > 0.0 and low:
            pos = pos + np.array([0.0, 0.0, lift])
            result.events.append({"low_handle_lift": lift})
        floor = cfg.min_grasp_height.get(self.spec.name)
        if floor is not None and pos[2] < floor:
            result.events.append({"min_grasp_height": [round(float(pos[2]), 4), floor]})
            pos = np.array([pos[0], pos[1], float(floor)])
        pre = self.spec.pregrasp_profile(orientation)
        closed = self.closed_profile(orientation)
        if self.spec.hand_type == "parallel_gripper":
            pre = self.gripper_opening(pre, orientation, shape, result)
        grasp = GraspChoice(style, orientation, quat, pos, pre, closed)
        self._first_pos = pos.copy()
        result.events.append({"grasp": grasp.to_dict()})
        return grasp

    def _neighbour_above(self, shape) -> bool:
        """A horizontal bar with something close above it (a neighbour's handle seen in depth) and
        more room below: the fingers point down, the hand's body stays clear of the neighbour."""
        clear = shape.clear
        return clear["up"] < self.config.neighbour_clear and clear["down"] > clear["up"] + 0.02

    def gripper_opening(self, pre: np.ndarray, orientation: str, shape, result: PlanResult) -> np.ndarray:
        """A parallel gripper opens no wider than the free space beside the handle allows (a
        neighbouring handle of a double door 5-8 cm away), and never narrower than the bar."""
        cfg = self.config
        sides = ("up", "down") if orientation == "horizontal" else ("left", "right")
        room = min(shape.clear[k] for k in sides) + shape.thickness / 2
        opening = room - cfg.gripper_finger_width - cfg.neighbour_margin
        opening = max(opening, shape.thickness / 2 + cfg.gripper_min_clearance)
        if opening < float(np.max(pre)):
            result.events.append({"gripper_opening": round(opening, 4)})
        return np.minimum(pre, opening)

    def hinge_from_depth(self, handle, obs: Observation, result: PlanResult):
        """The door's hinge line (world x, y) from the depth image: on the hinge side (named by the
        instruction, else inferred), where the door's front plane ends, at the panel's depth."""
        hinge = hinge_side(obs.instruction)
        if hinge is None:
            hinge = infer_hinge_side(handle, obs.depth, obs.camera_view)
        edges = door_edges(handle, obs.depth, obs.camera_view)
        if hinge is None or edges is None:
            return None
        y = edges[0] if hinge == "left" else edges[1]
        if abs(y - handle.centre[1]) < 0.1:
            return None
        point = np.array([handle.panel_x, y])
        result.events.append({"hinge_from_depth": [round(float(v), 3) for v in point]})
        return point

    def grasp_style(self, handle, shape) -> str:
        """``wrap`` round a knob; ``hook`` behind a bar where the stand-off gap lets the fingers
        through; ``pinch`` across a bar too close to its panel (or a flat pull)."""
        if handle.kind == "knob":
            return "wrap"
        if shape.gap < self.config.pinch_gap.get(self.spec.hand_type, 0.0):
            return "pinch"
        return "hook"

    def approach(self, robot: Robot, g: GraspChoice, result: PlanResult, first: bool = True) -> float:
        """Open hand to the pre-grasp in front of the handle (along the approach axis), then in."""
        cfg = self.config
        target = g.pos.copy()
        if first and cfg.first_grasp_offset is not None:  # a deliberate miss (tests)
            target = target + np.asarray(cfg.first_grasp_offset, float)
        axis = g.axis
        pre_pos = target - cfg.pregrasp_distance * axis
        self._stage(result, "approach", site_target=target.tolist(), attempt=g.attempt)
        site0, _ = robot.site_pose()
        self._hold(robot, site0, g.quat, g.pre, 0.3 if first else 0.15)
        if first:  # move at the start depth, then to the pre-grasp
            waypoint = np.array([min(site0[0], pre_pos[0]), pre_pos[1], pre_pos[2]])
            self._move(robot, site0, waypoint, g.quat, g.pre, cfg.move_speed)
            self._move(robot, waypoint, pre_pos, g.quat, g.pre, cfg.move_speed)
        else:
            self._move(robot, site0, pre_pos, g.quat, g.pre, cfg.move_speed)
        self._hold(robot, pre_pos, g.quat, g.pre, 0.15)
        self._move(robot, pre_pos, target, g.quat, g.pre, cfg.approach_speed)
        self._hold(robot, target, g.quat, g.pre, 0.15)
        err = float(np.linalg.norm(robot.site_pos() - target))
        if err > 0.03:  # blocked on the way in (the hand's own state says so)
            result.events.append({"approach_error": round(err, 4)})
        self._approach_target = target
        return err

    def close_and_verify(self, robot: Robot, g: GraspChoice, result: PlanResult) -> bool:
        """Close the fingers, then pull a little: a held handle pushes back on the fingers (the touch
        sensors' load rises); a hand that closed on air or on the panel feels nothing more."""
        cfg = self.config
        self._stage(result, "grasp", attempt=g.attempt)
        target = self._approach_target
        close_time = cfg.close_time if cfg.close_time is not None else self.spec.close_time
        n = max(1, int(round(close_time / robot.control_dt)))
        for i in range(1, n + 1):
            robot.step(target, g.quat, g.pre + (g.closed - g.pre) * i / n)
        self._hold(robot, target, g.quat, g.closed, cfg.settle_time)
        if not cfg.verify_grasp:
            return True
        # pull back up to ``probe_distance``: a bar loose in a curled hand engages within a few cm
        start = robot.site_pos()
        n = max(1, int(math.ceil(cfg.probe_distance / (cfg.probe_speed * robot.control_dt))))
        back = -g.axis
        # contacts on a held bar come and go from step to step: judge over a window of steps
        window = max(1, int(round(cfg.touch_window / robot.control_dt)))
        recent: list[bool] = []
        touch: dict = {}
        held = False
        for i in range(1, n + 1):
            robot.step(start + back * cfg.probe_distance * i / n, g.quat, g.closed)
            if cfg.probe_distance * i / n >= cfg.probe_min:
                now, t = self.holding(robot)
                touch = t if now or not touch else touch
                recent = (recent + [now])[-window:]
                if sum(recent) >= cfg.touch_hits:
                    held = True
                    break
        if not held:
            held = sum(recent) >= 1
        result.events.append({"verify": {"attempt": g.attempt, "held": held,
                                         "touch": {k: round(v, 1) for k, v in touch.items() if v > 0.1}}})
        return held

    def back_off(self, robot: Robot, g: GraspChoice) -> None:
        """Open the fingers and move back along the approach axis."""
        site, squat = robot.site_pose()
        pre = g.pre
        self._hold(robot, site, squat, pre, 0.25)
        self._move(robot, site, site - self.config.backoff_distance * quat_axis_z(squat), squat, pre,
                   self.config.approach_speed * 2)

    def next_grasp(self, g: GraspChoice, handle, shape, state: PullState, result: PlanResult) -> GraspChoice:
        """The next try: where the grip last held (the handle moved with the part), a little deeper;
        else at the handle again, nearer then farther than the first try."""
        deeper = self.config.regrasp_deeper * (g.attempt + 1)
        if state.last_held is not None:  # the handle slid out toward the fingertips: go deeper there
            pos, quat = state.last_held
            quat = np.asarray(quat, float)
            new = GraspChoice(g.style, g.orientation, quat, np.asarray(pos, float) + deeper * quat_axis_z(quat),
                              g.pre, g.closed, g.attempt + 1)
        else:  # nothing held yet: the bar may be nearer or farther than seen; try nearer, then farther
            steps = self.config.regrasp_offsets
            shift = steps[min(g.attempt, len(steps) - 1)]
            new = GraspChoice(g.style, g.orientation, g.quat, self._first_pos + shift * g.axis, g.pre, g.closed,
                              g.attempt + 1)
        result.events.append({"regrasp": new.to_dict()})
        return new

    def _hold_until_min_time(self, robot: Robot, pose) -> None:
        if pose is None:
            pos, quat = robot.site_pose()
            fingers = self.spec.open_pose
        else:
            pos, quat, fingers = pose
        while robot.time < self.config.min_time - 1e-9:
            robot.step(pos, quat, fingers)

    def pull(self, robot: Robot, g: GraspChoice, door: bool, state: PullState, result: PlanResult) -> str:
        """Pull until the part is open ("done") or stalls ("done"), or the grip is lost ("slipped":
        the hand touched nothing for ``slip_time`` and moved ``slip_distance`` since it last did)."""
        cfg = self.config
        self._stage(result, "pull", attempt=g.attempt)
        dt = robot.control_dt
        start = robot.site_pos()
        target = start.copy()
        history = [start.copy()]
        travel_max = cfg.door_travel if door else cfg.drawer_travel
        stall_n = max(2, int(round(cfg.stall_time / dt)))
        slip_n = max(2, int(round(cfg.slip_time / dt)))
        quat = g.quat
        max_steps = int(round((max(0.0, travel_max - state.travelled) / cfg.pull_speed + 3.0) / dt))
        grip = robot.finger_qpos()  # the fingers as they closed on the handle
        grip_tolerance = cfg.grip_lost_change.get(self.spec.hand_type)
        quiet = 0
        last_touch = None
        direction = state.direction
        start_travel = state.travelled
        state.pull_start = len(state.track)
        held_path = 0.0  # the held path's length (m): the kind is judged once it is long enough
        watch_kind = True
        if door:
            self._start_hinge_pull(state, start, result)
        least_x = float(start[0])
        for k in range(max_steps):
            if self._time_left(robot) <= 0.0:
                return "done"
            site = robot.site_pos()
            if grip_tolerance is not None and float(np.max(np.abs(robot.finger_qpos() - grip))) > grip_tolerance:
                # the handle forced the fingers open: the grip is lost
                result.events.append({"grip_lost_at": round(state.travelled, 4)})
                return "slipped"
            if cfg.verify_grasp:
                held, touch = self.holding(robot)
                touching = held or any(v > cfg.touch_min for v in touch.values())
                quiet = quiet + 1 if not touching else 0
                if touching or last_touch is None:
                    last_touch = site.copy()
                away = float(np.linalg.norm(site - last_touch))
                if quiet >= slip_n and away >= cfg.slip_distance and (door or cfg.drawer_slips):
                    result.events.append({"slipped_at": round(state.travelled, 4), "turned": round(state.turned, 1)})
                    return "slipped"
                if held:
                    state.last_held = (site.copy(), quat.copy())
                    if len(state.track) > state.pull_start:
                        held_path += float(np.linalg.norm(site - state.track[-1]))
                    state.track.append(site.copy())
                    if watch_kind and held_path >= cfg.kind_check_distance - 1e-9:
                        verdict = self.judge_kind(robot, site, state, result)
                        if verdict is not None:
                            watch_kind = False  # judged once per pull
                            if verdict:
                                return "wrong_kind"
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
                    base_dir = state.base_dir
                    ang = math.degrees(math.atan2(base_dir[0] * cand[1] - base_dir[1] * cand[0],
                                                  float(base_dir @ cand)))
                    if state.hinge is not None and state.sense * ang < -cfg.hinge_disagree_deg / 4 \
                            and float(np.linalg.norm(site - start)) > cfg.hinge_check_distance:
                        # the handle turns the other way round: the hinge seen in depth is wrong
                        result.events.append({"hinge_pull_dropped": round(ang, 1)})
                        state.hinge = None
                    back = state.hinge is None and self._turned_back(state, ang)
                    if back and not state.held_back:
                        state.held_back = True
                        result.events.append({"door_turn_held": round(ang, 1), "from": round(state.peak_turn, 1)})
                    if state.hinge is None and abs(ang) <= cfg.door_max_turn and not back:
                        direction = cand
                        state.direction = cand
                        state.turned = ang
                        state.peak_turn = ang if abs(ang) > abs(state.peak_turn) else state.peak_turn
                        yaw = cfg.yaw_gain * ang + math.copysign(min(abs(ang), cfg.yaw_lead_deg), ang)
                        quat = turn_about_z(state.quat0, math.radians(yaw))
            if door and state.hinge is not None:
                tangent, ang = self._hinge_tangent(state, site)
                if abs(ang) <= cfg.door_max_turn:
                    direction = tangent
                    state.direction = tangent
                    state.turned = ang
                    state.opened = max(state.opened, abs(ang))
                    yaw = cfg.yaw_gain * ang + math.copysign(min(abs(ang), cfg.yaw_lead_deg), ang)
                    quat = turn_about_z(state.quat0, math.radians(yaw))
            pull_dir = direction
            if door and abs(state.turned) > 1.0 and cfg.pull_bias_deg:
                b = math.radians(math.copysign(cfg.pull_bias_deg, state.turned))
                c, sn = math.cos(b), math.sin(b)
                pull_dir = np.array([c * direction[0] - sn * direction[1], sn * direction[0] + c * direction[1], 0.0])
            # advance the target along the direction, never more than `lead` ahead of the site
            target = target + pull_dir * cfg.pull_speed * dt
            ahead = float((target - site) @ pull_dir)
            if ahead > cfg.lead:
                target = target - pull_dir * (ahead - cfg.lead)
            lateral = (target - site) - pull_dir * float((target - site) @ pull_dir)
            target = target - lateral
            robot.step(target, quat, g.closed)
            if door:
                state.travelled += float(np.linalg.norm(history[-1] - history[-2]))
            else:
                state.travelled = max(state.travelled, start_travel + float(np.linalg.norm(site - start)))
            if state.travelled >= travel_max:
                return "done"
            if door and cfg.door_back_stop is not None:
                least_x = min(least_x, float(site[0]))
                if float(site[0]) - least_x > cfg.door_back_stop:
                    # the handle swings back toward the cabinet: the door is at its stop (or beyond
                    # 90 degrees); pulling on would drag it shut
                    result.events.append({"door_back_stop": round(state.turned, 1)})
                    return "done"
            if k > stall_n and float(np.linalg.norm(history[-1] - history[-1 - stall_n])) < cfg.stall_distance:
                return "done"
        return "done"

    def _turned_back(self, state: PullState, ang: float) -> bool:
        """Whether a pull direction turned ``ang`` (deg) comes back ``door_turn_back`` or more from
        a farthest turn of at least ``door_turn_back_after`` (such a direction is not taken)."""
        cfg = self.config
        peak = state.peak_turn
        if cfg.door_turn_back is None or abs(peak) < cfg.door_turn_back_after:
            return False
        return math.copysign(1.0, peak) * (peak - ang) >= cfg.door_turn_back

    def _start_hinge_pull(self, state: PullState, site: np.ndarray, result: PlanResult) -> None:
        """Pull a door along the circle about the hinge seen in depth (kept across re-grasps)."""
        cfg = self.config
        seen = getattr(self, "_hinge", None)
        if not cfg.hinge_pull or seen is None or state.sense != 0.0:
            return
        r = site[:2] - np.asarray(seen, float)
        radius = float(np.linalg.norm(r))
        if not (cfg.hinge_radius_range[0] <= radius <= cfg.hinge_radius_range[1]):
            return
        t = np.array([-r[1], r[0]]) / radius
        if abs(t[0]) < 0.5:  # the handle is not beside its hinge in the door's plane
            return
        state.sense = -1.0 if t[0] > 0 else 1.0  # the tangent that leaves the cabinet (-x)
        state.hinge = np.asarray(seen, float)
        state.angle0 = math.atan2(r[1], r[0])
        result.events.append({"hinge_pull": {"hinge": [round(float(v), 3) for v in seen], "radius": round(radius, 3)}})

    def _hinge_tangent(self, state: PullState, site: np.ndarray) -> tuple[np.ndarray, float]:
        """The opening tangent of the circle about the hinge through the site, and the door's angle
        (deg, signed like the turn of the pull direction from -x)."""
        r = site[:2] - state.hinge
        norm = max(1e-6, float(np.linalg.norm(r)))
        t = state.sense * np.array([-r[1], r[0]]) / norm
        tangent = np.array([t[0], t[1], 0.0])
        base = state.base_dir
        ang = math.degrees(math.atan2(base[0] * t[1] - base[1] * t[0], float(base[0] * t[0] + base[1] * t[1])))
        return tangent, ang

    def door_arc(self, state: PullState):
        """The door's hinge, the handle's radius, its start angle, the sense of opening and how far
        it opened (rad): from the handle's held path (a fitted circle) where that agrees with the
        hinge seen in depth, else from the hinge seen in depth. None when neither is known."""
        cfg = self.config
        if len(state.track) < 8:
            return None
        track = np.array(state.track)
        p0 = track[0]
        seen = getattr(self, "_hinge", None)
        fit = fit_circle_xy(track) if abs(state.turned) >= cfg.push_min_turn else None
        centre = None
        if fit is not None:
            c, r = fit
            plausible = cfg.push_radius_range[0] <= r <= cfg.push_radius_range[1]
            if seen is not None:
                plausible &= float(np.linalg.norm(c - seen)) < cfg.hinge_agreement
            if plausible:
                centre = c
        if centre is None and seen is not None:
            centre = np.asarray(seen, float)
        if centre is None:
            return None
        radius = float(np.linalg.norm(p0[:2] - centre))
        a0 = math.atan2(p0[1] - centre[1], p0[0] - centre[0])
        a_now = math.atan2(track[-1][1] - centre[1], track[-1][0] - centre[0])
        sense = 1.0 if _wrap(a_now - a0) > 0 else -1.0
        return centre, radius, a0, sense, abs(_wrap(a_now - a0))

    def recover_door(self, robot: Robot, state: PullState, result: PlanResult) -> bool:
        """A door that opened and was lost: push it open from inside with the hand alone.

        The hinge comes from the held track (a circle through the handle's path). The hand goes round
        the door's free edge into the gap between door and cabinet, palm toward the door's inside,
        and sweeps along the arc, pushing the door open by contact."""
        cfg = self.config
        arc = self.door_arc(state)
        if arc is None:
            return False
        centre, radius, a0, sense, opened = arc
        if math.degrees(opened) < cfg.push_min_turn or not (cfg.push_radius_range[0] <= radius <= cfg.push_radius_range[1]):
            result.events.append({"push_skipped": {"opened_deg": round(math.degrees(opened), 1), "radius": round(radius, 3)}})
            return False
        p0 = state.track[0]
        self._stage(result, "recover", hinge=[round(float(x), 3) for x in centre], radius=round(radius, 3),
                    opened_deg=round(math.degrees(opened), 1))
        z = float(p0[2])

        def point(rho, phi):
            a = a0 + sense * phi
            return np.array([centre[0] + rho * math.cos(a), centre[1] + rho * math.sin(a), z])

        def palm_quat(phi):
            a = a0 + sense * phi
            radial = np.array([math.cos(a), math.sin(a), 0.0])
            tangent = sense * np.array([-math.sin(a), math.cos(a), 0.0])  # the opening direction
            y = np.cross(tangent, radial)
            return mat_to_quat(np.column_stack([radial, y, tangent]))

        fist = self.closed_profile("vertical")
        site, squat = robot.site_pose()
        out = radius + cfg.push_clearance
        q_out = palm_quat(opened + math.radians(20))
        # round the free edge: out beyond it, across into the gap, in behind the door
        b = point(out, opened + math.radians(20))
        self._move(robot, site, site + np.array([-0.05, 0.0, 0.0]), squat, fist, cfg.move_speed)
        self._move(robot, robot.site_pos(), b, q_out, fist, cfg.move_speed)
        phi_in = opened * cfg.push_entry_fraction
        a = point(out, phi_in)
        self._move(robot, b, a, palm_quat(phi_in), fist, cfg.approach_speed * 2)
        rho = radius * cfg.push_radius_fraction
        c = point(rho, phi_in)
        self._move(robot, a, c, palm_quat(phi_in), fist, cfg.approach_speed * 2)
        # sweep: the palm meets the door's inside and pushes it along the arc
        phi = phi_in
        phi_end = math.radians(cfg.push_to_deg)
        dphi = cfg.pull_speed / rho * robot.control_dt
        while phi < phi_end and self._time_left(robot) > 0.0:
            phi = min(phi_end, phi + dphi)
            robot.step(point(rho, phi), palm_quat(phi), fist)
        result.pushed = True
        result.events.append({"pushed_to_deg": round(math.degrees(phi), 1)})
        return True


#: the grasp-profile depth key of each style (``grasp_depth[style]`` wins where the profile has one)
_STYLE_KIND = {"hook": "bar", "pinch": "bar", "wrap": "knob"}


def _look(robot) -> np.ndarray | None:
    """A new depth image from the episode's camera, or None where the robot cannot look again
    (a robot of another kind may have no ``look``)."""
    look = getattr(robot, "look", None)
    return look() if look is not None else None


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def fit_circle_xy(points: np.ndarray):
    """Least-squares circle through points' (x, y): (centre, radius), or None when degenerate."""
    xy = points[:, :2]
    A = np.column_stack([2 * xy, np.ones(len(xy))])
    b = (xy ** 2).sum(axis=1)
    try:
        sol, *_ = np.linalg.lstsq(A, b, rcond=None)
    except np.linalg.LinAlgError:
        return None
    cx, cy, c = sol
    r2 = c + cx * cx + cy * cy
    if not np.isfinite(r2) or r2 <= 0:
        return None
    return np.array([cx, cy]), float(math.sqrt(r2))


__all__ = ["GRASP_FILE", "STAGES", "GraspChoice", "GraspProfile", "Observation", "PlanResult", "Planner",
           "PlannerConfig", "PullState", "Robot", "fit_circle_xy"]
