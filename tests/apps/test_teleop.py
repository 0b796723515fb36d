"""Teleoperation without a display: scripted key events open a drawer; demos record and replay exactly;
the human study writes `opend run` records; the CLI help documents the key map."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from opend_mj.apps.teleop import (KEYMAP, TeleopConfig, TeleopController, gamepad_motion, key_name, presses, steps,
                             teleop_config)

#: procedural cabinet (index, seed) of a generator made to sample single drawers with horizontal bars.
DRAWER_SOURCE = (1, 0)
DRAWER_ONLY = dict(invalid_fraction=0.0, valid_layouts=(("single_drawer", 1.0),), nightstand_share=0.0,
                   drawer_handle_kinds=(1.0, 0.0, 0.0), drawer_vertical_share=0.0)
HAND = "franka"


@pytest.fixture(scope="module")
def drawer_cabinet(tmp_path_factory):
    from opend_mj.assets.compiler import compile_cabinet
    from opend_mj.assets.procedural import GeneratorConfig, generate_source

    root = tmp_path_factory.mktemp("teleop_cabinets")
    source = generate_source(*DRAWER_SOURCE, root / "sources", GeneratorConfig(**DRAWER_ONLY))
    result = compile_cabinet(source, root / "cabinets", cache_dir=root / "cache")
    assert result.status == "built", f"{result.reason}: {result.message}"
    target = result.info["targets"][0]
    assert target["type"] == "drawer" and target["handle"]["orientation"] == "horizontal", target
    return root / "cabinets" / source.name, target


def _env(cabinet_dir, joint, hand=HAND, seed=0):
    from opend_mj.sim.task import EpisodeSpec, make_environment

    return make_environment(EpisodeSpec(cabinet_dir, joint, hand, seed=seed), teleop_config())


def _drawer_script(ctl: TeleopController) -> list:
    """Key presses that bring the grasp site to the handle (counted from ground truth: test only),
    close the grip and pull back."""
    task, physics = ctl.task, ctl.physics
    centre = task.handle_corners(physics).mean(axis=0)
    site = physics.bind(task.hand.grasp_site).xpos.copy()
    delta = centre - np.array([ctl.spec.approach_offset, 0.0, 0.0]) - site
    step = ctl.step_size

    def keys(d, pos, neg):
        n = int(round(d / step))
        return presses(pos, n) if n > 0 else presses(neg, -n)

    standoff = 0.08
    script = keys(delta[1], "a", "d") + keys(delta[2], "r", "f") + keys(delta[0] - standoff, "w", "s")
    script += [steps(60)] + keys(standoff, "w", "s") + [steps(60)]
    script += ["space", ("wait_s", ctl.spec.close_time + 0.4)]
    script += presses("s", 22) + [("wait_s", 1.0), "enter"]
    return script


@pytest.fixture(scope="module")
def recorded(drawer_cabinet, tmp_path_factory):
    """The scripted drawer episode, recorded and written to an .npz demo file."""
    from opend_mj.apps.demos import DemoRecorder, write_demos

    cabinet_dir, target = drawer_cabinet
    env = _env(cabinet_dir, target["joint"])
    try:
        recorder = DemoRecorder()
        ctl = TeleopController(env, recorder=recorder)
        ctl.apply(_drawer_script(ctl))
        outcome = ctl.outcome()
        demo = recorder.finish(ctl)
        final_qpos = env.physics.data.qpos.copy()
    finally:
        env.close()
    path = write_demos(tmp_path_factory.mktemp("demos") / "demos.npz", [demo], append=False)
    return {"outcome": outcome, "demo": demo, "path": path, "final_qpos": final_qpos, "ctl_done": ctl.done}


# --------------------------------------------------------------------------------------------------
def test_key_names_and_map():
    assert key_name("W") == "w" and key_name(87) == "w" and key_name(ord("a")) == "a"
    assert key_name(32) == key_name(" ") == key_name("SPACE") == "space"
    assert key_name(257) == key_name("Return") == "enter" and key_name(259) == "backspace"
    assert [key_name(c) for c in (265, 264, 263, 262)] == ["up", "down", "left", "right"]
    assert key_name(91) == "[" and key_name(93) == "]"
    assert key_name(1000) is None and key_name("") is None
    needed = set("wsadrfqeg[]") | {"up", "down", "left", "right", "space", "enter", "backspace"}
    assert needed <= set(KEYMAP)


def test_gamepad_motion_dead_zone_and_directions():
    cfg = TeleopConfig()
    dpos, drot = gamepad_motion([0.05, -0.1, -1, 0, 0, -1], 0.1, cfg)  # inside the dead zone, triggers rest
    assert np.allclose(dpos, 0) and np.allclose(drot, 0)
    dpos, drot = gamepad_motion([0, -1, -1, 0, 0, -1], 0.1, cfg)  # left stick pushed forward
    assert dpos[0] == pytest.approx(cfg.pad_speed * 0.1) and np.allclose(dpos[1:], 0)
    dpos, drot = gamepad_motion([0, 0, -1, 1, 0, 1], 0.1, cfg)  # right stick right, right trigger
    assert drot[2] < 0 and drot[1] > 0


def test_controller_keys(drawer_cabinet):
    cabinet_dir, target = drawer_cabinet
    env = _env(cabinet_dir, target["joint"])
    try:
        ctl = TeleopController(env)
        spec = ctl.spec
        start_pos, start_quat = (np.array(x) for x in ctl.task.start_pose)
        a = ctl.action()
        assert a.shape == (7 + len(spec.actuator_names),)
        assert np.allclose(a[:3], start_pos) and np.allclose(a[7:], spec.open_pose)
        ctl.apply(["w", "w", "a", "r", "f"])
        assert np.allclose(ctl.target_pos - start_pos, [0.02, 0.01, 0.0])
        ctl.apply(["]", "s"])
        assert ctl.step_size == pytest.approx(0.02)
        assert np.allclose(ctl.target_pos - start_pos, [0.0, 0.01, 0.0])
        ctl.apply(["[", "[", "[", "[", "[", "[", "[", "["])
        assert ctl.step_size == pytest.approx(ctl.config.min_step)
        # yaw: rotation about world z by rot_step (scaled with the step size)
        ctl.step_size = ctl.config.step
        q0 = ctl.target_quat.copy()
        ctl.handle_key("q")
        angle = 2 * np.arccos(min(1.0, abs(float(np.dot(q0, ctl.target_quat)))))
        assert angle == pytest.approx(ctl.config.rot_step)
        ctl.handle_key("e")
        assert abs(float(np.dot(q0, ctl.target_quat))) == pytest.approx(1.0)
        # grip ramps to the grasp profile over close_time, and back
        ctl.handle_key("space")
        assert ctl.grip_goal == 1.0 and ctl.grip == 0.0
        n_close = int(np.ceil(spec.close_time * ctl.task.config.control_hz))
        ctl.step(n_close // 2)
        assert 0.3 < ctl.grip < 0.7
        ctl.step(n_close)
        assert ctl.grip == 1.0 and np.allclose(ctl.action()[7:], spec.grasp_profile("horizontal"))
        # profile toggle: vertical profile and hand orientation
        from opend_mj.sim.hands import orientation_for_handle

        ctl.handle_key("g")
        assert ctl.profile == "vertical"
        assert np.allclose(ctl.action()[7:], spec.grasp_profile("vertical"))
        assert abs(float(np.dot(ctl.target_quat, orientation_for_handle("vertical")))) == pytest.approx(1.0)
        ctl.handle_key(32)  # GLFW space: open again
        ctl.step(n_close + 1)
        assert ctl.grip == 0.0 and np.allclose(ctl.action()[7:], spec.open_pose)
        # reset (BACKSPACE) puts everything back; ENTER ends
        assert ctl.handle_key(259) == "reset"
        assert np.allclose(ctl.target_pos, start_pos) and ctl.profile == "horizontal" and ctl.steps == 0
        assert env.physics.data.time == 0.0
        assert ctl.handle_key("x") is None and not ctl.done
        ctl.apply(["enter", "w"])  # stops at ENTER
        assert ctl.done and np.allclose(ctl.target_pos, start_pos)
        labels = [r[0] for r in ctl.status_lines()]
        assert labels[:2] == ["instruction", "open ratio"]
    finally:
        env.close()


def test_scripted_keys_open_drawer(recorded):
    outcome = recorded["outcome"]
    assert recorded["ctl_done"]
    assert outcome.open_ratio > 0.2 and outcome.success, outcome
    assert outcome.others_moved == []


def test_demo_file_layout(recorded, drawer_cabinet):
    from opend_mj.apps.demos import FORMAT, OBS_KEYS, read_demos

    demo = recorded["demo"]
    file_attrs, demos = read_demos(recorded["path"])
    assert file_attrs["format"] == FORMAT and file_attrs["total"] == demo.num_samples
    args = json.loads(file_attrs["env_args"])
    assert args["env_name"] == "OpenCabinet" and args["env_kwargs"]["control_hz"] == 60.0
    assert len(demos) == 1
    d = demos[0]
    T = d.num_samples
    assert d.actions.shape == (T, 7 + 2) and T > 100
    assert set(d.obs) == set(OBS_KEYS)
    assert d.obs["root_pos"].shape == (T, 3) and d.obs["root_quat"].shape == (T, 4)
    assert d.obs["hand_joint_pos"].shape == (T, 2) and d.obs["open_ratio"].shape == (T,)
    assert d.obs["open_ratio"][0] == 0.0 and d.final["open_ratio"][0] == pytest.approx(d.attrs["open_ratio"])
    a = d.attrs
    assert a["instruction"] == drawer_cabinet[1]["instruction"] and a["target_joint"] == drawer_cabinet[1]["joint"]
    assert a["hand"] == HAND and a["seed"] == 0 and a["success"] is True and a["num_samples"] == T
    assert a["cabinet"] == drawer_cabinet[0].name and isinstance(a["room"], int)
    assert np.array_equal(d.actions, demo.actions)


def test_replay_matches_recording(recorded):
    from opend_mj.apps.demos import load_demo, replay_demo

    demo, args = load_demo(recorded["path"], 0)
    result = replay_demo(demo, args)
    assert abs(result.open_ratio - demo.attrs["open_ratio"]) <= 1e-9
    assert np.allclose(result.final_qpos, recorded["final_qpos"], atol=1e-9, rtol=0)
    assert np.allclose(result.obs["root_pos"], demo.obs["root_pos"], atol=1e-6, rtol=0)  # stored as float32


def test_append_and_hdf5(recorded, tmp_path):
    from opend_mj.apps.demos import read_demos, write_demos

    demo = recorded["demo"]
    p = tmp_path / "two.npz"
    write_demos(p, [demo])
    write_demos(p, [demo])  # appended
    attrs, demos = read_demos(p)
    assert len(demos) == 2 and attrs["total"] == 2 * demo.num_samples
    h = write_demos(tmp_path / "demos.hdf5", [demo])
    attrs, demos = read_demos(h)
    assert demos[0].attrs["open_ratio"] == demo.attrs["open_ratio"]
    assert np.array_equal(demos[0].actions, demo.actions)


def test_replay_cli(recorded):
    from opend_mj.cli import main

    res = CliRunner().invoke(main, ["replay", str(recorded["path"]), "--demo", "0"])
    assert res.exit_code == 0, res.output
    assert "OK" in res.output and f"{recorded['demo'].attrs['open_ratio']:.9f}" in res.output
    res = CliRunner().invoke(main, ["replay", str(recorded["path"]), "--demo", "3"])
    assert res.exit_code != 0


def test_teleop_help_documents_keys():
    from opend_mj.cli import main

    res = CliRunner().invoke(main, ["teleop", "--help"])
    assert res.exit_code == 0
    for word in ("W / S", "A / D", "R / F", "Q / E", "SPACE", "BACKSPACE", "ENTER", "[ / ]", "--study"):
        assert word in res.output


def test_study_writes_run_records(drawer_cabinet, tmp_path):
    from opend_mj.assets.layout import Manifest
    from opend_mj.evaluation.results import load_results
    from opend_mj.apps.teleop import run_study, sample_study

    cabinet_dir, target = drawer_cabinet
    cab = {"id": cabinet_dir.name, "split": "test", "path": cabinet_dir.name,
           "targets": [{"joint": target["joint"], "type": target["type"], "instruction": target["instruction"]}]}
    Manifest(cabinets=[cab]).save(cabinet_dir.parent)
    tasks = sample_study(cabinet_dir.parent, 2, seed=3)
    assert len(tasks) == 2 and tasks == sample_study(cabinet_dir.parent, 2, seed=3)

    def play(ctl):  # a person who gives up at once
        ctl.apply([steps(5), "enter"])

    out = tmp_path / "human.jsonl"
    records = run_study(tasks, HAND, play, out)
    loaded = load_results(out)
    assert loaded == json.loads(json.dumps(records)) and len(loaded) == 2
    fields = ("cabinet", "joint", "type", "instruction", "hand", "solver", "split", "seed", "room", "success",
              "open_ratio", "range_ratio", "joint_value", "others_moved", "failed_stage", "sim_seconds",
              "wall_seconds")
    for r in loaded:
        assert set(fields) <= set(r)
        assert r["solver"] == "human" and r["split"] == "test" and r["success"] is False
        assert r["failed_stage"] == "pull" and r["sim_seconds"] == pytest.approx(5 / 60, abs=1e-3)
