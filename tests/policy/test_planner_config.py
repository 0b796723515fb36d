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
    from opend_mj.sim.hands import HANDS_DIR, get_hand

    assert (HANDS_DIR / hand / "planner.json").is_file()
    numbers = get_hand(hand).planner
    for key, value in expected.items():
        assert getattr(numbers, key) == value, key


@pytest.fixture
def forget_users_hands():
    """Users' hands registered by a test leave the registry after it."""
    from opend_mj.sim.hands import registry

    before = set(registry._REGISTRY)
    yield
    for name in set(registry._REGISTRY) - before:
        registry._REGISTRY.pop(name)


def test_a_hand_without_a_planner_file_gets_its_types_numbers(tmp_path, forget_users_hands):
    """A user's hand registered from a folder with no planner.json gets its type's numbers."""
    import shutil

    from opend_mj.policy.planner import HandPlannerConfig, Planner
    from opend_mj.sim.hands import HANDS_DIR, load_spec, register_hand

    for name, source in (("users_gripper", "franka"), ("users_hand", "allegro")):
        folder = tmp_path / name
        folder.mkdir()
        shutil.copy(HANDS_DIR / source / "hand.xml", folder / "hand.xml")
        spec = dataclasses.replace(load_spec(source), name=name)
        spec.save(folder / "spec.json")
        model = register_hand(name, folder / "hand.xml", folder / "spec.json", overwrite=True)
        assert model.grasp is None and model.folder == folder.resolve()
        if name == "users_gripper":
            assert model.planner.hold_parts == 2 and model.planner.grip_lost_change == 0.012
        else:
            assert model.planner.pinch_gap == 0.012 and model.planner.grip_lost_change is None
    assert Planner(None, None).hand == HandPlannerConfig()


def test_a_users_hand_is_planned_with_its_own_files(tmp_path, forget_users_hands):
    """register_hand honours the grasp.json and planner.json beside the user's model: the planner
    built for that hand uses them, and an unknown key in either is refused, naming the file and key."""
    import shutil

    from opend_mj.policy.factory import build_planner
    from opend_mj.sim.hands import HANDS_DIR, load_spec, register_hand

    folder = tmp_path / "users_allegro"
    folder.mkdir()
    shutil.copy(HANDS_DIR / "allegro" / "hand.xml", folder / "hand.xml")
    dataclasses.replace(load_spec("allegro"), name="users_allegro").save(folder / "spec.json")
    (folder / "planner.json").write_text(json.dumps({"hold_parts": 3, "hook_slide": 0.01}))
    (folder / "grasp.json").write_text(json.dumps({"hand": "users_allegro", "close_scale": 0.7,
                                                   "grasp_depth": {"bar": 0.002, "knob": 0.0},
                                                   "knob_orientation": "vertical"}))
    register_hand("users_allegro", folder / "hand.xml", folder / "spec.json", overwrite=True)
    planner = build_planner("oracle", "users_allegro", ground_truth=lambda: None)
    assert planner.hand.hold_parts == 3 and planner.hand.hook_slide == 0.01
    assert planner.config.grasp.close_scale == 0.7 and planner.config.grasp.depth["bar"] == 0.002
    assert planner.config.grasp.knob_orientation == "vertical"
    assert build_planner("oracle", "users_allegro", use_grasp_file=False,
                         ground_truth=lambda: None).config.grasp.close_scale == 1.0

    (folder / "grasp.json").write_text(json.dumps({"hand": "users_allegro", "close_scael": 0.7}))
    with pytest.raises(ValueError, match="unknown key 'close_scael'") as err:
        register_hand("users_allegro", folder / "hand.xml", folder / "spec.json", overwrite=True)
    assert str(folder / "grasp.json") in str(err.value)
    (folder / "grasp.json").unlink()
    spec = json.loads((folder / "spec.json").read_text())
    (folder / "spec.json").write_text(json.dumps({**spec, "finger_count": 4}))
    with pytest.raises(ValueError, match="unknown key 'finger_count'") as err:
        register_hand("users_allegro", folder / "hand.xml", folder / "spec.json", overwrite=True)
    assert str(folder / "spec.json") in str(err.value)


def test_an_oracle_needs_its_ground_truth_and_an_agent_may_not_have_it():
    from opend_mj.policy.factory import build_solver

    with pytest.raises(ValueError, match="ground_truth callback"):
        build_solver("oracle")
    with pytest.raises(ValueError, match="which an agent may not"):
        build_solver("oracle", ground_truth=lambda: None, for_agent=True)
    assert build_solver("oracle", ground_truth=lambda: (1, 2, 3, 4, 5)) is not None


@pytest.mark.parametrize("content, message", [
    ({"low_handle_lift": 0.02, "lift_twice": 1}, "unknown key 'lift_twice'"),
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
    """Per-episode state lives in one ``EpisodeState`` that every stage reads (made anew by each run);
    the planner itself holds its solver, its stage context and its stages, nothing of an episode."""
    from opend_mj.policy.planner import EpisodeState, Planner, PlannerConfig, Stage

    planner = Planner(solver=None, hand=None, config=PlannerConfig())
    assert isinstance(planner.state, EpisodeState) and planner.state.hinge is None
    stages = {"front", "grasping", "approach", "kind", "flap", "slide", "pulling", "recovery", "takeover"}
    assert set(vars(planner)) == {"solver", "ctx"} | stages
    fresh = EpisodeState()
    planner.state = fresh
    for name in stages:
        stage = getattr(planner, name)
        assert isinstance(stage, Stage) and stage.episode is fresh and set(vars(stage)) <= {
            "ctx", "solver", "front", "approach", "kind", "flap", "slide", "grasping", "recovery"}


def test_the_hinge_side_is_inferred_only_where_configured(door_plane):
    """A single door (no side in the instruction): the hinge side comes from depth where
    ``infer_hinge`` is on, and is unknown where it is off; a side the instruction names stands."""
    from types import SimpleNamespace

    from opend_mj.policy.perception import HandleEstimate
    from opend_mj.policy.planner import Planner, PlannerConfig

    view, depth = door_plane(-0.3, 0.2)
    handle = HandleEstimate(centre=np.array([0.96, 0.15, 0.0]), orientation="vertical", kind="bar",
                            size=(0.015, 0.2), front_x=0.953, panel_x=1.0)
    obs = SimpleNamespace(instruction="door", depth=depth, camera_view=view)
    on = Planner(solver=None, hand=None, config=PlannerConfig())
    assert on.grasping.hinge_side(handle, obs) == "right"
    off = Planner(solver=None, hand=None, config=PlannerConfig().override({"grasp.infer_hinge": False}))
    assert off.grasping.hinge_side(handle, obs) is None
    assert off.grasping.hinge_side(handle, SimpleNamespace(instruction="left door", depth=depth, camera_view=view)) == "left"
