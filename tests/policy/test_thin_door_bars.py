"""Thin door bars close to their door, end to end: a procedural door whose horizontal bar is 9 mm
thick with 15 mm behind it (the real set's median gap is 23 mm, its 10th percentile 10 mm) really
opens with the Franka gripper and the Allegro hand, the Allegro hooking the bar at its fingers'
middle segments (``hook_slide``)."""

from __future__ import annotations

from pathlib import Path

import pytest



def _thin_bar_door() -> tuple[str, str, object]:
    """(id, joint, sampled cabinet): the first generated double door (seed 0) with its bars in the lower half
    of the cabinet, of a generator whose bars are 9 mm thick with 15 mm behind them, on doors horizontal."""
    from opend_mj.assets.procedural import GeneratorConfig, find_cabinets

    config = GeneratorConfig(bar_diameter_range=(0.009, 0.009), bar_gap_range=(0.015, 0.015),
                             door_handle_kinds=(1.0, 0.0, 0.0), door_horizontal_share=1.0, flap_share=0.0,
                             long_bar_share=0.0)
    (cabinet,) = find_cabinets(lambda c: len(c.targets) == 2 and all(
        t.kind == "door" and t.double and t.handle_orientation == "horizontal" and t.handle_center[1] < 0
        for t in c.targets), config=config)
    return cabinet.id, "joint_0", cabinet


THIN_BAR_DOOR = _thin_bar_door()


@pytest.fixture(scope="module")
def thin_bar_cabinet(tmp_path_factory) -> Path:
    from opend_mj.assets.compiler import compile_cabinet
    from opend_mj.assets.procedural import write_source

    root = tmp_path_factory.mktemp("thin_bar")
    cid, _, cabinet = THIN_BAR_DOOR
    src = write_source(cabinet, root / "src")
    res = compile_cabinet(src, root / "built", cache_dir=root / "cache")
    assert (root / "built" / cid / "cabinet.json").is_file(), res
    return root / "built" / cid


@pytest.mark.slow
@pytest.mark.parametrize("hand", ["franka", "allegro"])
def test_a_thin_bar_close_to_its_door_is_held_and_the_door_opens(thin_bar_cabinet, hand):
    from opend_mj.evaluation.episode import EpisodeJob
    from opend_mj.evaluation.runner import run_episode

    cid, joint, _ = THIN_BAR_DOOR
    rec = run_episode(EpisodeJob(cabinet=cid, cabinet_dir=str(thin_bar_cabinet), joint=joint, split="test",
                                 hand=hand, solver="oracle"))
    assert "error" not in rec, rec.get("error")
    shape = rec["handle_shape"]
    assert rec["target_type"] == "door" and rec["handle_orientation"] == "horizontal"
    assert shape["thickness"] < 0.012 and shape["gap"] < 0.02, shape
    assert rec["grasp_style"] == "hook"
    assert rec["success"] and rec["open_ratio"] > 0.2, rec
    assert rec["others_moved"] == []


def test_the_allegro_hooks_a_bar_at_its_fingers_middle_segments(grasp_scenes):
    """The Allegro's hook grasp site lies ``hook_slide`` back along its finger axis from the bar, so the
    bar sits at the middle segments; a hand without a slide grasps at the bar."""
    import numpy as np

    from opend_mj.sim.hands import get_hand
    from opend_mj.transforms import quat_to_mat

    slide = get_hand("allegro").planner.hook_slide
    assert 0.02 <= slide <= 0.06
    assert get_hand("franka").planner.hook_slide == 0.0
    # a synthetic bar 40 cm up (no low-handle rules), 12 mm thick with 25 mm behind it
    helpers = grasp_scenes
    bar, posts = helpers._bar(thickness=0.012, gap=0.025, length=0.2, z=0.4)
    handle, _, grasp = helpers._choose("allegro", [bar, *posts], bar, "door", kind="door")
    assert grasp.style == "hook"
    fingers = quat_to_mat(grasp.quat)[:, 1]
    offset = grasp.pos - handle.centre
    assert float(offset @ fingers) == pytest.approx(-slide, abs=1e-6)
    _, _, plain = helpers._choose("allegro", [bar, *posts], bar, "door", kind="door", hook_slide=0.0)
    assert float((plain.pos - handle.centre) @ fingers) == pytest.approx(0.0, abs=1e-6)
    assert np.allclose(plain.pos - grasp.pos, slide * fingers)
    # a drawer's bar (pulled straight) is hooked at the site
    _, _, drawer = helpers._choose("allegro", [bar, *posts], bar, "top drawer", kind="drawer")
    assert float((drawer.pos - handle.centre) @ fingers) == pytest.approx(0.0, abs=1e-6)
    # nor toward a neighbour beside a vertical bar (a double door's other handle 6 cm away)
    vbar, vposts = helpers._bar(thickness=0.008, gap=0.02, length=0.2, y=0.03, z=0.4, orientation="vertical")
    other, oposts = helpers._bar(thickness=0.008, gap=0.02, length=0.2, y=-0.038, z=0.4, orientation="vertical")
    handle, shape, near = helpers._choose("allegro", [vbar, *vposts, other, *oposts], vbar, "top left door",
                                          kind="door")
    # fingers toward the left door's hinge (+y): the slide would move the hand right, to the neighbour
    assert quat_to_mat(near.quat)[1, 1] > 0.99 and shape.clear["right"] < 0.1
    assert np.allclose(near.pos[1:], handle.centre[1:], atol=1e-6)
