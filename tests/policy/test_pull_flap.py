"""Flaps: doors hinged about a horizontal axis at their front's top edge (they lift) or bottom edge
(they drop). The pull stage alone on a flap whose bar stays in the hand only while the hand is
square to the flap (a hook or pinch twisted 30 degrees off the bar loses it), and the front's top
and bottom edges read from a depth image."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from opend_mj.policy.planner import GraspChoice, Observation, Planner, PlannerConfig, PlanResult, PullState
from opend_mj.policy.planner.records import Flap
from opend_mj.policy.solvers import get_solver
from opend_mj.sim.hands import load_spec
from opend_mj.transforms import axis_angle_quat, quat_axis_z

from .fake_robot import DT, HANDLE_SPEED, FakeRobot

START_Z = 0.5  # the handle's height when the flap is closed (m)


class HeldFlap(FakeRobot):
    """A robot whose grasp site holds a flap's bar: the handle on a circle of ``radius`` (m) in the
    x-z plane about a hinge ``radius`` above (``sign`` +1) or below (-1) it, opening toward -x up to
    ``travel`` (rad). Each step the handle goes to the point of its circle nearest the target; the
    grip holds while the hand's approach axis is within ``hold_deg`` of the flap's inward normal,
    and once lost stays lost (the hand then moves freely)."""

    def __init__(self, sign: float, radius: float, travel: float, hold_deg: float = 30.0):
        super().__init__()
        self.sign, self.radius, self.travel, self.hold_deg = sign, radius, travel, hold_deg
        self.hinge_z = START_Z + sign * radius
        self.opening = 0.0

    def handle_pos(self) -> np.ndarray:
        a = self.opening
        return np.array([-0.03 - self.radius * math.sin(a), 0.0, self.hinge_z - self.sign * self.radius * math.cos(a)])

    def follow(self, p, site_quat, fingers) -> None:
        a = self.opening
        inward = np.array([math.cos(a), 0.0, -self.sign * math.sin(a)])  # into the flap's front
        if math.degrees(math.acos(np.clip(quat_axis_z(site_quat) @ inward, -1.0, 1.0))) > self.hold_deg:
            self.let_go(self.handle_pos())  # the bar twisted out of the hand
            return
        want = math.atan2(-0.03 - p[0], self.sign * (self.hinge_z - p[2]))
        self.opening = self.moved(a, want, self.travel, HANDLE_SPEED * DT / self.radius)


def _pull_flap(part: HeldFlap, config: PlannerConfig, front_z: tuple) -> float:
    """The pull stage on ``part`` from a closed start, the front's top and bottom edges seen at
    ``front_z`` (m); returns how far it opened (the fraction of its range)."""
    planner = Planner(get_solver("oracle", ground_truth=lambda: None), load_spec("allegro"), config)
    quat = axis_angle_quat((0.0, 1.0, 0.0), math.pi / 2)  # approach axis +x
    g = GraspChoice("hook", "horizontal", quat, part.site_pos(), np.zeros(16), np.zeros(16))
    state = PullState(quat0=quat, front_z=front_z)
    result = PlanResult(stage_reached="pull", failed_stage=None)
    planner.pulling.pull(part, g, True, state, result)
    return part.opening / part.travel


@pytest.mark.parametrize("sign, radius, travel_deg", [(1.0, 0.4, 100.0), (1.0, 0.23, 90.0), (-1.0, 0.85, 90.0),
                                                      (-1.0, 0.65, 114.0)])
def test_a_flap_is_pulled_along_its_circle_to_its_stop(sign, radius, travel_deg):
    """Flaps of the real set's kinds (hinged at the top 0.23-0.6 m above their bar, at the bottom
    0.65-0.87 m below it, opening 90-114 degrees) open to 85 % of their range or more: the held bar
    rises (or sinks) as a circle about the front's far edge predicts, so the pull follows that
    circle and the hand pitches with the flap. Pulled as a side door is (straight out, the hand
    level), the bar twists out of the hand before the flap is half open."""
    edges = (START_Z + radius + 0.01, START_Z - 0.05) if sign > 0 else (START_Z + 0.05, START_Z - radius - 0.01)
    travel = math.radians(travel_deg)
    assert _pull_flap(HeldFlap(sign, radius, travel), PlannerConfig(), edges) >= 0.85
    side_door = PlannerConfig().override({"door.flap_pull": False})
    assert _pull_flap(HeldFlap(sign, radius, travel), side_door, edges) < 0.5


def test_a_flap_whose_front_reaches_past_its_hinge_is_pulled_on_its_own_circle():
    """The front seen in depth may continue past the flap's hinge (a coplanar front above it): the
    edge bounds the radius, and the held path's own circle sets it within that bound."""
    travel = math.radians(100.0)
    assert _pull_flap(HeldFlap(1.0, 0.4, travel), PlannerConfig(), (START_Z + 0.55, START_Z - 0.05)) >= 0.85


def test_no_flap_where_the_front_has_no_edge_for_its_hinge():
    """A handle that sinks while the front ends just below it (less than the least believed hinge
    radius) is no flap hinged below: the pull stays a side door's."""
    part = HeldFlap(-1.0, 0.85, math.radians(90.0))
    planner = Planner(get_solver("oracle", ground_truth=lambda: None), load_spec("allegro"), PlannerConfig())
    quat = axis_angle_quat((0.0, 1.0, 0.0), math.pi / 2)
    g = GraspChoice("hook", "horizontal", quat, part.site_pos(), np.zeros(16), np.zeros(16))
    state = PullState(quat0=quat, front_z=(START_Z + 0.4, START_Z - 0.05))
    result = PlanResult(stage_reached="pull", failed_stage=None)
    planner.pulling.pull(part, g, True, state, result)
    assert state.flap is None and not any("flap" in e for e in result.events)


def _forward_view():
    """A 256 px camera (fovy 45 degrees) at the origin looking along +x (columns: right = -y, up = +z)."""
    from opend_mj.sim.camera import CameraIntrinsics, CameraView

    rot = np.column_stack([(0, -1, 0), (0, 0, 1), (-1, 0, 0)]).astype(float)
    return CameraView(CameraIntrinsics.from_fovy(45, 256, 256), np.zeros(3), rot)


@pytest.mark.parametrize("handle_z", [-0.25, 0.2])
def test_the_fronts_top_and_bottom_edges_from_depth(handle_z):
    """A synthetic front 1 m away spanning z in [-0.3, 0.3], with a horizontal bar 4 cm proud of it:
    the plane's edges above and below the bar are found within a pixel (about 3 mm here)."""
    from opend_mj.policy.perception import HandleEstimate, door_edges_vertical

    view = _forward_view()
    cols, rows = np.meshgrid(np.arange(256) + 0.5, np.arange(256) + 0.5)
    on_plane = view.backproject(cols.ravel(), rows.ravel(), np.ones(cols.size))  # points at depth 1
    inside = (np.abs(on_plane[:, 1]) < 0.3) & (on_plane[:, 2] > -0.3) & (on_plane[:, 2] < 0.3)
    depth = np.where(inside, 1.0, 2.5)
    on_bar = (np.abs(on_plane[:, 1]) < 0.1) & (np.abs(on_plane[:, 2] - handle_z) < 0.008)
    depth = np.where(on_bar, 0.96, depth).reshape(256, 256)
    handle = HandleEstimate(centre=np.array([0.965, 0.0, handle_z]), orientation="horizontal", kind="bar",
                            size=(0.2, 0.016), front_x=0.96, panel_x=1.0)
    top, bottom = door_edges_vertical(handle, depth, view)
    assert top == pytest.approx(0.3, abs=0.004) and bottom == pytest.approx(-0.3, abs=0.004)


class LooseFlap(HeldFlap):
    """A flap hooked by fingers that feel nothing (the Allegro's loose hook on a thin bar): the hand
    touches only with its palm, which is no hold, so no held path is recorded; the robot can look
    again. The closed front is a plane at
    x = ``PANEL_X`` spanning y in [-0.3, 0.3] and z from the handle's edge to the hinge's, seen by a
    camera at (0, 0, ``START_Z``) looking along +x."""

    def __init__(self, sign: float, radius: float, travel: float):
        super().__init__(sign, radius, travel)
        self.x0 = PANEL_X - 0.035  # the bar's centre, 3.5 cm in front of the panel

    def handle_pos(self) -> np.ndarray:
        a = self.opening
        return np.array([self.x0 - self.radius * math.sin(a), 0.0,
                         self.hinge_z - self.sign * self.radius * math.cos(a)])

    def step(self, site_pos, site_quat, fingers) -> None:
        p = np.asarray(site_pos, float)
        super().step(p - np.array([self.x0 + 0.03, 0.0, 0.0]), site_quat, fingers)  # the parent's frame

    def touch(self) -> dict:
        return {"palm": 5.0}

    def look(self) -> np.ndarray:
        return _flap_depth(self.sign, self.radius, self.opening)


PANEL_X = 1.0


def _flap_view():
    from opend_mj.sim.camera import CameraIntrinsics, CameraView

    rot = np.column_stack([(0, -1, 0), (0, 0, 1), (-1, 0, 0)]).astype(float)
    return CameraView(CameraIntrinsics.from_fovy(45, 256, 256), np.array([0.0, 0.0, START_Z]), rot)


def _flap_depth(sign: float, radius: float, opening: float) -> np.ndarray:
    """Depth (along +x) of a flap turned ``opening`` (rad) about its hinge line (x = ``PANEL_X``,
    z = ``START_Z`` + sign x radius, along y), its free edge 5 cm beyond the handle, in front of a
    far wall."""
    view = _flap_view()
    cols, rows = np.meshgrid(np.arange(256) + 0.5, np.arange(256) + 0.5)
    ray = view.backproject(cols.ravel(), rows.ravel(), np.ones(cols.size)) - view.pos  # x = 1 per ray
    hinge_z = START_Z + sign * radius
    # points of the flap: x = PANEL_X - s sin(a), z = hinge_z - sign s cos(a) for s in [0, radius + 0.05]
    t_a = math.tan(opening)
    # on the ray x = t, z = START_Z + ray_z t; the flap's plane: (PANEL_X - x) cos a = sign (hinge_z - z) sin a
    num = PANEL_X * math.cos(opening) - sign * (hinge_z - START_Z) * math.sin(opening)
    den = math.cos(opening) - sign * ray[:, 2] * math.sin(opening)
    t = num / den
    z = START_Z + ray[:, 2] * t
    s = np.abs(hinge_z - z) / max(math.cos(opening), 1e-6) if t_a < 1e3 else np.zeros_like(z)
    on = (np.abs(ray[:, 1] * t) < 0.3) & (s <= radius + 0.05) & (sign * (hinge_z - z) >= 0) & (t > 0)
    depth = np.where(on, t, 2.5)
    bar = on & (np.abs(ray[:, 1] * t) < 0.1) & (np.abs(s - radius) < 0.008) & (opening == 0.0)
    depth = np.where(bar, PANEL_X - 0.04, depth)
    return depth.reshape(256, 256)


def _pull_loose_flap(sign: float, radius: float, config: PlannerConfig) -> tuple[float, list]:
    """The Allegro's pull stage on a :class:`LooseFlap` turning up to 95 degrees, the robot able to
    look again: (the fraction of its travel it opened, the planner's events)."""
    from opend_mj.policy.perception import HandleEstimate

    part = LooseFlap(sign, radius, math.radians(95.0))
    planner = Planner(get_solver("oracle", ground_truth=lambda: None), load_spec("allegro"), config)
    planner.state.handle = HandleEstimate(centre=part.handle_pos(), orientation="horizontal", kind="bar",
                                          size=(0.2, 0.016), front_x=PANEL_X - 0.04, panel_x=PANEL_X)
    planner.state.first = Observation(rgb=None, depth=part.look(), instruction="door", camera_view=_flap_view())
    quat = axis_angle_quat((0.0, 1.0, 0.0), math.pi / 2)
    g = GraspChoice("hook", "horizontal", quat, part.site_pos(), np.zeros(16), np.zeros(16))
    result = PlanResult(stage_reached="pull", failed_stage=None)
    planner.pulling.pull(part, g, True, PullState(quat0=quat), result)
    return part.opening / part.travel, result.events


@pytest.mark.parametrize("sign, radius", [(1.0, 0.4), (-1.0, 0.6)])
def test_a_flap_held_without_touch_is_seen_by_the_camera(sign, radius):
    """A hand that feels nothing records no held path; one look, 8 cm into the pull, shows the
    front's shift growing down it (a flap hinged at its top) or up it (at its bottom), and the flap
    is then pulled along its circle to its stop. Without the look it is pulled as a side door is,
    and the bar twists out of the hand before the flap is half open."""
    opened, events = _pull_loose_flap(sign, radius, PlannerConfig())
    seen = [e["flap"] for e in events if "flap" in e]
    assert seen and seen[0]["hinge"] == ("top" if sign > 0 else "bottom"), events
    assert opened >= 0.85, events
    assert _pull_loose_flap(sign, radius, PlannerConfig().override({"door.flap_pull": False}))[0] < 0.5




def _first_flap(hinge: str) -> tuple[int, str, str]:
    """(index, id, joint) of the first generated flap (seed 0) hinged at its ``hinge`` edge."""
    from opend_mj.assets.procedural import find_cabinets

    (cabinet,) = find_cabinets(lambda c: any(t.hinge == hinge for t in c.targets))
    return cabinet.index, cabinet.id, f"joint_{[t.hinge for t in cabinet.targets].index(hinge)}"


PROCEDURAL_FLAPS = [_first_flap("top"), _first_flap("bottom")]


@pytest.mark.slow
@pytest.mark.parametrize("index, cid, joint", PROCEDURAL_FLAPS, ids=["top-hinged", "bottom-hinged"])
def test_a_procedural_flap_opens_with_the_planner(tmp_path, index, cid, joint):
    """A whole episode in the Task: the oracle planner opens a generated flap (lifting one hinged at
    its top, lowering one hinged at its bottom) past 75 % of its range, by contact alone."""
    from opend_mj.assets.compiler import compile_cabinet
    from opend_mj.assets.procedural import generate_source
    from opend_mj.evaluation.episode import EpisodeJob
    from opend_mj.evaluation.runner import run_episode

    src = generate_source(index, 0, tmp_path / "src")
    compile_cabinet(src, tmp_path / "built", cache_dir=tmp_path / "cache")
    cab = tmp_path / "built" / cid
    target = next(t for t in json.loads((cab / "cabinet.json").read_text())["targets"] if t["joint"] == joint)
    assert abs(target["axis"][2]) < 0.1, target["axis"]  # a horizontal hinge: a flap
    side_door = []
    for hand in ("skeleton", "franka"):
        job = EpisodeJob(cabinet=cid, cabinet_dir=str(cab), joint=joint, split="test", hand=hand, solver="oracle")
        rec = run_episode(job)
        assert "error" not in rec, rec.get("error")
        assert rec["target_type"] == "door" and rec["success"] and rec["range_ratio"] >= 0.75, (hand, rec)
        old = run_episode(replace(job, planner_overrides=(("door.flap_pull", False),)))
        side_door.append(old["success"] and old["range_ratio"] >= 0.75)
    assert not all(side_door)  # pulled as a side door, not both hands open it this far


@pytest.mark.parametrize("sign", [1.0, -1.0])
@pytest.mark.parametrize("radius", [0.4, 0.3])
def test_a_lost_flaps_swing_is_read_from_its_held_path_not_from_the_hands_pitch(sign, radius):
    """A flap held up to 50 degrees (hinged at its top or bottom), whose hand pitched on to 85
    before the lost grip was noticed: it swung 50 degrees, read on the circle about the front's far
    edge (40 cm from the handle), and never more where its own hinge is nearer (the flap is pushed
    on, not taken as open)."""
    from opend_mj.policy.planner.records import Flap

    planner = Planner(get_solver("oracle", ground_truth=lambda: None), load_spec("allegro"))
    start = np.array([-0.03, 0.0, START_Z])
    state = PullState(quat0=np.array([1.0, 0.0, 0.0, 0.0]), peak_tilt=85.0 * sign)
    state.flap = Flap(start=start, out=np.array([-1.0, 0.0, 0.0]), sign=sign, reach=0.4)
    state.track = [start + radius * np.array([-math.sin(a), 0.0, sign * (1.0 - math.cos(a))])
                   for a in np.radians(np.linspace(0.0, 50.0, 11))]
    swung = planner.recovery.swung(state)
    assert state.swung() == 85.0
    assert (swung == pytest.approx(50.0, abs=0.1)) if radius == 0.4 else 30.0 < swung < 50.0
    state.flap = None
    assert planner.recovery.swung(state) == 85.0


#: flaps whose bar the Allegro's fingers lose part way: one hinged at its top edge 43 cm above its bar
#: (at 55-65 degrees), one hinged at its bottom edge 64 cm below it (at 40-50 degrees)
LOST_FLAPS = [("46166", "joint_2"), ("47024", "joint_0")]


@pytest.mark.slow
@pytest.mark.parametrize("target", LOST_FLAPS, ids=["top-hinged", "bottom-hinged"])
def test_a_real_flap_lost_part_way_is_pushed_open_by_its_inside(real_episode, target):
    """A flap the hand lost part way stays where it was let go; the hand goes round its free edge
    and pushes it by its inside past 75 % of its range, by contact alone. Without the push it
    stays short."""
    rec = real_episode(*target, "allegro")
    assert rec["pushed"] and rec["success"] and rec["range_ratio"] >= 0.75, rec
    assert rec["others_moved"] == []
    held = real_episode(*target, "allegro", overrides=(("recovery.flap_push_min_deg", 180.0),))
    assert not held["pushed"] and 0.2 < held["range_ratio"] < 0.75, held


def test_a_tall_flap_is_seen_at_the_second_look():
    """A drop-down front hinged 85 cm below its handle has turned only 5-6 degrees when the hand
    came 8 cm out, too little for the first look; the second, at 16 cm, sees it and the flap is pulled
    along its circle. With one look only it is not seen as a flap."""

    def flaps_seen(config):
        return [e["flap"] for e in _pull_loose_flap(-1.0, 0.85, config)[1] if "flap" in e]

    seen = flaps_seen(PlannerConfig())
    assert seen and seen[0]["hinge"] == "bottom" and seen[0]["out"] >= 0.15, seen
    assert not flaps_seen(PlannerConfig().override({"door.flap_look_distances": (0.08,)}))


@pytest.mark.parametrize("sign", [1.0, -1.0], ids=["top-hinged", "bottom-hinged"])
def test_fingers_on_a_flaps_bar_press_down_its_front_as_it_turns(sign):
    """Fingers resting on a flap's bar from above press along its front, the way its bar's top
    faces: straight down while it is closed, turned with it as it opens (a press straight down
    would hold a lifting flap back and stall it part way)."""
    planner = Planner(get_solver("oracle", ground_truth=lambda: None), load_spec("franka"), PlannerConfig())
    start, reach = np.array([-0.3, 0.0, START_Z]), 0.4
    state = PullState(quat0=np.array([1.0, 0.0, 0.0, 0.0]))
    state.flap = Flap(start=start, out=np.array([-1.0, 0.0, 0.0]), sign=sign, reach=reach)
    assert planner.flap.press_direction(start, state) == pytest.approx([0.0, 0.0, -1.0])
    a = math.radians(30.0)
    hinge = start + np.array([0.0, 0.0, sign * reach])
    site = hinge + reach * np.array([-math.sin(a), 0.0, -sign * math.cos(a)])  # the bar, 30 degrees open
    down_front = np.array([-math.sin(a), 0.0, -math.cos(a)]) if sign > 0 else np.array([math.sin(a), 0.0, -math.cos(a)])
    assert planner.flap.press_direction(site, state) == pytest.approx(down_front)


#: wide flaps hinged at their top, a low bar the gripper can only take from above (pressed on its
#: top): 38 cm and 58 cm below hinges that sit below the front's top edge
PRESSED_FLAPS = [("45915", "joint_1"), ("45922", "joint_1")]


@pytest.mark.slow
@pytest.mark.parametrize("target", PRESSED_FLAPS, ids=["38cm", "58cm"])
def test_a_real_flap_pressed_from_above_opens_past_three_quarters(real_episode, target):
    """The Franka's fingers on a low bar's top drag a wide top-hinged flap open by friction along
    its circle, pressing down the front as it lifts, to more than 75 % of its range."""
    rec = real_episode(*target, "franka")
    assert rec["grasp_style"] == "press_down" and rec["success"] and rec["range_ratio"] >= 0.75, rec
    assert rec["others_moved"] == []
