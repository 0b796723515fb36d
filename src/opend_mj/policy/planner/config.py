"""The planner's configuration: one frozen dataclass per stage, gathered in :class:`PlannerConfig`.

Units: metres, seconds, degrees (names ending ``_deg``), newtons; speeds in m/s. Numbers that
differ from hand to hand live with each hand (``hands/<name>/planner.json``,
:class:`~opend_mj.sim.hands.HandPlannerConfig`); perception's thresholds in
:class:`~opend_mj.policy.perception.PerceptionConfig`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import asdict, dataclass, field, replace

from opend_mj.policy.perception import PerceptionConfig


@dataclass(frozen=True)
class LocateConfig:
    """How a solver's image box becomes the handle to grasp."""

    #: snap a learned solver's box to the handle that stands out of the panel in depth (never the
    #: oracle's exact boxes, nor a box that is a depth proposal already)
    refine_with_depth: bool = True
    #: a box over a pair of pulls (its centre bare panel, two handles in depth) -> the nearer pull
    one_of_paired_handles: bool = True


@dataclass(frozen=True)
class ApproachConfig:
    """Moving the open hand to the handle: free-space moves, then straight in along the approach axis."""

    #: grasp-site distance (m) in front of the handle before moving in
    pregrasp_distance: float = 0.10
    #: free-space moves (m/s)
    move_speed: float = 0.6
    #: the final approach and the hand's small moves near the cabinet (m/s)
    approach_speed: float = 0.15
    #: the hand holds its pose this long (s) before the first approach, before a re-approach, at the
    #: pre-grasp and at the grasp (so that the mocap-driven root settles)
    first_wait: float = 0.3
    again_wait: float = 0.15
    pregrasp_wait: float = 0.15
    grasp_wait: float = 0.15
    #: a grasp site farther than this (m) from its target after the approach was blocked (logged)
    blocked_error: float = 0.03
    #: a deliberate miss of the first grasp (m, world offset; for tests of the re-grasp)
    first_grasp_offset: tuple | None = None


@dataclass(frozen=True)
class GraspConfig:
    """Where and how the hand grasps: the site pose from the handle, the finger orientation, the
    style (hook / pinch / wrap) and how far the fingers close."""

    #: grasp depth (m) beyond the handle's estimated centre along the approach axis, per handle kind
    #: ("bar", "knob") or grasp style; a hand's ``grasp.json`` sets it
    depth: dict = field(default_factory=lambda: {"bar": 0.0, "knob": 0.0})
    #: how far the fingers close: fraction of the way from the pre-grasp to the grasp profile of the
    #: hand spec (1: the spec's profile); a hand's ``grasp.json`` sets it
    close_scale: float = 1.0
    #: the finger orientation for knobs ("horizontal" | "vertical"); a hand's ``grasp.json`` sets it
    knob_orientation: str = "horizontal"
    #: seconds to close the fingers (None: the hand spec's ``close_time``), then to let them settle
    close_time: float | None = None
    settle_time: float = 0.3
    #: doors named "right" in the instruction: dexterous fingers point to -y (toward the hinge), so
    #: that the door's pull presses the handle into the finger curl
    flip_right_doors: bool = True
    #: ... only for vertical bars: the fingers round a horizontal bar point up (down where a
    #: neighbour closer than ``neighbour_clear`` (m) is above it and there is more room below, by
    #: ``more_room_below`` (m))
    horizontal_doors_unflipped: bool = True
    neighbour_clear: float = 0.10
    more_room_below: float = 0.02
    #: single doors (no side in the instruction): infer the hinge side from the depth image
    infer_hinge: bool = True
    #: a hinge line seen in depth closer than this (m, across) to the handle is not believed (a
    #: handle sits near a door's free edge, away from its hinge)
    min_hinge_distance: float = 0.1
    #: horizontal handles lower than this (m above the floor) are grasped with the fingers down
    flip_below: float = 0.2
    #: handles lower than this (m) are "low": the hand's ``low_handle_lift`` and ``low_handle_pitch``
    #: apply (``hands/<name>/planner.json``)
    low_handle_height: float = 0.10
    #: parallel gripper: a finger's width outside its pad (m), the margin kept to a neighbour (m),
    #: and the least clearance between an open pad and the bar (m)
    gripper_finger_width: float = 0.021
    neighbour_margin: float = 0.005
    gripper_min_clearance: float = 0.008


@dataclass(frozen=True)
class VerifyConfig:
    """Does the closed hand hold the handle? After closing, the hand pulls back a little and its
    touch sensors are read: fingers round a handle keep pressing on it, fingertips that pressed on
    the panel behind a thin bar leave it."""

    verify_grasp: bool = True
    #: pull back up to ``probe_distance`` (m) at ``probe_speed`` (m/s); touch counts from ``probe_min`` (m)
    probe_distance: float = 0.04
    probe_min: float = 0.012
    probe_speed: float = 0.08
    #: a part of the hand touches when pressed with more than this (N)
    touch_min: float = 0.3
    #: touch is judged over a window (s): held when the hand held in at least ``touch_hits`` of its
    #: control steps (contacts on a held bar come and go from one step to the next)
    touch_window: float = 0.15
    touch_hits: int = 3
    #: parts of the hand whose touch does not count toward a hold (the hand's ``hold_parts`` is the
    #: number of other parts needed)
    load_excludes: tuple = ("palm", "wrist", "other")


@dataclass(frozen=True)
class PullConfig:
    """The pull: the target leads the grasp site along the pull direction at bounded speed until the
    part stops, the travel is done or the grip is lost."""

    #: speed (m/s), lead of the target ahead of the site (m), maximum travel per kind (m). The
    #: travel limits are safety caps: a pull ends at the part's stop (the site stalls) before them.
    #: Drawers: the real OpenD train cabinets' drawers slide 0.24-0.70 m. Doors: the handle's path
    #: to a 90-degree stop is 1.73 m on a door 1.1 m wide (the real set's widest handles are 1.15 m
    #: from their hinge); 2.0 m is 95 degrees at the largest believed hinge radius (1.2 m,
    #: ``DoorConfig.hinge_radius_range``), or 170 degrees at 0.67 m
    speed: float = 0.15
    lead: float = 0.04
    drawer_travel: float = 0.8
    door_travel: float = 2.0
    #: stop pulling when the site moved less than ``stall_distance`` (m) in ``stall_time`` (s)
    stall_time: float = 0.6
    stall_distance: float = 0.008
    #: a lost grip: no touch at all (palm included) for ``slip_time`` (s), and the hand moved
    #: ``slip_distance`` (m) since it last touched (a lightly damped drawer yanked by the fingers
    #: coasts along with the hand, out of contact, for a while)
    slip_time: float = 0.4
    slip_distance: float = 0.1
    #: drawers too? (off: a drawer yanked out of contact coasts on, and pulling on finds it again;
    #: drawers are re-grasped only when the first grasp held nothing)
    drawer_slips: bool = False
    #: a grip lost beyond this much travel (drawers, m) or turn (doors, deg) is a finished pull
    drawer_done: float = 0.25
    door_done_deg: float = 80.0
    #: a drawer that the hand held less than ``slip_distance`` along the pull (it stalled, or the
    #: hand came off it) and whose front, seen again, did not move (a robot that cannot look
    #: again: whose handle came out less than ``drawer_stuck_travel`` (m) while held) does not
    #: slide this way: with ``drawer_slide`` it is
    #: grasped again and slid along its front, across its bar (a sliding panel: a vertical bar
    #: slides sideways, a horizontal one up or down), first toward where the front reaches farther
    #: from the handle (a handle sits at a panel's leading edge), then the other way
    drawer_stuck_travel: float = 0.03
    drawer_slide: bool = True


@dataclass(frozen=True)
class DoorConfig:
    """Pulling a door (``pull="arc"``): the pull direction follows the handle's circle, about the
    hinge seen in depth where there is one, else along the handle's observed motion; the hand's yaw
    turns with it so that the grip does not twist."""

    #: observed motion: a direction over ``direction_window`` control steps, believed once the site
    #: moved ``direction_min_motion`` (m) over it, low-passed with weight ``direction_gain`` per step
    direction_window: int = 6
    direction_min_motion: float = 0.004
    direction_gain: float = 0.35
    #: the observed-motion direction turns at most (the site's horizontal step) / ``min_path_radius``
    #: rad per control step (m; None: unbounded): a door's handle moves on a circle no smaller than
    #: this, so a faster turn is the hand sliding or twisting on the handle, not the door
    min_path_radius: float | None = 0.12
    #: the pull direction may point back toward the cabinet (+x) at most this much (sine of the angle)
    max_pull_toward_cabinet: float = 0.35
    #: stop turning once the pull direction turned this much (deg): a door's own stop ends the pull
    #: before (the real OpenD train set's doors open 90-179 degrees)
    max_turn_deg: float = 170.0
    #: without a hinge: once the direction turned at least ``turn_back_after_deg``, a direction
    #: ``turn_back_deg`` back from the farthest turn is not taken (a door opens one way; at its stop
    #: the hand is pushed aside, and following the direction round would drag the door shut).
    #: None: always taken
    turn_back_deg: float | None = 30.0
    turn_back_after_deg: float = 30.0
    #: the hand's yaw = ``yaw_gain`` * (the pull direction's turn) + ``yaw_lead_deg`` (deg, in the
    #: turn's sense, at most the turn); a hand that lags the door presses its fingertips into the
    #: panel on one side
    yaw_gain: float = 1.0
    yaw_lead_deg: float = 0.0
    #: flaps (doors hinged about a horizontal axis; :mod:`~opend_mj.policy.planner.flap`): seen once
    #: the held handle rose or sank ``flap_min_rise`` (m), within a factor ``flap_rise_ratio`` of the
    #: rise a circle about the front's far edge (seen in depth) predicts; then pulled along the
    #: circle whose radius the held path sets, between ``flap_min_radius_share`` x that edge's
    #: distance and the distance; the hand pitches with the flap by ``tilt_gain`` x its angle. A
    #: path whose chord turned more than ``flap_max_turn_deg`` about z came out as a side door's
    #: (on the 133 real cabinets: flaps' chords 0-10.3 degrees when seen, side doors 12.6 and more)
    flap_pull: bool = True
    flap_min_rise: float = 0.01
    flap_rise_ratio: float = 2.0
    flap_min_radius_share: float = 0.5
    flap_max_turn_deg: float = 12.0
    #: a flap seen by the camera (a hand that holds too loosely to record a held path): one look
    #: once the site came each of ``flap_look_distances`` (m) out; the front's shift sloped at
    #: least ``flap_front_slope`` (m per m) up or down it, at most half that across it
    flap_look_distances: tuple = (0.08, 0.16)
    flap_front_slope: float = 0.1
    tilt_gain: float = 1.0
    #: pull this many degrees beyond the pull direction, in the sense of the turn
    pull_bias_deg: float = 0.0
    #: stop once the site came back toward the cabinet (+x) this far (m) from the farthest it got:
    #: the door is at its stop (or beyond 90 deg); pulling on would drag it shut. None: never
    back_stop: float | None = 0.03
    #: the back stop also for a pull about a hinge seen in depth? (off: past 90 degrees a door's
    #: handle comes back toward the cabinet along the circle the pull follows, which is the door
    #: opening on, not a door at its stop; the door's stop stalls the site instead)
    back_stop_with_hinge: bool = False
    #: with a hinge seen in depth: pull along the circle about it (the tangent at the grasp site,
    #: wherever the site slid to along a bar) when the handle is ``hinge_radius_range`` (m) from it;
    #: drop the hinge when, ``hinge_check_distance`` (m) into the pull, the handle moves the other
    #: way round by more than a quarter of ``hinge_disagree_deg``
    hinge_pull: bool = True
    hinge_radius_range: tuple = (0.12, 1.2)
    hinge_disagree_deg: float = 40.0
    hinge_check_distance: float = 0.03
    #: a hinge seen in the first image is checked by the camera once the site came each of
    #: ``hinge_look_distances`` (m) out: the front seen turning about a vertical axis is hinged
    #: where its shift toward the camera falls to zero; a line that far from the first one
    #: (``RecoveryConfig.hinge_agreement``) with the handle ``seen_hinge_radius`` (m) from it
    #: replaces it (:meth:`~opend_mj.policy.planner.pull.Pulling._hinge_looked`); a front seen
    #: more than ``hinge_look_slack`` (m) farther out at the handle than the hand came is not
    #: this door's. Empty distances: never
    hinge_look_distances: tuple = (0.05, 0.08)
    seen_hinge_radius: tuple = (0.08, 1.2)
    hinge_look_slack: float = 0.01
    #: the pull direction's turn (deg) from which the pull bias applies
    bias_after_deg: float = 1.0


@dataclass(frozen=True)
class RecoveryConfig:
    """When a grasp holds nothing or a grip is lost: back off and grasp again; a door lost after it
    started to open is pushed open from inside with the hand alone."""

    #: grasp tries per handle, and the time (s) one more try needs
    max_grasp_tries: int = 3
    attempt_time: float = 3.0
    #: back off this far (m) along the approach axis, after opening the fingers for ``open_time`` (s)
    backoff_distance: float = 0.06
    open_time: float = 0.25
    #: where the grip last held, go this much deeper (m) per try
    regrasp_deeper: float = 0.008
    #: with nothing held yet, the n-th re-grasp goes this far (m) along the approach axis from the
    #: first grasp (a thin bar seen in a few pixels may be nearer or farther than estimated)
    regrasp_offsets: tuple = (-0.012, 0.010)
    #: doors lost after opening at least ``push_min_turn`` (deg): push them open from inside
    push_recovery: bool = True
    push_min_turn: float = 8.0
    #: a push starts only with at least this much of the episode's time budget left (s): going
    #: round the free edge into the gap takes 2-4 s and the sweep several more; a push cut off by
    #: the budget leaves the hand inside the door's swing, where the next moves push the door back
    #: shut, and its moves overran the budget by up to 2 s
    push_min_time: float = 8.0
    #: the least number of held site positions a circle is fitted to
    push_min_track: int = 8
    #: a hinge fitted to the handle's path is believed when within ``hinge_agreement`` (m) of the
    #: one seen in depth and its radius is in ``push_radius_range`` (m)
    hinge_agreement: float = 0.12
    push_radius_range: tuple = (0.12, 1.2)
    #: the hand goes round the door's free edge ``push_clearance`` (m) beyond the handle's radius
    #: or the door's width seen in depth, whichever is larger,
    #: ``push_edge_deg`` ahead of the door, after stepping ``push_step_back`` (m) out of the cabinet;
    #: it enters the gap at ``push_entry_fraction`` of the door's angle, ``push_radius_fraction`` of
    #: the handle's radius from the hinge, at ``push_speed_factor`` times the approach speed, and
    #: sweeps the door to ``push_to_deg``
    push_clearance: float = 0.14
    push_edge_deg: float = 20.0
    push_step_back: float = 0.05
    push_entry_fraction: float = 0.45
    push_radius_fraction: float = 0.85
    push_speed_factor: float = 2.0
    push_to_deg: float = 125.0
    #: look before pushing: no push where too little of the door's front is seen moving, and the
    #: hand goes round the free edge ahead of the angle the front is seen turned where that is
    #: more than the held path's (``Planner.door_seen_turn``)
    push_look: bool = True
    #: a flap lost after opening at least ``flap_push_min_deg`` (deg) is pushed open by its inside
    #: to ``flap_push_to_deg`` (deg)
    flap_push_min_deg: float = 20.0
    flap_push_to_deg: float = 100.0


@dataclass(frozen=True)
class KindConfig:
    """The kind check (learned solvers only: the oracle's box is the named handle). Once the held
    handle travelled ``check_distance`` (m), its path and the front seen moving tell its kind; a
    handle of the other kind than the instruction's is pushed back, let go, and the solver asked
    again with what was seen (``solver.solve(..., observed=...)``)."""

    verify_kind: bool = True
    check_distance: float = 0.12
    #: the held path: the turn (deg, seen from above) between its first and last ``chord`` (m) at
    #: or above ``door_turn`` (up to ``door_turn_max``) or its tilt (deg, seen from the side) at or
    #: above ``door_tilt`` is a door's; turn at most ``drawer_turn`` and tilt at most
    #: ``drawer_tilt`` a drawer's. A turn above ``door_turn_max`` within ``check_distance`` is no
    #: door's (its hinge would be less than ~17 cm from the handle) but a hand sliding along its bar
    chord: float = 0.03
    door_turn: float = 8.0
    drawer_turn: float = 2.0
    door_tilt: float = 30.0
    drawer_tilt: float = 10.0
    door_turn_max: float = 30.0
    #: the kinds whose sighting by the path gives a handle up. Only "door" (a drawer was named, the
    #: handle swung): a hand sliding along a door's bar moves straight, so a path's "drawer" is
    #: only logged
    retry_on: tuple = ("door",)
    #: the front seen moving (:func:`~opend_mj.policy.perception.front_motion`): a front whose shift
    #: toward the camera grows across it, or up it (a flap hinged at its bottom edge), by
    #: ``front_door_slope`` (m per m: the tangent of its angle) or more turned about a hinge; one
    #: level within ``front_drawer_slope`` both ways that came ``front_drawer_shift`` (m) or more
    #: toward the camera slid out. A flap tips top first, so only an upward slope counts for a door
    front_door_slope: float = 0.1
    front_drawer_slope: float = 0.05
    front_drawer_shift: float = 0.05
    #: the kinds whose sighting by the front gives a handle up
    front_retry_on: tuple = ("drawer", "door")
    #: handles tried per episode (the first included), and the time (s) a new handle needs
    max_target_tries: int = 3
    retarget_time: float = 6.0
    #: a box where every grasp closed on nothing is given back to the solver grown by this many
    #: pixels on every side: the grasps tried there (and the depth snap of the box) cover about
    #: that much around it, so a proposal a pixel or two off it is the same empty place
    empty_margin: float = 3.0


@dataclass(frozen=True)
class PlannerConfig:
    """Everything the planner is set by, one section per stage (each a frozen dataclass).

    ``pull``: "arc" (a door's pull follows its handle's circle; drawers always go straight along
    -x) or "straight" (the paper's: every part pulled straight back along -x). ``min_time``: an
    episode lasts at least this long (s of simulated time); ``max_time``: the episode's time
    budget (s). ``release``: open the fingers and back off at the end. Change a field with
    :meth:`override` (``{"grasp.close_scale": 0.9}``)."""

    pull: str = "arc"
    min_time: float = 5.0
    max_time: float = 24.0
    release: bool = False
    locate: LocateConfig = field(default_factory=LocateConfig)
    perception: PerceptionConfig = field(default_factory=PerceptionConfig)
    approach: ApproachConfig = field(default_factory=ApproachConfig)
    grasp: GraspConfig = field(default_factory=GraspConfig)
    verify: VerifyConfig = field(default_factory=VerifyConfig)
    pulling: PullConfig = field(default_factory=PullConfig)
    door: DoorConfig = field(default_factory=DoorConfig)
    recovery: RecoveryConfig = field(default_factory=RecoveryConfig)
    kind: KindConfig = field(default_factory=KindConfig)

    def __post_init__(self) -> None:
        if self.pull not in ("arc", "straight"):
            raise ValueError(f"PlannerConfig.pull: {self.pull!r} is neither 'arc' nor 'straight'")

    def to_dict(self) -> dict:
        return asdict(self)

    def override(self, values: dict) -> "PlannerConfig":
        """A copy with ``values`` set: keys are field names of this class (``"pull"``) or
        ``"section.field"`` (``"grasp.close_scale"``, ``"perception.snap.margin_px"``)."""
        config = self
        for key, value in dict(values).items():
            config = _set_path(config, key.split("."), value, key)
        return config


def _set_path(obj, path: list[str], value, key: str):
    names = {f.name for f in dataclasses.fields(obj)}
    if path[0] not in names:
        raise KeyError(f"planner configuration: no field {key!r} ({type(obj).__name__} has "
                       f"{', '.join(sorted(names))})")
    if len(path) == 1:
        return replace(obj, **{path[0]: value})
    return replace(obj, **{path[0]: _set_path(getattr(obj, path[0]), path[1:], value, key)})
