"""A hand's planner settings, the files beside its model in ``hands/<name>/``.

* ``grasp.json`` (:class:`GraspProfile`, written by ``opend search-grasp``): how far the fingers
  close, how deep the grasp goes, how a knob is grasped.
* ``planner.json`` (:class:`HandPlannerConfig`): the numbers of the planner that differ from hand
  to hand (a low handle's lift and pitch, the lowest grasp site, when a bar is pinched, how many
  fingers make a hold, when a gripper's grip is lost).

Both loaders refuse what they do not know: an unknown key or a value of the wrong type is an error
that names the file and the key (keys starting with ``_`` are notes for people and are skipped).
Pure Python: the planner reads these through :class:`~opend_mj.sim.hands.HandModel`.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

GRASP_FILE = "grasp.json"
PLANNER_FILE = "planner.json"


def read_json_object(path: Path, what: str) -> dict:
    """The JSON object in ``path``; a clear error naming the file where it is not one."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path}: cannot read the hand's {what}: {exc}") from exc
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a JSON object of the hand's {what}")
    return data


def _number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


@dataclass
class GraspProfile:
    """A hand's grasp tuning (``hands/<name>/grasp.json``, written by ``opend search-grasp``).

    ``close_scale``: how far the fingers close, as a fraction of the way from the pre-grasp to the
    spec's grasp profile; ``grasp_depth``: metres beyond the handle's estimated centre along the
    approach axis, per handle kind ("bar", "knob"); ``knob_orientation``: the finger orientation
    for knobs ("horizontal" | "vertical"); ``search``: the settings the search tried; ``note``:
    free text for people."""

    hand: str
    close_scale: float = 1.0
    grasp_depth: dict = field(default_factory=lambda: {"bar": 0.0, "knob": 0.0})
    knob_orientation: str = "horizontal"
    search: list = field(default_factory=list)
    note: str = ""

    @classmethod
    def load(cls, path: Path) -> "GraspProfile":
        """Read ``path``; a clear error naming the file for unknown keys or wrong types."""
        path = Path(path)
        data = read_json_object(path, "grasp settings")
        fields = {f.name for f in dataclasses.fields(cls)}
        values = {}
        for key, value in data.items():
            if key.startswith("_"):
                continue
            if key not in fields:
                raise ValueError(f"{path}: unknown key {key!r} (known: {', '.join(sorted(fields))})")
            values[key] = value
        if not isinstance(values.get("hand"), str):
            raise ValueError(f"{path}: 'hand' must name the hand, got {values.get('hand')!r}")
        if "close_scale" in values and not (_number(values["close_scale"]) and 0 < values["close_scale"] <= 2):
            raise ValueError(f"{path}: 'close_scale' must be a number in (0, 2], got {values['close_scale']!r}")
        depth = values.get("grasp_depth", {})
        if not (isinstance(depth, dict) and all(isinstance(k, str) and _number(v) and abs(v) < 0.1
                                                for k, v in depth.items())):
            raise ValueError(f"{path}: 'grasp_depth' must map handle kinds to metres (|depth| < 0.1), got {depth!r}")
        if values.get("knob_orientation", "horizontal") not in ("horizontal", "vertical"):
            raise ValueError(f"{path}: 'knob_orientation' must be 'horizontal' or 'vertical', "
                             f"got {values['knob_orientation']!r}")
        if not isinstance(values.get("search", []), list) or not isinstance(values.get("note", ""), str):
            raise ValueError(f"{path}: 'search' must be a list and 'note' a string")
        return cls(**values)

    def save(self, path: Path) -> Path:
        path = Path(path)
        path.write_text(json.dumps(asdict(self), indent=2) + "\n")
        return path

    def apply(self, config):
        """``config`` (a :class:`~opend_mj.policy.planner.PlannerConfig`) with this profile's
        finger closing, grasp depth and knob orientation."""
        return config.override({"grasp.close_scale": self.close_scale, "grasp.depth": dict(self.grasp_depth),
                                "grasp.knob_orientation": self.knob_orientation})


@dataclass(frozen=True)
class HandPlannerConfig:
    """The planner's numbers for one hand (``hands/<name>/planner.json``).

    ``low_handle_lift`` (m): for a handle lower than ``GraspConfig.low_handle_height``, the grasp
    site goes this much above the handle's centre, so that open fingers pointing down clear the
    floor on the way in and close over the bar from above. ``min_grasp_height`` (m above the
    floor, or None): the lowest grasp site (fingers that point down behind a bar strike the floor
    below it). ``low_handle_pitch`` (deg): a low horizontal bar is approached pitched down by this
    much, from above and in front (a body wide along the finger axis clears the floor below and the
    door behind). ``pinch_gap`` (m): a bar whose stand-off gap is below this is pinched rather than
    hooked. ``hold_parts``: the hand holds when at least this many of its parts (fingers, the
    thumb; not the palm) press on something. ``grip_lost_change`` (the finger joints' unit: m for
    a gripper's slides, or None): the grip is lost, and the pull stops, when a finger joint moved
    this much from where it closed on the handle (only for fingers that do not move while they
    hold).

    ``clearance_margin`` (m, or None: no check): the open hand at its grasp pose "clears" when
    its collision geoms stay this far above the floor and in front of the panel behind the handle
    (:mod:`.clearance`). Where it does not: ``clearance_knob_turn``: a knob is grasped with the
    hand turned a quarter about the approach axis (the other finger orientation) where that pose
    keeps more room to the floor and the panel (the smaller of the two); ``clearance_pitches`` (deg, tried in order): a horizontal handle is approached pitched
    down by the first of these (90 = straight down) at which the hand clears, a gripper's fingers
    opened as little as the bar's half thickness plus ``clearance_bar_margin`` (m).

    ``hook_down_pitches`` (deg below the horizontal, tried in order; empty: never): a horizontal
    bar near the floor whose grasp pose does not clear (above) is hooked from above instead: the
    hand points down into the stand-off gap behind the bar, its fingers closed into one hook
    ``hook_down_width`` (m thick across the bar) and lowered ``hook_down_depth`` (m) below the
    bar's centre, and pulls the bar out by the back of its fingers (a gripper's body, 20 cm long
    across a bar, fits neither under a bar 3-6 cm above the floor nor behind it). Of the pitches
    at which the closed fingers fit the gap with ``hook_down_margin`` (m) each side and the hand
    clears the floor and the panel, the one that puts the fingers farthest behind the bar is taken.
    ``press_depth`` (m; 0: never): where the gap behind such a bar is too narrow for the closed
    fingers, the same pose comes down on the bar's top instead and presses this far below it
    (the grasp style "press_down"): the friction of that press, not a hook, pulls the bar out.
    Hooks are preferred over presses. ``floor_give`` (m): how far the open fingers of a grasp pose
    may reach below the floor and still close on the bar (they bend back and slide on it); only a
    pose that reaches deeper counts as near the floor for the hook or press from above.

    ``flap_min_radius_share`` (or None: ``DoorConfig.flap_min_radius_share``): the least radius of a
    flap's circle, as a share of the distance from the handle to the front's far edge seen in depth
    (the flap pull, :mod:`opend_mj.policy.planner.flap`). A gripper pitched at a low bar
    holds it between two flat pads that let it roll along them as the flap lifts, so the held path
    rises faster than the bar and its own circle comes out too small: the hand then pitches ahead of
    the flap and twists the bar out of its pads.

    ``yaw_rate`` (deg/s, or None: at once): during a door's pull the hand's yaw follows the pull
    direction's turn at most this fast (the pull, :mod:`opend_mj.policy.planner.pull`);
    the direction itself changes at once. Where the hinge the pull turns about is replaced by the
    one the camera sees turning, the direction turns by tens of degrees in one control step; a
    gripper yawed as fast twists the bar out of its pads.

    ``hook_slide`` (m): a hooked door bar is grasped this far out along the fingers from the grasp site
    (the hand moves back along its finger axis), so that the bar lies at the fingers' middle
    segments and their curl closes behind it; at the site (the proximal segments) a thin bar close
    to its door is passed over by the curl, whose tips then press on the panel. No slide toward a
    neighbour seen beside the bar (``GraspConfig.neighbour_clear``)."""

    low_handle_lift: float = 0.0
    min_grasp_height: float | None = None
    low_handle_pitch: float = 0.0
    pinch_gap: float = 0.0
    hold_parts: int = 1
    grip_lost_change: float | None = None
    clearance_margin: float | None = None
    clearance_knob_turn: bool = False
    clearance_pitches: tuple = ()
    clearance_bar_margin: float = 0.004
    hook_slide: float = 0.0
    hook_down_pitches: tuple = ()
    hook_down_width: float = 0.0
    hook_down_depth: float = 0.005
    hook_down_margin: float = 0.001
    press_depth: float = 0.0
    floor_give: float = 0.0
    flap_min_radius_share: float | None = None
    yaw_rate: float | None = None

    @classmethod
    def for_type(cls, hand_type: str) -> "HandPlannerConfig":
        """The numbers for a hand without a ``planner.json``, by its type."""
        return HAND_TYPE_DEFAULTS.get(hand_type, cls())

    @classmethod
    def load(cls, path: Path) -> "HandPlannerConfig":
        """Read ``path``; a clear error naming the file for unknown fields or wrong types."""
        path = Path(path)
        data = read_json_object(path, "planner numbers")
        fields = {f.name: f for f in dataclasses.fields(cls)}
        values = {}
        for key, value in data.items():
            if key.startswith("_"):  # "_doc" and the like: notes for people
                continue
            if key not in fields:
                raise ValueError(f"{path}: unknown key {key!r} (known: {', '.join(fields)})")
            if key == "clearance_knob_turn":
                if not isinstance(value, bool):
                    raise ValueError(f"{path}: {key!r} must be true or false, got {value!r}")
                values[key] = value
                continue
            if key in ("clearance_pitches", "hook_down_pitches"):
                ok = isinstance(value, list) and all(
                    isinstance(v, (int, float)) and not isinstance(v, bool) and 0 <= v <= 90 for v in value)
                if not ok:
                    raise ValueError(f"{path}: {key!r} must be a list of degrees in [0, 90], got {value!r}")
                values[key] = tuple(float(v) for v in value)
                continue
            optional = key in ("min_grasp_height", "grip_lost_change", "clearance_margin", "flap_min_radius_share",
                                "yaw_rate")
            if value is None and optional:
                values[key] = None
                continue
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ValueError(f"{path}: {key!r} must be a number{' or null' if optional else ''}, got {value!r}")
            if key == "hold_parts" and not (isinstance(value, int) and value >= 1):
                raise ValueError(f"{path}: 'hold_parts' must be a whole number of at least 1, got {value!r}")
            values[key] = int(value) if key == "hold_parts" else float(value)
        return cls(**values)

    def to_dict(self) -> dict:
        return asdict(self)


#: A hand without a ``planner.json``: a dexterous hand pinches a bar closer than 12 mm to its
#: panel (its fingers cannot get behind it) and holds with one part; a parallel gripper closes
#: across every bar, holds with both fingers, and has lost its grip when a finger moved 12 mm.
HAND_TYPE_DEFAULTS = {
    "dexterous": HandPlannerConfig(pinch_gap=0.012, hold_parts=1),
    "parallel_gripper": HandPlannerConfig(pinch_gap=0.0, hold_parts=2, grip_lost_change=0.012),
}
