"""Sliding panels: "drawers" whose front slides sideways along the cabinet instead of out of it. The
pull stage alone on a panel held perfectly, whose handle moves only along its slide; the panel's
front in a synthetic depth image tells which way to slide it first."""

from __future__ import annotations

import math

import numpy as np
import pytest

from opend_mj.policy.perception import HandleEstimate
from opend_mj.policy.planner import GraspChoice, Observation, Planner, PlannerConfig, PlanResult, PullState
from opend_mj.policy.solvers import get_solver
from opend_mj.sim.hands import load_spec
from opend_mj.transforms import axis_angle_quat

from .fake_robot import DT, HANDLE_SPEED, FakeRobot

HANDLE_Y = -0.25  # the bar's y (m): near the right (-y) edge of a front spanning y in [-0.3, 0.3]


class HeldSlider(FakeRobot):
    """A robot whose grasp site holds a panel's bar perfectly; the bar moves only along
    ``axis`` (a world unit vector), from 0 to ``travel`` (m): each step it goes as far along its
    slide as the target's projection on it, at most 2 m/s."""

    def __init__(self, axis, travel: float):
        super().__init__()
        self.axis, self.travel = np.asarray(axis, float), travel
        self.start = np.array([0.965, HANDLE_Y, 0.0])
        self.opening = 0.0

    def handle_pos(self) -> np.ndarray:
        return self.start + self.opening * self.axis

    def follow(self, p, quat, fingers) -> None:
        want = float((p - self.start) @ self.axis)
        self.opening = self.moved(self.opening, want, self.travel, HANDLE_SPEED * DT)


def _forward_view():
    """A 256 px camera (fovy 45 degrees) at the origin looking along +x (columns: right = -y, up = +z)."""
    from opend_mj.sim.camera import CameraIntrinsics, CameraView

    rot = np.column_stack([(0, -1, 0), (0, 0, 1), (-1, 0, 0)]).astype(float)
    return CameraView(CameraIntrinsics.from_fovy(45, 256, 256), np.zeros(3), rot)


def _planner_seeing_the_front() -> Planner:
    """A planner whose first image shows a front 1 m away spanning y in [-0.3, 0.3] and z in
    [-0.3, 0.3], with a vertical bar 4 cm proud of it at ``HANDLE_Y``."""
    view = _forward_view()
    cols, rows = np.meshgrid(np.arange(256) + 0.5, np.arange(256) + 0.5)
    on_plane = view.backproject(cols.ravel(), rows.ravel(), np.ones(cols.size))
    inside = (np.abs(on_plane[:, 1]) < 0.3) & (np.abs(on_plane[:, 2]) < 0.3)
    depth = np.where(inside, 1.0, 2.5)
    on_bar = (np.abs(on_plane[:, 1] - HANDLE_Y) < 0.008) & (np.abs(on_plane[:, 2]) < 0.1)
    depth = np.where(on_bar, 0.96, depth).reshape(256, 256)
    planner = Planner(get_solver("oracle", ground_truth=lambda: None), load_spec("allegro"), PlannerConfig())
    planner.state.handle = HandleEstimate(centre=np.array([0.965, HANDLE_Y, 0.0]), orientation="vertical", kind="bar",
                                          size=(0.016, 0.2), front_x=0.96, panel_x=1.0)
    planner.state.first = Observation(rgb=None, depth=depth, instruction="drawer", camera_view=view)
    return planner


@pytest.mark.parametrize("axis", [(0.0, 1.0, 0.0), (0.0, -1.0, 0.0)])
def test_a_drawer_that_does_not_come_out_is_slid_along_its_front(axis):
    """Pulled out, the panel does not move ("stuck"); it is then slid across its bar, first toward
    its body (the front reaches farther on the +y side of the bar), then the other way, and opens
    fully along the way it slides."""
    planner = _planner_seeing_the_front()
    part = HeldSlider(axis, 0.39)
    quat = axis_angle_quat((0.0, 1.0, 0.0), math.pi / 2)
    g = GraspChoice("hook", "vertical", quat, part.site_pos(), np.zeros(16), np.zeros(16))
    state = PullState(quat0=quat)
    result = PlanResult(stage_reached="pull", failed_stage=None)
    assert planner.pulling.pull(part, g, False, state, result) == "stuck"
    tried = []
    while part.opening < 0.9 * part.travel and planner.slide.next_slide(state, result):
        tried.append(state.direction[1])
        planner.pulling.pull(part, g, False, state, result)
    assert tried[0] == 1.0  # toward the panel's body first
    assert part.opening >= 0.95 * part.travel, result.events
    assert tried == ([1.0] if axis[1] > 0 else [1.0, -1.0])


def test_a_drawer_that_comes_out_is_not_slid():
    """A drawer that comes out with the hand is pulled to its stop, never slid."""
    planner = _planner_seeing_the_front()
    part = HeldSlider((-1.0, 0.0, 0.0), 0.4)
    quat = axis_angle_quat((0.0, 1.0, 0.0), math.pi / 2)
    g = GraspChoice("hook", "vertical", quat, part.site_pos(), np.zeros(16), np.zeros(16))
    state = PullState(quat0=quat)
    result = PlanResult(stage_reached="pull", failed_stage=None)
    assert planner.pulling.pull(part, g, False, state, result) == "done"
    assert part.opening >= 0.95 * part.travel and state.slides is None
