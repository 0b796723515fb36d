"""A horizontal bar near the floor hooked from above (``hook_down_pitches``): the Franka gripper's
body, 20 cm long across a bar, fits neither under a bar 3-6 cm above the floor nor behind it, so it
points its closed fingers down into the stand-off gap behind the bar and pulls the bar out by their
backs; where that gap is too narrow for them, it presses them on the bar's top (``press_depth``).
Synthetic scenes for the choice; real PartNet-Mobility doors (../shared) end to end."""

from __future__ import annotations

import numpy as np
import pytest

#: a door whose 7 mm bar stands 2-5 cm above the floor with 27 mm behind it (measured in depth)
LOW_BAR_DOOR = ("45403", "joint_1")
#: a door whose bar stands 3-5 cm above the floor with too little behind it for the closed fingers
PRESSED_BAR_DOOR = ("45385", "joint_1")


def test_the_gripper_hooks_a_low_bar_from_above_where_its_level_grasp_hits_the_floor(grasp_scenes):
    from opend_mj.policy.planner.clearance import clearances, outline_for
    from opend_mj.sim.hands import load_spec
    from opend_mj.transforms import quat_to_mat

    h = grasp_scenes
    spec = load_spec("franka")
    bar, posts = h._bar(thickness=0.008, gap=0.032, length=0.12, z=0.035)
    handle, shape, grasp = h._choose("franka", [bar, *posts], bar, "door", kind="door")
    assert grasp.style == "hook_down"
    axes = quat_to_mat(grasp.quat)
    assert axes[2, 2] < -0.6  # the fingers point down
    assert abs(axes[1, 1]) > 0.99  # the fingers' closing axis along the bar (world y)
    assert np.allclose(grasp.pre, grasp.closed) and np.allclose(grasp.closed, 0.0)  # one closed hook
    assert grasp.probe is not None and grasp.probe[0] < -0.99  # tested by pulling out of the panel
    back, panel = bar[1][0], h.PANEL_X
    assert back < grasp.pos[0] < panel  # in the gap behind the bar
    floor, door = clearances(outline_for(spec, grasp.closed), grasp.pos, grasp.quat, panel)
    assert floor > 0.0 and door >= -1e-6
    # no gap for the fingers (15 mm): the same pose presses on the bar's top, between the bar's
    # front and the panel (press_depth), or, for a hand without one, the level grasp stays
    bar, posts = h._bar(thickness=0.008, gap=0.015, length=0.12, z=0.035)
    pressed = h._choose("franka", [bar, *posts], bar, "door", kind="door")[2]
    assert pressed.style == "press_down" and pressed.press > 0.0 and pressed.on_top_press == pressed.press
    assert bar[0][0] < pressed.pos[0] < panel
    level = h._choose("franka", [bar, *posts], bar, "door", kind="door", press_depth=0.0)[2]
    assert level.style not in ("hook_down", "press_down") and level.press == 0.0
    # 30 cm up: level, fingers open
    bar, posts = h._bar(thickness=0.008, gap=0.032, length=0.12, z=0.3)
    high = h._choose("franka", [bar, *posts], bar, "door", kind="door")[2]
    assert high.style == "hook" and high.probe is None
    # a hand without hook_down_pitches never hooks from above
    bar, posts = h._bar(thickness=0.008, gap=0.032, length=0.12, z=0.035)
    assert h._choose("franka", [bar, *posts], bar, "door", kind="door", hook_down_pitches=())[2].style != "hook_down"


def test_hook_down_pitches_are_checked_when_the_hand_file_is_read(tmp_path):
    from opend_mj.policy.planner import HandPlannerConfig

    path = tmp_path / "planner.json"
    path.write_text('{"hook_down_pitches": [60, 120]}')
    with pytest.raises(ValueError, match="hook_down_pitches"):
        HandPlannerConfig.load(path)
    path.write_text('{"hook_down_pitches": [80, 60], "hook_down_width": 0.021}')
    assert HandPlannerConfig.load(path).hook_down_pitches == (80.0, 60.0)


@pytest.mark.slow
@pytest.mark.parametrize(("target", "hand", "style"), [(LOW_BAR_DOOR, "franka", "hook_down"),
                                                     (PRESSED_BAR_DOOR, "franka", "press_down"),
                                                     (PRESSED_BAR_DOOR, "allegro", "press_down")])
def test_a_real_door_with_its_bar_near_the_floor_opens(real_episode, target, hand, style):
    """The gripper, and the Allegro whose open fingers would stop on the floor short of the bar."""
    rec = real_episode(*target, hand)
    assert rec["grasp_style"] == style
    assert rec["success"] and rec["range_ratio"] > 0.75, rec
    assert rec["others_moved"] == []


def test_the_allegros_open_fingers_give_a_little_on_the_floor(grasp_scenes):
    """The Allegro's open fingers point down at a low bar and reach below its grasp site: where they
    would reach more than the hand's ``floor_give`` below the floor they stop on it, short of the
    bar, and the hand presses on the bar's top instead; where they only graze it (a bar 5.2 cm up,
    1.4 mm into the floor) they bend and slide, and the hook stays."""
    from opend_mj.sim.hands import get_hand

    h = grasp_scenes
    give = get_hand("allegro").planner.floor_give
    assert give > 0.0
    low, low_posts = h._bar(thickness=0.01, gap=0.016, length=0.12, z=0.04)
    floor = next(e["no_clear_pose"][0] for e in h._choose_events("allegro", [low, *low_posts], low)
                 if "no_clear_pose" in e)
    assert floor < -give
    assert h._choose("allegro", [low, *low_posts], low, "door", kind="door")[2].style == "press_down"
    grazing, posts = h._bar(thickness=0.01, gap=0.016, length=0.12, z=0.052)
    floor = next(e["no_clear_pose"][0] for e in h._choose_events("allegro", [grazing, *posts], grazing)
                 if "no_clear_pose" in e)
    assert -give < floor < 0.0
    assert h._choose("allegro", [grazing, *posts], grazing, "door", kind="door")[2].style == "hook"
    stiff = h._choose("allegro", [grazing, *posts], grazing, "door", kind="door", floor_give=0.0)[2]
    assert stiff.style == "press_down"
