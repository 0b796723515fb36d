"""The Franka gripper's door pulls: the hand's yaw turned at a bounded rate, a flap's circle taken at
the far edge's reach, a low bar hooked at a steeper pitch where that clears, and the numbers in
``hands/franka/planner.json`` that turn them on (every other hand keeps the defaults: off).

- ``yaw_rate`` (deg/s): where the hinge the pull turns about is replaced by the one the camera sees
  turning, the pull direction turns by tens of degrees in one control step. A gripper's pads hold a
  bar by friction on two flat faces; yawed by as much at once, they twist off it.
- ``flap_min_radius_share``: the flap's circle is the held path's own, bounded below by this share of
  the far edge's distance; a pitched gripper's held path rises faster than the bar (the bar rolls
  along its pads), so for the Franka the bound is the far edge's distance itself.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from opend_mj.policy.planner import GraspChoice, Observation, Planner, PlannerConfig, PlanResult, PullState
from opend_mj.sim.hands import HandPlannerConfig
from opend_mj.policy.planner.records import Flap
from opend_mj.policy.solvers import get_solver
from opend_mj.sim.hands import HANDS_DIR, get_hand, load_spec
from opend_mj.transforms import axis_angle_quat, quat_axis_z

from .test_pull_door_hinge import PANEL_X, PROUD, SeenDoor, _view



class PadDoor(SeenDoor):
    """A :class:`SeenDoor` held between a gripper's pads: the grip is lost (for good) where the hand's
    approach axis turns more than ``twist_deg`` (deg) about z in one control step (the pads twist off
    the bar), besides ``hold_deg`` off the door's normal. Records the hand's yaw (deg) each step."""

    twist_deg = 5.0

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.yaws: list[float] = []

    def step(self, site_pos, site_quat, fingers) -> None:
        axis = quat_axis_z(site_quat)
        yaw = math.degrees(math.atan2(axis[1], axis[0]))
        if self.held and self.yaws and abs(math.remainder(yaw - self.yaws[-1], 360.0)) > self.twist_deg:
            self.n_steps += 1
            self.let_go(site_pos)
            return
        self.yaws.append(yaw)
        super().step(site_pos, site_quat, fingers)


def _pull(part: PadDoor, hand: HandPlannerConfig, hinge: tuple) -> tuple[float, list]:
    """The pull stage alone on ``part`` from a closed start, the hinge seen in the first image at
    ``hinge`` (world x, y): (the fraction of its travel it opened, the planner's events)."""
    from opend_mj.policy.perception import HandleEstimate

    planner = Planner(get_solver("oracle", ground_truth=lambda: None), load_spec("allegro"), PlannerConfig(), numbers=hand)
    planner.state.hinge = np.asarray(hinge, float)
    planner.state.handle = HandleEstimate(centre=part.handle_pos(), orientation="horizontal", kind="bar",
                                          size=(0.1, 0.008), front_x=PANEL_X - PROUD - 0.004, panel_x=PANEL_X)
    planner.state.first = Observation(rgb=None, depth=part.look(), instruction="door", camera_view=_view())
    quat = axis_angle_quat((0.0, 1.0, 0.0), math.pi / 2)  # approach axis +x
    g = GraspChoice("hook", "horizontal", quat, part.site_pos(), np.zeros(16), np.zeros(16))
    result = PlanResult(stage_reached="pull", failed_stage=None)
    planner.pulling.pull(part, g, True, PullState(quat0=quat), result)
    return part.opening / part.travel, result.events


@pytest.mark.parametrize("hinge_y", [-0.3, 0.3])
def test_a_replaced_hinge_turns_the_hand_at_the_bounded_rate(hinge_y):
    """A door 34 cm wide, its bar 30 cm from the hinge, the hinge seen in the first image 60 cm away on
    the other side of the handle: the camera replaces it 5 cm into the pull and the pull direction
    turns by 10 degrees or more at once. With ``yaw_rate`` 30 deg/s the hand's yaw follows it at most
    0.5 degrees a control step and the pads keep the bar to the door's stop; at once, the pads twist
    off the bar where the hinge is replaced."""
    door = dict(radius=0.3, hinge_y=hinge_y, travel=math.radians(60), slides=True)
    wrong = (PANEL_X, -np.sign(hinge_y) * 0.6)
    bounded = PadDoor(**door)
    opened, events = _pull(bounded, HandPlannerConfig(yaw_rate=30.0), wrong)
    assert any("hinge_seen_turning" in e for e in events), events
    steps = np.abs(np.diff(bounded.yaws))
    assert steps.max() <= 30.0 / 60.0 + 1e-6, steps.max()
    assert bounded.held and opened >= 0.9, (opened, events)
    at_once = PadDoor(**door)
    opened, events = _pull(at_once, HandPlannerConfig(), wrong)
    assert any("hinge_seen_turning" in e for e in events), events
    assert not at_once.held and opened < 0.5, (opened, events)


def test_a_flap_circle_is_at_least_the_hands_share_of_the_far_edge():
    """A held path that rose along a circle of 20 cm while the front's far edge is 45 cm above the
    handle: the default bound (half the reach) lets the circle shrink to 22.5 cm; the Franka's share
    (1.0) keeps it at the reach."""
    r, reach = 0.2, 0.45
    angles = np.linspace(0.0, 0.4, 20)
    track = [np.array([-r * math.sin(a), 0.0, r - r * math.cos(a)]) for a in angles]  # out along -x, rising
    flap = Flap(start=np.zeros(3), out=np.array([-1.0, 0.0, 0.0]), sign=1.0, reach=reach)
    spec = load_spec("franka")
    radii = []
    for hand in (HandPlannerConfig(), HandPlannerConfig(flap_min_radius_share=1.0)):
        planner = Planner(get_solver("oracle", ground_truth=lambda: None), spec, PlannerConfig(), numbers=hand)
        radii.append(planner.flap.radius(flap, PullState(quat0=np.array([1.0, 0.0, 0.0, 0.0]), track=track)))
    assert radii[0] == pytest.approx(PlannerConfig().door.flap_min_radius_share * reach, abs=1e-6)
    assert radii[1] == pytest.approx(reach, abs=1e-6)


def test_the_franka_turns_them_on_and_the_other_hands_do_not():
    """``hands/franka/planner.json`` bounds the yaw rate, takes the flap's reach and searches steeper
    pitches for low bars; the other hands keep the defaults (off)."""
    franka = HandPlannerConfig.load(HANDS_DIR / "franka" / "planner.json")
    assert franka.yaw_rate is not None and franka.yaw_rate > 0
    assert franka.flap_min_radius_share == 1.0
    assert franka.clearance_pitches and min(franka.clearance_pitches) > franka.low_handle_pitch
    for name in ("allegro", "shadow", "skeleton"):
        other = get_hand(name).planner
        assert other.yaw_rate is None and other.flap_min_radius_share is None, name


@pytest.mark.parametrize("key,value", [("yaw_rate", "fast"), ("flap_min_radius_share", True)])
def test_a_wrong_number_is_refused_naming_the_file(tmp_path, key, value):
    path = tmp_path / "planner.json"
    path.write_text(json.dumps({key: value}))
    with pytest.raises(ValueError, match=str(path)):
        HandPlannerConfig.load(path)


@pytest.mark.slow
@pytest.mark.parametrize("cid,joint", [
    ("45415", "joint_0"),  # a side door whose hinge the camera replaces: the yaw rate
    ("45600", "joint_1"),  # a bar 4.5 cm above the floor: hooked pitched 40 degrees
    ("46166", "joint_1"),  # a flap hinged at its top, its bar 8 cm above the floor: the flap's reach
])
def test_real_franka_doors_open(real_episode, cid, joint):
    """The Franka on three real doors it lost before (open 0-2 %) opens each beyond 20 %."""
    rec = real_episode(cid, joint, "franka")
    assert rec["success"] and rec["open_ratio"] > 0.2, rec
