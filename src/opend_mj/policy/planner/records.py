"""What the planner sees, chooses, keeps and reports: plain records, no behaviour.

Units: metres, radians in quaternions (w, x, y, z), degrees where a name ends in ``_deg`` or says so.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from enum import StrEnum

import numpy as np

from opend_mj.transforms import mat_to_quat, quat_axis_z, quat_mul

#: The stages an episode goes through (``PlanResult.stage_reached``; "check" ends every episode).
STAGES = ("locate", "approach", "grasp", "pull", "recover")


class StageOutcome(StrEnum):
    """How a pull (:meth:`~opend_mj.policy.planner.pull.Pulling.pull`) or a handle's whole attempt
    (:meth:`~opend_mj.policy.planner.loop.Planner.open_handle`) ended. The values are the words the
    records keep (a pull's ``{"pull_end": ...}`` event), and a member equals its word."""

    #: the part is open (or the pull ended where it could not go on: stalled, at its stop, out of time)
    DONE = "done"
    #: the grip was lost during the pull
    SLIPPED = "slipped"
    #: no grasp held the handle (or the hand let go of it and it was given up)
    NOT_HELD = "not_held"
    #: every grasp closed on air and nothing moved: no handle in the solver's box
    NO_HANDLE = "no_handle"
    #: the held handle's motion showed the other kind than the instruction's
    WRONG_KIND = "wrong_kind"
    #: a drawer that did not come out along this direction (slid along its front next)
    STUCK = "stuck"


@dataclass
class Observation:
    """The one observation the planner gets: an RGB-D image, its camera and the instruction."""

    rgb: np.ndarray
    depth: np.ndarray
    instruction: str
    camera_view: object  # CameraView: intrinsics and pose


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
    #: [{"box": [...], "kind": "door" | "drawer", "by": "path" | "front", "turn_deg": ...}, ...]
    wrong_kind: list = field(default_factory=list)
    #: boxes given up because every grasp tried there closed on nothing (no touch at all):
    #: [[u0, v0, u1, v1], ...]
    no_handle: list = field(default_factory=list)
    events: list = field(default_factory=list)

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class GraspChoice:
    """One grasp: the style chosen from the handle's shape, the site pose and the finger targets."""

    style: str  # "hook" (behind a bar with room), "pinch" (a bar close to its panel), "wrap" (a knob),
    # "hook_down" (a low bar hooked from above by the closed fingers), "press_down" (the closed
    # fingers pressed on a low bar's top, dragging it by friction: no gap behind it takes them)
    orientation: str  # the handle's: "horizontal" | "vertical"
    quat: np.ndarray  # grasp-site orientation (world)
    pos: np.ndarray  # grasp-site position (world, m)
    pre: np.ndarray  # finger targets, open
    closed: np.ndarray  # finger targets, closed
    attempt: int = 0
    #: the direction (world unit vector) the grasp is tested by pulling along; None: back along
    #: the approach axis (a hand that hooks from above tests by pulling out of the panel instead)
    probe: np.ndarray | None = None
    #: m: a hook that does not fit behind the bar presses on its top instead; verify and pull keep
    #: the site's target this far below the site, so the fingers drag the bar by friction
    press: float = 0.0

    @property
    def on_top_press(self) -> float:
        """``press`` (m) for fingers that come down on the bar's top ("press_down": approach and
        close bounded too); 0 for the others, which go where they were planned."""
        return self.press if self.style == "press_down" else 0.0

    @property
    def axis(self) -> np.ndarray:
        """The approach direction (site +z)."""
        return quat_axis_z(self.quat)

    def to_dict(self) -> dict:
        out = {"style": self.style, "orientation": self.orientation, "attempt": self.attempt,
               "pos": [round(float(x), 4) for x in self.pos]}
        if self.press:
            out["press"] = self.press
        return out


@dataclass
class Flap:
    """A door hinged about a horizontal axis at its front's top (``sign`` +1: it lifts) or bottom
    edge (-1: it drops): the held site where its pull began (m), the horizontal unit vector the
    handle comes out along, and the distance (m) from the start to that edge (the largest radius)."""

    start: np.ndarray
    out: np.ndarray
    sign: float
    reach: float


@dataclass
class PullState:
    """What a pull knows and keeps across re-grasps: its direction, turn and the held track."""

    quat0: np.ndarray
    direction: np.ndarray = field(default_factory=lambda: np.array([-1.0, 0.0, 0.0]))
    base_dir: np.ndarray = field(default_factory=lambda: np.array([-1.0, 0.0, 0.0]))
    turned: float = 0.0  # the pull direction's turn from ``base_dir`` (deg, signed)
    travelled: float = 0.0  # m
    track: list = field(default_factory=list)  # site positions while the grip held
    last_held: tuple | None = None  # (site pos, site quat) the last time the grip held
    #: doors: the hinge (world x, y) the pull turns about, the handle's start angle about it (rad)
    #: and the sense of opening (+1 / -1); None until a pull starts with a hinge seen in depth
    hinge: np.ndarray | None = None
    angle0: float = 0.0
    sense: float = 0.0
    opened: float = 0.0  # the largest door angle (deg) reached while the grip held
    peak_turn: float = 0.0  # the pull direction's farthest turn (deg, signed) without a hinge
    tilt: float = 0.0  # the pull direction's tilt out of the horizontal (deg, up positive)
    peak_tilt: float = 0.0  # its largest (deg, signed): a flap's swing
    flap: Flap | None = None  # a flap seen by the held handle's rise (kept across re-grasps)
    front_z: tuple | None = None  # the front's top and bottom edge z (m) seen in depth; () unseen
    flap_looked: int = 0  # how many times the camera looked for a flap
    hinge_looked: int = 0  # how many times the camera looked at the front turning about its hinge
    slides: list | None = None  # directions still to slide a drawer that did not come out
    held_back: bool = False  # a direction turning back from ``peak_turn`` was not taken
    #: where the latest pull's held path starts in ``track``, and the kind (and turn, deg) it showed
    pull_start: int = 0
    seen_kind: str | None = None
    seen_by: str = ""  # "path" (the held handle's) or "front" (the camera's)
    seen_turn: float = 0.0

    def swung(self) -> float:
        """How far (deg) the held door swung: its turn about z, or a flap's tilt."""
        return max(abs(self.turned), abs(self.peak_tilt))


@dataclass
class EpisodeState:
    """What the planner's stages keep about the episode being run (a fresh one per :meth:`Planner.run`).

    ``first``: the image a pulled front's motion is measured against (the episode's first, or one
    taken after a wrong handle was pushed back); ``handle``: the 3D handle being opened;
    ``hinge``: the door's hinge line (world x, y) seen in depth, or None; ``first_pos``: the first
    grasp's site position (re-grasps with nothing held go near it); ``approach_target``: where the
    latest approach took the grasp site (the fingers close there); ``taken_over``, ``felt``: see below."""

    first: Observation | None = None
    handle: object | None = None  # HandleEstimate
    hinge: np.ndarray | None = None
    first_pos: np.ndarray | None = None
    approach_target: np.ndarray | None = None
    #: an episode taken over mid-way: {"turned_deg", "slid", "held"} (how far the part had moved,
    #: whether the hand held the handle); None for an episode planned from its start
    taken_over: dict | None = None
    #: whether the fingers have felt anything (touch at or above ``VerifyConfig.touch_min``) in a
    #: grasp's check at the handle being opened: a box where they never did holds no handle
    felt: bool = False


@dataclass
class PartMotion:
    """How the instructed part moved since the first image, as a rigid motion of the world: a turn
    ``rot`` (3 x 3) about ``pivot`` (world, m), then a shift ``shift`` (m). An episode taken over
    mid-way (:meth:`~opend_mj.policy.planner.Planner.run` with ``motion``) moves the grasp chosen in
    the first image with its part: a drawer pulled out, a door turned about its hinge."""

    rot: np.ndarray = field(default_factory=lambda: np.eye(3))
    pivot: np.ndarray = field(default_factory=lambda: np.zeros(3))
    shift: np.ndarray = field(default_factory=lambda: np.zeros(3))
    #: how far the part is open, as a share of its joint's range (None: unknown)
    share: float | None = None

    @property
    def axis(self) -> np.ndarray:
        """The turn's axis (world unit vector; zeros for a slide)."""
        r = self.rot
        v = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
        n = float(np.linalg.norm(v))
        return v / n if n > 1e-9 else np.zeros(3)

    @property
    def upright(self) -> bool:
        """Whether the part turned about an upright axis (a side door's hinge), not a level one (a flap's)."""
        return abs(float(self.axis[2])) > 0.9

    def point(self, p) -> np.ndarray:
        """Where a point of the part at ``p`` (world, m) in the first image is now."""
        return self.pivot + self.rot @ (np.asarray(p, float) - self.pivot) + self.shift

    def orientation(self, quat) -> np.ndarray:
        """An orientation (w, x, y, z) fixed to the part in the first image, now."""
        q = quat_mul(mat_to_quat(self.rot), np.asarray(quat, float))
        return q / np.linalg.norm(q)

    @property
    def angle_deg(self) -> float:
        """How far the part turned (deg)."""
        return float(np.degrees(np.arccos(np.clip((np.trace(self.rot) - 1.0) / 2.0, -1.0, 1.0))))

    @property
    def distance(self) -> float:
        """How far the part slid (m)."""
        return float(np.linalg.norm(self.shift))
