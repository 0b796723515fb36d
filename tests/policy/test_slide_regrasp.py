"""Grasping a sliding panel again to slide it along its front: at its handle (the panel did not come
out, so the handle is where it was seen), with a dexterous hand's fingers pointing against the slide
(the hook round a bar is closed on the fingers' side and open on the palm's) and the bar in the
fingers' curl. Synthetic scenes for the choice; a real PartNet-Mobility sliding panel (../shared)
end to end."""

from __future__ import annotations

import numpy as np
import pytest

#: a "drawer" whose front slides sideways: a vertical bar 17 mm thick with 37 mm behind it
SLIDING_PANEL = ("45855", "joint_0")


def _planner_and_grasp(h, hand: str, bar_and_posts=None):
    """A planner that chose its grasp on a drawer's bar (synthetic depth; a vertical bar unless
    ``bar_and_posts`` are given), and that grasp."""
    from opend_mj.policy.perception import estimate_handle
    from opend_mj.policy.planner import Observation, Planner, PlannerConfig, PlanResult
    from opend_mj.policy.solvers import get_solver
    from opend_mj.sim.hands import load_spec

    bar, posts = bar_and_posts or h._bar(thickness=0.016, gap=0.035, length=0.3, z=0.5, orientation="vertical")
    view = h._view()
    depth = h._render(view, [bar, *posts])
    box = h._box_of(view, *bar)
    planner = Planner(get_solver("oracle", ground_truth=lambda: box.as_tuple()), load_spec(hand), PlannerConfig())
    obs = Observation(rgb=None, depth=depth, instruction="drawer", camera_view=view)
    result = PlanResult(stage_reached="locate", failed_stage=None, target_kind="drawer")
    handle = estimate_handle(box, depth, view, planner.config.perception)
    shape = planner.perceive(handle, box, obs, result)
    planner.state.handle = handle
    planner.state.first = obs
    return planner, handle, shape, planner.grasping.choose_grasp(handle, shape, obs, result), result


@pytest.mark.parametrize("slide_y", [1.0, -1.0])
def test_a_panel_is_grasped_again_at_its_handle_with_the_fingers_against_the_slide(grasp_scenes, slide_y):
    from opend_mj.policy.planner import PullState
    from opend_mj.transforms import quat_to_mat

    planner, handle, shape, g, result = _planner_and_grasp(grasp_scenes, "allegro")
    assert g.style == "hook" and g.orientation == "vertical"
    fingers = quat_to_mat(g.quat)[:, 1]
    assert abs(fingers[1]) > 0.99  # along the front, across the vertical bar
    state = PullState(quat0=g.quat)
    # the hand last felt touch 7 cm out (sliding off the bar) and 1 cm along the front (the panel
    # drawn a little sideways): the handle is as deep as it was seen, where it was last held across
    state.last_held = (g.pos + np.array([-0.07, 0.01, 0.0]), g.quat)
    state.slides = [np.array([0.0, slide_y, 0.0]), np.array([0.0, -slide_y, 0.0])]
    assert planner.slide.next_slide(state, result)
    again = planner.grasping.next_grasp(g, handle, shape, state, result)
    new_fingers = quat_to_mat(again.quat)[:, 1]
    assert new_fingers[1] * slide_y < -0.99  # the fingers point against the slide
    assert np.allclose(quat_to_mat(again.quat)[:, 2], quat_to_mat(g.quat)[:, 2])  # same approach axis
    deeper = planner.config.recovery.regrasp_deeper
    assert again.pos[0] == pytest.approx(g.pos[0] + deeper, abs=1e-9)  # at the seen depth, a little deeper
    assert again.pos[2] == pytest.approx(g.pos[2])
    turned = fingers[1] * slide_y > 0.5
    assert any("slide_fingers_turned" in e for e in result.events) == turned
    # turned, the bar lies in the fingers' curl: the site moved hook_slide back along the new fingers
    expected_y = g.pos[1] + 0.01 + (planner.hand.hook_slide * fingers[1] if turned else 0.0)
    assert again.pos[1] == pytest.approx(expected_y, abs=1e-9)


def test_a_drawer_that_came_out_is_grasped_again_where_it_was_last_held(grasp_scenes):
    """No slide (the drawer came out, then the grip was lost): the handle is where the hand last held it."""
    from opend_mj.policy.planner import PullState

    planner, handle, shape, g, result = _planner_and_grasp(grasp_scenes, "allegro")
    state = PullState(quat0=g.quat)
    state.last_held = (g.pos + np.array([-0.07, 0.0, 0.0]), g.quat)
    again = planner.grasping.next_grasp(g, handle, shape, state, result)
    assert again.pos[0] == pytest.approx(g.pos[0] - 0.07 + planner.config.recovery.regrasp_deeper, abs=1e-9)
    assert np.allclose(again.quat, g.quat)


def test_the_gripper_is_never_turned_for_a_slide(grasp_scenes):
    from opend_mj.policy.planner import PullState

    planner, handle, shape, g, result = _planner_and_grasp(grasp_scenes, "franka")
    state = PullState(quat0=g.quat)
    state.slides = [np.array([0.0, 1.0, 0.0]), np.array([0.0, -1.0, 0.0])]
    planner.slide.next_slide(state, result)
    again = planner.grasping.next_grasp(g, handle, shape, state, result)
    assert np.allclose(again.quat, g.quat)
    assert not any("slide_fingers_turned" in e for e in result.events)


@pytest.mark.slow
def test_a_real_sliding_panel_opens_with_the_allegro(real_episode):
    rec = real_episode(*SLIDING_PANEL, "allegro")
    assert rec["pull_end"][0] == "stuck"  # pulled out first, it did not come
    assert rec["success"] and rec["range_ratio"] > 0.75, rec
    assert rec["others_moved"] == []


def test_a_panel_pressed_from_above_is_pressed_again_at_the_depth_it_was_seen(grasp_scenes):
    """A low bar pressed from above (the Allegro's open fingers would stop on the floor) whose panel
    did not come out: the press slid off toward the camera, but the bar is as deep as it was seen;
    only its place along the front is taken from where it was last held."""
    from opend_mj.policy.planner import PullState

    h = grasp_scenes
    bar, posts = h._bar(thickness=0.01, gap=0.016, length=0.12, z=0.04)
    planner, handle, shape, g, result = _planner_and_grasp(h, "allegro", (bar, posts))
    assert g.style == "press_down"
    state = PullState(quat0=g.quat)
    state.last_held = (g.pos + np.array([-0.05, 0.02, 0.0]), g.quat)
    state.slides = [np.array([0.0, 1.0, 0.0]), np.array([0.0, -1.0, 0.0])]
    assert planner.slide.next_slide(state, result)
    again = planner.grasping.next_grasp(g, handle, shape, state, result)
    assert again.style == "press_down"
    assert again.pos[0] == pytest.approx(g.pos[0]) and again.pos[1] == pytest.approx(g.pos[1] + 0.02)
    # a drawer that came out (no slide): pressed again where it was last held
    state.slides = None
    came_out = planner.grasping.next_grasp(g, handle, shape, state, result)
    assert came_out.pos[0] == pytest.approx(g.pos[0] - 0.05)

