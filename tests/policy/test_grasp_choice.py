"""Grasp choice from what the planner sees: synthetic depth images of a panel with a thin bar on
stand-offs, a wide bar with room behind it, and a knob; the handle's shape is measured in depth and
the grasp style follows from it."""

from __future__ import annotations

import numpy as np
import pytest

PANEL_X = 1.0


def _view():
    from opend_mj.sim.camera import CameraIntrinsics, CameraView

    # camera at the origin looking along +x (columns: right = -y, up = +z, backward = -x)
    rot = np.column_stack([(0, -1, 0), (0, 0, 1), (-1, 0, 0)]).astype(float)
    return CameraView(CameraIntrinsics.from_fovy(45, 256, 256), np.zeros(3), rot)


def _render(view, boxes):
    """Planar depth of a wall at x = PANEL_X and axis-aligned boxes (lo, hi) in front of it."""
    cols, rows = np.meshgrid(np.arange(256) + 0.5, np.arange(256) + 0.5)
    far = view.backproject(cols.ravel(), rows.ravel(), np.ones(cols.size))  # points at depth 1
    d = far - view.pos  # ray directions with planar depth 1 per unit t
    t_best = (PANEL_X - view.pos[0]) / d[:, 0]
    for lo, hi in boxes:
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (lo - view.pos) / d
            t2 = (hi - view.pos) / d
        tmin = np.nanmax(np.minimum(t1, t2), axis=1)
        tmax = np.nanmin(np.maximum(t1, t2), axis=1)
        hit = (tmax >= tmin) & (tmin > 0)
        t_best = np.where(hit & (tmin < t_best), tmin, t_best)
    return t_best.reshape(256, 256)  # planar depth = t (direction has unit planar depth)


def _box_of(view, lo, hi):
    from opend_mj.policy.handle_box import HandleBox

    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    uv = view.project(corners)
    return HandleBox(uv[:, 0].min(), uv[:, 1].min(), uv[:, 0].max(), uv[:, 1].max())


def _bar(thickness, gap, length=0.2, y=0.0, z=0.0, orientation="horizontal"):
    """A bar whose back is `gap` in front of the panel, with two stand-offs."""
    back = PANEL_X - gap
    front = back - thickness
    if orientation == "horizontal":
        bar = ((front, y - length / 2, z - thickness / 2), (back, y + length / 2, z + thickness / 2))
        posts = [((back, y + s * length * 0.4 - 0.004, z - 0.004), (PANEL_X, y + s * length * 0.4 + 0.004, z + 0.004))
                 for s in (-1, 1)]
    else:
        bar = ((front, y - thickness / 2, z - length / 2), (back, y + thickness / 2, z + length / 2))
        posts = [((back, y - 0.004, z + s * length * 0.4 - 0.004), (PANEL_X, y + 0.004, z + s * length * 0.4 + 0.004))
                 for s in (-1, 1)]
    return bar, posts


def _choose(hand, boxes, handle_box_world, instruction="top drawer", kind="drawer", overrides=None, **hand_numbers):
    """The grasp chosen for a synthetic scene; ``overrides``: ``PlannerConfig.override`` keys;
    ``hand_numbers``: fields of the hand's ``HandPlannerConfig`` to replace."""
    from dataclasses import replace

    from opend_mj.policy.perception import estimate_handle
    from opend_mj.policy.planner import Observation, PlanResult, Planner, PlannerConfig
    from opend_mj.policy.solvers import get_solver
    from opend_mj.sim.hands import get_hand, load_spec

    view = _view()
    depth = _render(view, boxes)
    box = _box_of(view, *handle_box_world)
    spec = load_spec(hand)
    numbers = replace(get_hand(spec.name).planner, **hand_numbers)
    planner = Planner(get_solver("oracle", ground_truth=lambda: box.as_tuple()), spec,
                      PlannerConfig().override(overrides or {}), numbers=numbers)
    obs = Observation(rgb=None, depth=depth, instruction=instruction, camera_view=view)
    result = PlanResult(stage_reached="locate", failed_stage=None, target_kind=kind)
    handle = estimate_handle(box, depth, view, planner.config.perception)
    shape = planner.perceive(handle, box, obs, result)
    grasp = planner.grasping.choose_grasp(handle, shape, obs, result)
    return handle, shape, grasp


@pytest.mark.parametrize("hand", ["allegro", "shadow"])
def test_thin_bar_close_to_the_panel_is_pinched(hand):
    bar, posts = _bar(thickness=0.008, gap=0.008, z=0.3)  # 30 cm up: not a handle near the floor
    handle, shape, grasp = _choose(hand, [bar, *posts], bar)
    assert handle.kind == "bar" and handle.orientation == "horizontal"
    assert shape.thickness == pytest.approx(0.008, abs=0.004)
    assert shape.gap < 0.012
    assert grasp.style == "pinch"


@pytest.mark.parametrize("hand", ["allegro", "skeleton"])
def test_wide_bar_with_room_behind_is_hooked(hand):
    bar, posts = _bar(thickness=0.014, gap=0.03, length=0.25)
    # the synthetic scene sits at z = 0: not a handle near the floor
    handle, shape, grasp = _choose(hand, [bar, *posts], bar, low_handle_lift=0.0, min_grasp_height=None,
                                   hook_down_pitches=())
    assert handle.kind == "bar"
    assert shape.thickness == pytest.approx(0.014, abs=0.005)
    assert shape.gap == pytest.approx(0.03, abs=0.008)
    assert shape.length == pytest.approx(0.25, abs=0.02)
    assert grasp.style == "hook"
    # the site goes to the bar (within a centimetre), approached along +x
    assert np.allclose(grasp.pos[1:], [0.0, 0.0], atol=0.01)
    assert grasp.axis[0] > 0.99


def test_vertical_thin_bar_and_its_neighbour():
    """A vertical bar with a second handle 6 cm to its side (double doors): the neighbour is seen."""
    bar, posts = _bar(thickness=0.008, gap=0.02, length=0.2, y=0.03, orientation="vertical")
    other, other_posts = _bar(thickness=0.008, gap=0.02, length=0.2, y=-0.038, orientation="vertical")
    handle, shape, grasp = _choose("allegro", [bar, *posts, other, *other_posts], bar, "top left door")
    assert handle.orientation == "vertical"
    assert shape.clear["right"] == pytest.approx(0.06, abs=0.012)
    assert shape.clear["left"] > 0.1
    assert grasp.style == "hook"


def test_knob_is_wrapped():
    knob = ((PANEL_X - 0.035, -0.017, -0.017), (PANEL_X, 0.017, 0.017))
    handle, shape, grasp = _choose("allegro", [knob], knob)
    assert handle.kind == "knob"
    assert shape.length == pytest.approx(0.034, abs=0.006)
    assert grasp.style == "wrap"


def test_parallel_gripper_pinches_every_bar():
    bar, posts = _bar(thickness=0.008, gap=0.008, z=0.3)  # well above the floor (low bars: test_hook_from_above)
    _, _, grasp = _choose("franka", [bar, *posts], bar)
    assert grasp.style == "hook"  # the gripper closes across the bar whatever the gap (pinch_gap 0)


def test_a_box_over_a_pair_of_pulls_becomes_the_nearer_pull():
    from opend_mj.policy.handle_box import HandleBox
    from opend_mj.policy.perception import one_of_paired_handles

    depth = np.full((64, 128), 1.0)
    depth[30:34, 20:34] = 0.965  # left cup pull, 3.5 cm proud
    depth[30:34, 90:104] = 0.965  # right cup pull
    pair = HandleBox(20, 30, 104, 34, orientation="horizontal")
    single = one_of_paired_handles(pair, depth)
    assert single is not None and single.orientation == "horizontal"
    assert (single.u0, single.u1, single.v0, single.v1) in {(20, 34, 30, 34), (90, 104, 30, 34)}
    # one bar under the box: nothing to choose
    bar = depth.copy()
    bar[30:34, 20:104] = 0.965
    assert one_of_paired_handles(pair, bar) is None
    # bare panel: nothing to choose either
    assert one_of_paired_handles(pair, np.full((64, 128), 1.0)) is None


@pytest.mark.parametrize("hand", ["allegro", "shadow"])
def test_horizontal_door_bar_under_a_neighbour_is_grasped_fingers_down(hand):
    """Stacked doors whose bars meet at the seam (the neighbour's bar 6 cm above): the fingers point
    down, away from the neighbour; without one they point up, whichever side the door hinges on."""
    from opend_mj.transforms import quat_to_mat

    high = {"grasp.flip_below": -1.0}  # the synthetic scene sits at z = 0: not a handle near the floor
    bar, posts = _bar(thickness=0.012, gap=0.02, length=0.25, y=0.1, z=0.0)
    other, other_posts = _bar(thickness=0.012, gap=0.02, length=0.25, y=0.1, z=0.06)
    floorless = {"hook_down_pitches": ()}  # nor hooked from above
    _, shape, grasp = _choose(hand, [bar, *posts, other, *other_posts], bar, "bottom right door", kind="door",
                              overrides=high, **floorless)
    assert shape.clear["up"] < 0.08 and shape.clear["down"] > 0.1
    fingers = quat_to_mat(grasp.quat)[:, 1]  # the open fingers point along site +y
    assert fingers[2] < -0.9
    _, _, alone = _choose(hand, [bar, *posts], bar, "bottom right door", kind="door", overrides=high, **floorless)
    assert quat_to_mat(alone.quat)[:, 1][2] > 0.9


@pytest.mark.parametrize("hand", ["allegro", "shadow"])
def test_a_bar_near_the_floor_is_grasped_from_above(hand):
    """A door bar 6 cm above the floor: the grasp site goes above the bar, so that the open fingers
    pointing down clear the floor; the same bar 30 cm up is grasped at its centre."""
    from opend_mj.sim.hands import get_hand

    numbers = get_hand(hand).planner
    lift, slide = numbers.low_handle_lift, numbers.hook_slide
    assert lift > 0.0 and lift >= slide  # the lift already puts the bar that far out along the fingers
    low_bar, low_posts = _bar(thickness=0.012, gap=0.02, length=0.2, z=0.06)
    handle, _, low = _choose(hand, [low_bar, *low_posts], low_bar, "door", kind="door")
    assert low.pos[2] == pytest.approx(handle.centre[2] + lift) and handle.centre[2] < 0.08
    # 30 cm up, fingers up: at its centre, less the hand's hook slide (the bar at the middle segments)
    high_bar, high_posts = _bar(thickness=0.012, gap=0.02, length=0.2, z=0.3)
    handle, _, high = _choose(hand, [high_bar, *high_posts], high_bar, "door", kind="door")
    assert high.pos[2] == pytest.approx(handle.centre[2] - slide) and handle.centre[2] > 0.25


def test_the_gripper_pitches_down_for_a_bar_near_the_floor():
    """The gripper's body is 21 cm wide along its finger axis: for a bar 6 cm above the floor it comes
    from above and in front, pitched down, so that the body's lower end stays above the floor and its
    upper end off the door; a bar 30 cm up is approached level."""
    from opend_mj.sim.hands import get_hand
    from opend_mj.transforms import quat_to_mat

    pitch = np.radians(get_hand("franka").planner.low_handle_pitch)
    assert pitch > 0.0
    low_bar, low_posts = _bar(thickness=0.012, gap=0.02, length=0.2, z=0.06)
    # (the gripper's own press from above, press_depth, is test_hook_from_above's)
    _, _, low = _choose("franka", [low_bar, *low_posts], low_bar, "door", kind="door", press_depth=0.0)
    approach = quat_to_mat(low.quat)[:, 2]
    assert approach[2] == pytest.approx(-np.sin(pitch), abs=1e-6) and approach[0] > 0.5
    high_bar, high_posts = _bar(thickness=0.012, gap=0.02, length=0.2, z=0.3)
    _, _, high = _choose("franka", [high_bar, *high_posts], high_bar, "door", kind="door")
    assert quat_to_mat(high.quat)[:, 2] == pytest.approx([1.0, 0.0, 0.0], abs=1e-6)


def test_the_skeleton_grasps_no_lower_than_its_floor_clearance():
    """The Skeleton's fingers point down behind a low bar and strike the floor below a grasp site
    5 cm up: a door bar 3 cm above the floor is grasped at 5 cm (at its top edge), one 8 cm up at
    its centre. Other hands keep their own lift."""
    from opend_mj.sim.hands import get_hand

    floor = get_hand("skeleton").planner.min_grasp_height
    low_bar, low_posts = _bar(thickness=0.014, gap=0.016, length=0.1, z=0.03)
    handle, _, low = _choose("skeleton", [low_bar, *low_posts], low_bar, "door", kind="door")
    assert handle.centre[2] < floor - 0.015
    assert low.pos[2] == pytest.approx(floor)
    mid_bar, mid_posts = _bar(thickness=0.014, gap=0.016, length=0.1, z=0.08)
    handle, _, mid = _choose("skeleton", [mid_bar, *mid_posts], mid_bar, "door", kind="door")
    assert mid.pos[2] == pytest.approx(handle.centre[2]) and handle.centre[2] > floor
    _, _, off = _choose("skeleton", [low_bar, *low_posts], low_bar, "door", kind="door", min_grasp_height=None)
    assert off.pos[2] < floor - 0.015


def test_the_hand_outline_is_the_models_collision_geometry():
    """The open gripper seen from its grasp site: its body reaches 10.2 cm along the finger axis, its
    pads 9.5 mm beyond the site, its flange 9.34 cm behind it (hands/franka/hand.xml); closed, the
    fingers reach no farther along the finger axis than the body."""
    from opend_mj.policy.planner.clearance import outline_for
    from opend_mj.sim.hands import load_spec

    spec = load_spec("franka")
    open_hand = outline_for(spec, [0.04, 0.04])
    assert open_hand.support([0.0, 1.0, 0.0]) == pytest.approx(0.102)
    assert open_hand.support([0.0, 0.0, 1.0]) == pytest.approx(0.0095)
    assert open_hand.support([0.0, 0.0, -1.0]) == pytest.approx(0.0934)
    closed = outline_for(spec, [0.0, 0.0])
    assert closed.support([0.0, 1.0, 0.0]) == pytest.approx(0.102)
    assert closed.support([1.0, 0.0, 0.0]) == pytest.approx(0.03)


def test_the_gripper_has_no_room_at_a_bar_near_the_floor_and_its_door():
    """A 14 mm bar 4 cm above the floor, 16 mm off its door: the gripper pitched down 35 degrees (its
    low-handle pose) reaches into the floor and the door, and no pitch from 35 to 90 degrees clears
    both (its 20 cm body across the bar); the same bar 30 cm up clears level."""
    from opend_mj.transforms import quat_to_mat

    bar, posts = _bar(thickness=0.014, gap=0.016, length=0.1, z=0.04)
    pitches = (35.0, 45.0, 55.0, 65.0, 75.0, 90.0)
    handle, _, grasp = _choose("franka", [bar, *posts], bar, "door", kind="door", clearance_pitches=pitches,
                               press_depth=0.0)
    assert handle.centre[2] < 0.05
    # nothing clears: the pose stays the hand's low-handle pose (pitched 35 degrees down); with its
    # press_depth the gripper presses on the bar's top instead (test_hook_from_above)
    assert quat_to_mat(grasp.quat)[2, 2] == pytest.approx(-np.sin(np.radians(35.0)), abs=1e-6)
    assert _choose("franka", [bar, *posts], bar, "door", kind="door")[2].style == "press_down"
    planner_events = _choose_events("franka", [bar, *posts], bar, clearance_pitches=pitches)
    assert any("no_clear_pose" in e for e in planner_events), planner_events
    floor, door = next(e["no_clear_pose"] for e in planner_events if "no_clear_pose" in e)
    assert floor < 0.0 and door < 0.0
    high_bar, high_posts = _bar(thickness=0.014, gap=0.016, length=0.1, z=0.3)
    events = _choose_events("franka", [high_bar, *high_posts], high_bar, clearance_pitches=pitches)
    assert not any("no_clear_pose" in e or "clearance_pitch" in e for e in events), events


def _choose_events(hand, boxes, handle_box, **hand_numbers):
    """The planner's events while choosing the grasp of a door's handle in a synthetic scene."""
    from dataclasses import replace

    from opend_mj.policy.perception import estimate_handle
    from opend_mj.policy.planner import Observation, PlanResult, Planner, PlannerConfig
    from opend_mj.policy.solvers import get_solver
    from opend_mj.sim.hands import get_hand, load_spec

    view = _view()
    depth = _render(view, boxes)
    box = _box_of(view, *handle_box)
    spec = load_spec(hand)
    planner = Planner(get_solver("oracle", ground_truth=lambda: box.as_tuple()), spec, PlannerConfig(),
                      numbers=replace(get_hand(spec.name).planner, **hand_numbers))
    obs = Observation(rgb=None, depth=depth, instruction="door", camera_view=view)
    result = PlanResult(stage_reached="locate", failed_stage=None, target_kind="door")
    handle = estimate_handle(box, depth, view, planner.config.perception)
    planner.grasping.choose_grasp(handle, planner.perceive(handle, box, obs, result), obs, result)
    return result.events


def _knob(z, size=0.04, depth=0.028):
    return ((PANEL_X - depth, -size / 2, z - size / 2), (PANEL_X, size / 2, z + size / 2))


@pytest.mark.parametrize("hand", ["franka", "allegro"])
def test_a_knob_near_the_floor_is_grasped_with_the_hand_turned(hand):
    """A 40 mm knob 4 cm above the floor: grasped level with the fingers across it up and down,
    the gripper's 20 cm body (the Allegro's open fingers) would reach into the floor; turned a
    quarter about the approach axis (fingers to the sides) it has more room, and a knob is round.
    The same knob 40 cm up is grasped as the hand's grasp.json says (horizontal)."""
    low = _knob(0.04)
    handle, _, grasp = _choose(hand, [low], low, "door", kind="door")
    assert handle.kind == "knob"
    assert grasp.orientation == "vertical"
    events = _choose_events(hand, [low], low)
    turned = next(e["knob_turned"] for e in events if "knob_turned" in e)
    assert turned[0] == "vertical" and min(turned[3:]) > min(turned[1:3])
    high = _knob(0.4)
    _, _, grasp = _choose(hand, [high], high, "door", kind="door")
    assert grasp.orientation == "horizontal"
    # a hand that does not check (clearance_margin null) keeps its orientation near the floor too
    _, _, grasp = _choose(hand, [low], low, "door", kind="door", clearance_margin=None)
    assert grasp.orientation == "horizontal"


def test_the_pitch_search_takes_the_first_pitch_that_clears():
    """A 10 mm bar 7 cm above the floor with 45 mm behind it, the gripper's fixed low-handle pitch
    off: level, its body reaches into the floor; of 10, 35 and 60 degrees, 10 does not clear, 35
    does (both clearances at least the margin), and the grasp is approached pitched by it."""
    from opend_mj.policy.planner.clearance import clearances, outline_for
    from opend_mj.sim.hands import load_spec
    from opend_mj.transforms import quat_to_mat

    bar, posts = _bar(thickness=0.01, gap=0.045, length=0.2, z=0.07)
    numbers = dict(low_handle_pitch=0.0, clearance_pitches=(10.0, 35.0, 60.0))
    handle, shape, grasp = _choose("franka", [bar, *posts], bar, "door", kind="door", **numbers)
    events = _choose_events("franka", [bar, *posts], bar, **numbers)
    pitch = next(e["clearance_pitch"] for e in events if "clearance_pitch" in e)
    assert pitch[0] == 35.0 and min(pitch[1:]) >= 0.003
    assert quat_to_mat(grasp.quat)[2, 2] == pytest.approx(-np.sin(np.radians(35.0)), abs=1e-6)
    floor, door = clearances(outline_for(load_spec("franka"), grasp.pre), grasp.pos, grasp.quat,
                             handle.front_x + shape.protrusion)
    assert floor >= 0.003 and door >= 0.003


def test_a_bar_is_measured_through_depth_noise():
    """Noise of 3 mm (a strong sensor's after fusing frames) pulls the nearest few per cent of the box's
    depths nearer, so the front read there lies ahead of the bar and too few pixels read as the bar:
    a thin bar with a wide gap. The noise is measured from neighbouring pixels and the front and the
    bar's depth band allow for it; exact depth reads no noise and is measured as before."""
    from dataclasses import replace

    from opend_mj.policy.perception import PerceptionConfig, estimate_handle, measure_handle

    view = _view()
    bar, posts = _bar(thickness=0.014, gap=0.025, z=-0.05)
    exact = _render(view, [bar] + posts)
    box = _box_of(view, *bar)
    noisy = exact + np.random.default_rng(0).normal(scale=0.003, size=exact.shape)

    def measure(depth, config=PerceptionConfig()):
        handle = estimate_handle(box, depth, view, config)
        return handle, measure_handle(handle, box, depth, view, config)

    handle, shape = measure(exact)
    assert handle.noise == 0.0 and shape.gap == pytest.approx(0.025, abs=0.004)
    handle, shape = measure(noisy)
    assert handle.noise == pytest.approx(0.003, rel=0.3)
    assert shape.thickness == pytest.approx(0.014, abs=0.005), shape
    assert shape.gap == pytest.approx(0.025, abs=0.006), shape
    _, blind = measure(noisy, replace(PerceptionConfig(), noise_floor=1.0))  # noise taken for none
    assert blind.gap > 0.035, blind


def test_noise_is_no_neighbour_but_a_neighbour_still_is():
    """Under depth noise a lone pixel read a centimetre proud of the panel is no obstacle: the free
    space around a handle alone on its panel stays the search radius on every side. A real
    neighbour (a second handle beside it) is still found through the same noise."""
    from opend_mj.policy.perception import PerceptionConfig, estimate_handle, measure_handle

    view = _view()
    config = PerceptionConfig()
    bar, posts = _bar(thickness=0.014, gap=0.025, z=-0.05)
    box = _box_of(view, *bar)
    rng = np.random.default_rng(0)

    def measure(parts):
        exact = _render(view, parts)
        noisy = exact + rng.normal(scale=0.003, size=exact.shape)
        handle = estimate_handle(box, noisy, view, config)
        return measure_handle(handle, box, noisy, view, config)

    alone = measure([bar] + posts)
    assert min(alone.clear.values()) == pytest.approx(config.search_radius), alone.clear
    other, other_posts = _bar(thickness=0.014, gap=0.025, z=0.03)
    beside = measure([bar] + posts + [other] + other_posts)
    assert beside.clear["up"] < 0.1 and beside.clear["down"] == pytest.approx(config.search_radius), beside.clear


def test_a_handle_at_a_doors_bottom_edge_stands_on_the_door_not_on_the_room_behind():
    """A vertical bar at a door's bottom right corner whose box reaches below the door's edge, where
    the camera sees the room 20 cm farther: the panel behind the bar is the door's front (the room
    is more than ``panel_max_behind`` behind the bar), and the door hinges on its far (left) side."""
    from opend_mj.policy.perception import estimate_handle, infer_hinge_side, measure_handle
    from opend_mj.policy.perception.config import PerceptionConfig

    view = _view()
    door_front = PANEL_X - 0.2
    door = ((door_front, -0.3, -0.08), (door_front + 0.02, 0.3, 0.3))  # its bottom edge at z = -0.08
    bar = ((door_front - 0.03, -0.27, -0.1), (door_front - 0.015, -0.255, -0.02))  # 2 cm below it
    posts = [((door_front - 0.015, -0.266, z - 0.004), (door_front, -0.259, z + 0.004)) for z in (-0.07, -0.03)]
    depth = _render(view, [door, bar, *posts])
    box = _box_of(view, *bar)
    config = PerceptionConfig()
    handle = estimate_handle(box, depth, view, config)
    assert handle.panel_x == pytest.approx(door_front, abs=0.01)
    assert measure_handle(handle, box, depth, view, config).protrusion == pytest.approx(0.03, abs=0.01)
    assert infer_hinge_side(handle, depth, view, config) == "left"
