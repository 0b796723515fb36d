"""Hands: DoF, actuators, mocap hold, bar grasp-and-pull, spec/registry, rendering."""

from __future__ import annotations

import json
import os
import shutil

os.environ.setdefault("MUJOCO_GL", "egl")  # before mujoco is imported

import mujoco
import numpy as np
import pytest
from dm_control import mjcf

from opend_mj import transforms
from opend_mj.sim import hands
from opend_mj.sim.hands import scene as hand_scene

EXPECTED_DOF = {"franka": 2, "allegro": 16, "shadow": 20, "skeleton": 20}


@pytest.mark.parametrize("name", sorted(EXPECTED_DOF))
def test_dof_and_structure(name):
    spec = hands.load_spec(name)
    assert spec.dof == EXPECTED_DOF[name]
    hand = hands.Hand(name)
    model = hand.mjcf_model
    assert not model.find_all("body") or all(not getattr(b, "mocap", False)
                                            for b in model.find_all("body"))
    assert all(j.tag != "freejoint" for j in model.find_all("joint"))
    physics = mjcf.Physics.from_mjcf_model(model)
    assert physics.model.nu == spec.dof and physics.model.njnt == spec.dof
    assert hand.grasp_site is not None and hand.root_body is not None
    # every actuator has a range and a force limit; every joint a range
    for a in hand.actuators:
        assert a.forcerange is not None and a.ctrlrange is not None
    for j in hand.joints:
        assert j.range is not None
    mass = physics.model.body_mass.sum()
    assert 0.3 < mass < 1.5, mass


def _air_scene(name):
    root, handle = hand_scene.build_scene(name, pos=(0, 0, 0.5))
    physics = mjcf.Physics.from_mjcf_model(root)
    return physics, handle


@pytest.mark.parametrize("name", sorted(EXPECTED_DOF))
def test_actuator_sweep(name):
    """Each actuator drives its joint through most of its range, in the air, one at a time, against
    gravity and joint friction (self-contacts off: the thumb may legitimately meet a finger)."""
    physics, handle = _air_scene(name)
    m, d = physics.model.ptr, physics.data.ptr
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    spec = handle.hand.spec
    jb = physics.bind(handle.hand.joints)
    ab = physics.bind(handle.hand.actuators)
    open_pose = np.asarray(spec.open_pose)
    qadr = jb.qposadr
    thumb = [i for i, j in enumerate(spec.joint_names) if spec.joint_roles.get(j, "").startswith("thumb")]
    opp = [i for i in thumb if spec.joint_roles[spec.joint_names[i]] == "thumb_opp"]
    for i in range(spec.dof):
        lo, hi = ab.ctrlrange[i]
        reached = []
        for target in (lo, hi):
            ctrl = open_pose.copy()
            if i in thumb and i not in opp:  # thumb in front of the palm, clear of the fingers
                ctrl[opp] = ab.ctrlrange[opp, 1]
            ctrl[i] = target
            d.ctrl[ab.element_id] = ctrl
            for _ in range(300):
                mujoco.mj_step(m, d)
            reached.append(d.qpos[qadr[i]])
        span = reached[1] - reached[0]
        assert span > 0.8 * (hi - lo), (spec.actuator_names[i], reached, (lo, hi))


@pytest.mark.parametrize("name", sorted(EXPECTED_DOF))
def test_still_in_air(name):
    """A hand held on its mocap weld under gravity neither drifts nor jitters (< 1 mm over 2 s)."""
    physics, handle = _air_scene(name)
    m, d = physics.model.ptr, physics.data.ptr
    handle.hand.set_finger_targets(physics, handle.hand.spec.open_pose)
    start = physics.bind(handle.hand.root_body).xpos.copy()
    worst = 0.0
    for _ in range(1000):
        mujoco.mj_step(m, d)
        worst = max(worst, np.linalg.norm(physics.bind(handle.hand.root_body).xpos - start))
    assert worst < 1e-3, worst
    assert np.abs(d.qvel[:6]).max() < 1e-2


@pytest.mark.parametrize("orientation", ["horizontal", "vertical"])
@pytest.mark.parametrize("name", sorted(EXPECTED_DOF))
def test_grasp_and_pull_bar(name, orientation):
    """Approach, close with the grasp profile, pull: the damped, frictional bar follows >= 10 cm."""
    bar = hand_scene.BarConfig(damping=40.0, frictionloss=8.0, radius=0.0065)
    r = hand_scene.bar_pull_trial(name, orientation, bar=bar, pull_distance=0.15)
    assert r.bar_moved > 0.12, r  # at least 10 cm with margin
    assert r.slip < 0.01, r


def test_grasp_pose_roundtrip():
    spec = hands.load_spec("allegro")
    for o in ("horizontal", "vertical"):
        q = hands.orientation_for_handle(o)
        rmat = transforms.quat_to_mat(q)
        assert np.allclose(rmat[:, 2], [1, 0, 0])  # approach +x
        axis = [0, 1, 0] if o == "horizontal" else [0, 0, -1]
        assert np.allclose(rmat[:, 0], axis)
        site = np.array([0.4, 0.1, 0.7])
        rp, rq = hands.grasp_pose_to_root_pose(spec, site, q)
        sp, sq = hands.root_pose_to_grasp_pose(spec, rp, rq)
        assert np.allclose(sp, site) and np.allclose(np.abs(sq @ q), 1.0)


def test_mocap_attachment_names_and_site_placement():
    root, handle = hand_scene.build_scene("shadow")
    physics = mjcf.Physics.from_mjcf_model(root)
    q = hands.orientation_for_handle("vertical")
    site = np.array([0.3, -0.1, 0.8])
    handle.reset_pose(physics, *hands.grasp_pose_to_root_pose(handle.hand.spec, site, q))
    physics.forward()
    pos, quat = handle.grasp_site_pose(physics)
    assert np.allclose(pos, site, atol=1e-6)
    assert np.isclose(abs(quat @ q), 1.0, atol=1e-6)
    assert handle.grasp_site_name.endswith("grasp_site")
    assert physics.model.name2id(handle.mocap_body_name, "body") >= 0
    assert physics.model.neq == 1


def test_spec_roundtrip_and_user_registry(tmp_path):
    spec = hands.load_spec("skeleton")
    path = tmp_path / "spec.json"
    spec.save(path)
    assert hands.HandSpec.load(path) == spec
    assert json.loads(path.read_text())["dof"] == 20
    # a user hand: any MJCF + spec, from a tmp dir
    user_dir = tmp_path / "myhand"
    user_dir.mkdir()
    shutil.copy(hands.HANDS_DIR / "franka" / "hand.xml", user_dir / "gripper.xml")
    user_spec = hands.load_spec("franka").to_dict()
    user_spec["name"] = "my_gripper"
    (user_dir / "spec.json").write_text(json.dumps(user_spec))
    hands.register_hand("my_gripper", user_dir / "gripper.xml", user_dir / "spec.json")
    assert "my_gripper" in hands.list_hands()
    assert set(EXPECTED_DOF) <= set(hands.list_hands())
    assert hands.get_hand("my_gripper").spec.dof == 2
    hand = hands.Hand("my_gripper")
    assert hand.spec.name == "my_gripper"
    with pytest.raises(KeyError):
        hands.get_hand("nope")
    with pytest.raises(ValueError):
        hands.HandSpec.from_dict(dict(user_spec, dof=3))


def test_render_png(tmp_path):
    os.environ.setdefault("MUJOCO_GL", "egl")
    from click.testing import CliRunner
    from PIL import Image

    from opend_mj.cli import main

    out = tmp_path / "hand.png"
    res = CliRunner().invoke(main, ["render-hand", "allegro", "--out", str(out), "--width", "160",
                                    "--height", "120"])
    assert res.exit_code == 0, res.output
    img = np.asarray(Image.open(out).convert("RGB")).astype(float)
    assert img.shape == (120, 160, 3)
    assert img.std() > 10  # not blank
