"""The planner's configuration: nested frozen sections, overrides by path, per-hand files."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest


def test_sections_are_frozen_and_overrides_go_by_path():
    from opend_mj.policy.planner import PlannerConfig

    config = PlannerConfig()
    with pytest.raises(dataclasses.FrozenInstanceError):
        config.grasp.close_scale = 0.5
    changed = config.override({"grasp.close_scale": 0.8, "pull": "straight", "perception.front.min_pixels": 50})
    assert changed.grasp.close_scale == 0.8 and changed.pull == "straight"
    assert changed.perception.front.min_pixels == 50
    assert config.grasp.close_scale == 1.0 and config.perception.front.min_pixels == 200  # unchanged
    with pytest.raises(KeyError, match="grasp.no_such_field"):
        config.override({"grasp.no_such_field": 1})
    with pytest.raises(ValueError, match="sideways"):
        PlannerConfig(pull="sideways")


def test_every_section_says_what_it_controls():
    from opend_mj.policy import planner
    from opend_mj.policy.perception import PerceptionConfig

    for field in dataclasses.fields(planner.PlannerConfig):
        section = getattr(planner.PlannerConfig(), field.name)
        if dataclasses.is_dataclass(section):
            assert type(section).__doc__ and len(type(section).__doc__) > 40, field.name
    assert PerceptionConfig.__doc__


def test_grasp_profile_sets_finger_closing_and_depth():
    from opend_mj.policy.planner import GraspProfile, PlannerConfig

    profile = GraspProfile(hand="allegro", close_scale=0.9, grasp_depth={"bar": 0.004, "knob": 0.0})
    config = profile.apply(PlannerConfig())
    assert config.grasp.close_scale == 0.9 and config.grasp.depth == {"bar": 0.004, "knob": 0.0}


@pytest.mark.parametrize("hand, expected", [
    ("allegro", dict(low_handle_lift=0.06, min_grasp_height=None, low_handle_pitch=0.0, pinch_gap=0.012,
                     hold_parts=1, grip_lost_change=None)),
    ("shadow", dict(low_handle_lift=0.03, min_grasp_height=None, pinch_gap=0.012, hold_parts=1)),
    ("skeleton", dict(low_handle_lift=0.0, min_grasp_height=0.05, pinch_gap=0.012, hold_parts=1)),
    ("franka", dict(low_handle_pitch=35.0, pinch_gap=0.0, hold_parts=2, grip_lost_change=0.025, yaw_rate=30.0,
                    flap_min_radius_share=1.0, clearance_pitches=(40.0, 45.0, 50.0))),
])
def test_each_hand_carries_its_planner_numbers(hand, expected):
    from opend_mj.policy.planner import HandPlannerConfig
    from opend_mj.sim.hands import HANDS_DIR, load_spec

    assert (HANDS_DIR / hand / "planner.json").is_file()
    numbers = HandPlannerConfig.for_hand(load_spec(hand))
    for key, value in expected.items():
        assert getattr(numbers, key) == value, key


def test_a_hand_without_a_planner_file_gets_its_types_numbers(tmp_path):
    from opend_mj.policy.planner import HandPlannerConfig
    from opend_mj.sim.hands import load_spec

    gripper = dataclasses.replace(load_spec("franka"), name="my_gripper")
    numbers = HandPlannerConfig.for_hand(gripper, hands_dir=tmp_path)
    assert numbers.hold_parts == 2 and numbers.grip_lost_change == 0.012 and numbers.low_handle_pitch == 0.0
    dexterous = dataclasses.replace(load_spec("allegro"), name="my_hand")
    numbers = HandPlannerConfig.for_hand(dexterous, hands_dir=tmp_path)
    assert numbers.pinch_gap == 0.012 and numbers.low_handle_lift == 0.0 and numbers.grip_lost_change is None
    assert HandPlannerConfig.for_hand(None) == HandPlannerConfig()


@pytest.mark.parametrize("content, message", [
    ({"low_handle_lift": 0.02, "lift_twice": 1}, "unknown field 'lift_twice'"),
    ({"hold_parts": 0}, "hold_parts"),
    ({"pinch_gap": "wide"}, "'pinch_gap' must be a number"),
    ({"min_grasp_height": None, "low_handle_pitch": None}, "'low_handle_pitch' must be a number"),
    ({"clearance_pitches": [35, 120]}, "'clearance_pitches' must be a list of degrees"),
    ({"clearance_knob_turn": 1}, "'clearance_knob_turn' must be true or false"),
])
def test_a_bad_planner_file_is_named_in_the_error(tmp_path, content, message):
    from opend_mj.policy.planner import HandPlannerConfig

    path = tmp_path / "planner.json"
    path.write_text(json.dumps(content))
    with pytest.raises(ValueError, match=message) as err:
        HandPlannerConfig.load(path)
    assert str(path) in str(err.value)
    path.write_text("{not json")
    with pytest.raises(ValueError, match="planner.json"):
        HandPlannerConfig.load(path)


def test_the_planner_keeps_its_episode_state_in_one_record():
    """Per-episode state lives in ``Planner.state`` (an ``EpisodeState``), made anew by each run."""
    from opend_mj.policy.planner import EpisodeState, Planner, PlannerConfig

    planner = Planner(solver=None, spec=None, config=PlannerConfig())
    assert isinstance(planner.state, EpisodeState) and planner.state.hinge is None
    assert set(vars(planner)) == {"solver", "spec", "grasp", "config", "hand", "on_stage", "state"}


def test_the_hinge_side_is_inferred_only_where_configured():
    """A single door (no side in the instruction): the hinge side comes from depth where
    ``infer_hinge`` is on, and is unknown where it is off; a side the instruction names stands."""
    from types import SimpleNamespace

    from opend_mj.policy.perception import HandleEstimate
    from opend_mj.policy.planner import Planner, PlannerConfig
    from opend_mj.sim.camera import CameraIntrinsics, CameraView

    rot = np.column_stack([(0, -1, 0), (0, 0, 1), (-1, 0, 0)]).astype(float)
    view = CameraView(CameraIntrinsics.from_fovy(45, 256, 256), np.zeros(3), rot)
    cols, rows = np.meshgrid(np.arange(256) + 0.5, np.arange(256) + 0.5)
    on_plane = view.backproject(cols.ravel(), rows.ravel(), np.ones(cols.size))
    inside = (on_plane[:, 1] > -0.3) & (on_plane[:, 1] < 0.2) & (np.abs(on_plane[:, 2]) < 0.3)
    depth = np.where(inside, 1.0, 2.5).reshape(256, 256)
    handle = HandleEstimate(centre=np.array([0.96, 0.15, 0.0]), orientation="vertical", kind="bar",
                            size=(0.015, 0.2), front_x=0.953, panel_x=1.0)
    obs = SimpleNamespace(instruction="door", depth=depth, camera_view=view)
    on = Planner(solver=None, spec=None, config=PlannerConfig())
    assert on.hinge_side(handle, obs) == "right"
    off = Planner(solver=None, spec=None, config=PlannerConfig().override({"grasp.infer_hinge": False}))
    assert off.hinge_side(handle, obs) is None
    assert off.hinge_side(handle, SimpleNamespace(instruction="left door", depth=depth, camera_view=view)) == "left"
