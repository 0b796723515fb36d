"""The dm_control task: scenes in every room, success checker, determinism, headless RGB-D, actions."""

from __future__ import annotations

import numpy as np
import pytest

from opend_mj.sim.rooms import ROOM_NAMES
from opend_mj.sim.task import EpisodeSpec, TaskConfig, make_environment


def _cabinet_with(proc_cabinets, kind):
    for c in proc_cabinets:
        for t in c.info["targets"]:
            if t["type"] == kind:
                return c, t
    pytest.fail(f"no {kind} among the procedural test cabinets (conftest.proc_cabinets should hold one)")


@pytest.fixture(scope="module")
def drawer_case(proc_cabinets):
    return _cabinet_with(proc_cabinets, "drawer")


@pytest.fixture(scope="module")
def door_case(proc_cabinets):
    return _cabinet_with(proc_cabinets, "door")


def _hold(env, steps):
    """Keep the hand at its start pose with open fingers for `steps` control steps."""
    task = env.task
    action = task.make_action(*task.start_pose, task.hand.spec.open_pose)
    for _ in range(steps):
        env.step(action)


@pytest.mark.parametrize("room", range(len(ROOM_NAMES)))
def test_every_room_renders_and_cabinet_stays_shut_10s(room, door_case, drawer_case):
    cabinet, target = (door_case, drawer_case)[room % 2]
    env = make_environment(EpisodeSpec(cabinet.dir, target["joint"], "allegro", seed=room, room=room),
                           TaskConfig(enable_rgbd=room == 0))
    try:
        ts = env.reset()
        if room == 0:
            rgb, depth = ts.observation["rgb"], ts.observation["depth"]
            assert rgb.shape == (256, 256, 3) and rgb.dtype == np.uint8 and rgb.std() > 5
            assert depth.shape[:2] == (256, 256) and np.isfinite(depth).all() and 0.1 < depth.min() < 5
        before = env.task.cabinet.joint_values(env.physics)
        _hold(env, int(10 * env.task.config.control_hz))
        after = env.task.cabinet.joint_values(env.physics)
        assert env.physics.data.time == pytest.approx(10.0, abs=0.02)
        for t in env.task.cabinet.targets:
            moved = abs(after[t.joint] - before[t.joint]) / (t.upper - t.lower)
            assert moved < 0.01, f"{t.joint} self-opened by {moved:.1%} of its range in room {room}"
        assert np.abs(env.physics.bind(env.task.cabinet.mjcf_model.find_all("joint")).qvel).max() < 1e-3
    finally:
        env.close()


def test_success_checker_scripted_values(drawer_case, door_case):
    for cabinet, target in (drawer_case, door_case):
        env = make_environment(EpisodeSpec(cabinet.dir, target["joint"], "franka", seed=0),
                               TaskConfig(enable_rgbd=False))
        try:
            env.reset()
            task, physics = env.task, env.physics
            checker = task.checker
            closed = {t.joint: t.closed for t in task.cabinet.targets}
            out = checker.check_values(closed)
            assert not out.success and out.open_ratio == 0 and out.others_moved == []
            tgt = task.target
            if tgt.kind == "drawer":
                q_open = tgt.closed + tgt.open_sign * 0.25 * tgt.drawer_length
                q_small = tgt.closed + tgt.open_sign * 0.15 * tgt.drawer_length
                assert checker.check_values({**closed, tgt.joint: q_open}).open_ratio == pytest.approx(0.25)
            else:
                q_open = tgt.closed + tgt.open_sign * np.deg2rad(45)  # 45 / 180 = 25 %
                q_small = tgt.closed + tgt.open_sign * np.deg2rad(30)
            assert checker.check_values({**closed, tgt.joint: q_open}).success
            assert not checker.check_values({**closed, tgt.joint: q_small}).success
            # The checker reads the simulator: set the joint in physics, as a scripted opening would.
            physics.bind(task.cabinet.joint_element(tgt.joint)).qpos = q_open
            physics.forward()
            outcome = task.outcome(physics)
            assert outcome.success and outcome.joint_value == pytest.approx(q_open)
            # Wrong target: another door/drawer opened, the instructed one closed -> failure, recorded.
            others = [t for t in task.cabinet.targets if t.joint != tgt.joint]
            if others:
                o = others[0]
                wrong = {**closed, o.joint: o.closed + o.open_sign * 0.9 * o.open_travel}
                result = checker.check_values(wrong)
                assert not result.success and result.others_moved == [o.joint]
        finally:
            env.close()


def test_same_seed_same_first_image_and_instruction(door_case):
    cabinet, target = door_case
    images = []
    for seed in (5, 5, 6):
        env = make_environment(EpisodeSpec(cabinet.dir, target["joint"], "shadow", seed=seed))
        try:
            ts = env.reset()
            images.append((ts.observation["rgb"].copy(), str(ts.observation["instruction"])))
        finally:
            env.close()
    assert np.array_equal(images[0][0], images[1][0]) and images[0][1] == images[1][1] == target["instruction"]
    assert not np.array_equal(images[0][0], images[2][0])


def test_oracle_boxes_lie_on_the_handles(door_case):
    cabinet, target = door_case
    env = make_environment(EpisodeSpec(cabinet.dir, target["joint"], "allegro", seed=1))
    try:
        ts = env.reset()
        boxes = env.task.handle_boxes(env.physics)
        depth = ts.observation["depth"].squeeze()
        view = env.task.camera_view(env.physics)
        for t in env.task.cabinet.targets:
            u0, v0, u1, v1 = boxes[t.joint]
            assert 0 <= u0 < u1 <= 256 and 0 <= v0 < v1 <= 256
            u, v = (u0 + u1) / 2, (v0 + v1) / 2
            point = view.backproject(u, v, depth[int(v), int(u)])
            lo, hi = t.handle_box
            assert np.all(point > lo - 0.03) and np.all(point < hi + 0.03), (t.joint, point, lo, hi)
    finally:
        env.close()


def test_root_moves_only_at_bounded_speed_and_bad_actions_raise(drawer_case):
    cabinet, target = drawer_case
    config = TaskConfig(enable_rgbd=False)
    env = make_environment(EpisodeSpec(cabinet.dir, target["joint"], "allegro", seed=0), config)
    try:
        env.reset()
        task = env.task
        pos0, quat0 = task.start_pose
        far = pos0 + np.array([0.0, -1.0, 0.0])
        env.step(task.make_action(far, quat0, task.hand.spec.open_pose))
        mocap_pos, _ = task.mocap.mocap_pose(env.physics)
        assert np.linalg.norm(mocap_pos - pos0) <= config.max_root_speed / config.control_hz + 1e-9
        for bad in (np.nan, np.inf):
            action = task.make_action(far, quat0, task.hand.spec.open_pose)
            action[0] = bad
            with pytest.raises(ValueError, match="non-finite"):
                env.step(action)
    finally:
        env.close()


def test_low_light_is_darker(door_case):
    cabinet, target = door_case
    means = []
    for scale in (1.0, 0.7):
        env = make_environment(EpisodeSpec(cabinet.dir, target["joint"], "allegro", seed=2, room=1),
                               TaskConfig(light_scale=scale))
        try:
            means.append(env.reset().observation["rgb"].mean())
        finally:
            env.close()
    assert means[1] < 0.92 * means[0]


def test_gymnasium_wrapper(drawer_case):
    from opend_mj.sim.gym_env import OpenDGymEnv

    cabinet, target = drawer_case
    env = OpenDGymEnv(EpisodeSpec(cabinet.dir, target["joint"], "franka", seed=0))
    try:
        obs, info = env.reset(seed=3)
        assert env.observation_space.contains(obs)
        assert info["instruction"] == target["instruction"] and info["outcome"]["open_ratio"] == 0.0
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        assert obs["rgb"].shape == (256, 256, 3) and not terminated and reward == 0.0
    finally:
        env.close()


def test_fast_environment_matches_composer_loop(drawer_case):
    """The tight substep loop must simulate exactly what composer's hook-per-substep loop does."""
    from dm_control import composer

    from opend_mj.sim.environment import OpenDEnvironment
    from opend_mj.sim.task import OpenCabinetTask

    cabinet, target = drawer_case
    episode = EpisodeSpec(cabinet.dir, target["joint"], "allegro", seed=0)
    finals, observations = [], []
    for cls in (composer.Environment, OpenDEnvironment):
        task = OpenCabinetTask(episode, TaskConfig(enable_rgbd=False))
        env = cls(task, time_limit=10, random_state=0, strip_singleton_obs_buffer_dim=True)
        try:
            env.reset()
            pos, quat = task.start_pose
            closed = task.hand.spec.grasp_profiles["horizontal"]
            for k in range(90):
                fingers = closed if k > 45 else task.hand.spec.open_pose
                ts = env.step(task.make_action(pos + np.array([0.3 * min(k / 45, 1), -0.2, 0.05]), quat, fingers))
            observations.append(ts.observation)
            finals.append((env.physics.bind(task.hand.root_body).xpos.copy(),
                           env.physics.bind(task.hand.joints).qpos.copy()))
        finally:
            env.close()
    assert np.abs(finals[0][0] - finals[1][0]).max() < 1e-6
    assert np.abs(finals[0][1] - finals[1][1]).max() < 1e-3
    # direct observation reads give what composer's observation buffers give
    assert list(observations[0]) == list(observations[1])
    for name in observations[0]:
        a, b = observations[0][name], observations[1][name]
        assert a.shape == b.shape and a.dtype == b.dtype, name
        if a.dtype.kind == "f":
            assert np.abs(a - b).max() < 1e-3, name
        else:
            assert np.array_equal(a, b), name


def test_retargeted_scene_starts_like_a_new_one(proc_cabinets):
    """`set_target` reuses the compiled scene for another target: same start as a scene of its own."""
    cabinet = next((c for c in proc_cabinets if len(c.info["targets"]) >= 2), None)
    assert cabinet is not None, "conftest.proc_cabinets holds a double door, so a cabinet with two targets"
    target, *rest = cabinet.info["targets"]
    others = [t["joint"] for t in rest]
    config = TaskConfig(enable_rgbd=False)
    env = make_environment(EpisodeSpec(cabinet.dir, target["joint"], "allegro", seed=3), config)
    fresh = make_environment(EpisodeSpec(cabinet.dir, others[0], "allegro", seed=3), config)
    try:
        env.reset()
        pos, quat = env.task.start_pose
        for _ in range(20):  # move things about first
            env.step(env.task.make_action(pos + np.array([0.2, 0.0, 0.0]), quat, env.task.hand.spec.open_pose))
        env.task.set_target(others[0])
        first, ref = env.reset(), fresh.reset()
        assert env.task.instruction == fresh.task.instruction
        assert env.task.target.joint == others[0]
        assert np.array_equal(env.physics.data.qpos, fresh.physics.data.qpos)
        assert np.array_equal(env.physics.data.mocap_pos, fresh.physics.data.mocap_pos)
        assert env.physics.data.time == 0.0
        for name in ref.observation:
            assert np.array_equal(first.observation[name], ref.observation[name]), name
    finally:
        env.close()
        fresh.close()


def _slerp_every_row(q, target, step_angle, n):
    """The mocap's bounded-speed slerp path computed row by row to the end (the reference)."""
    import math

    q = np.asarray(q, float) / math.sqrt(sum(float(x) * float(x) for x in q))
    t = np.asarray(target, float) / math.sqrt(sum(float(x) * float(x) for x in target))
    q0, q1, q2, q3 = (float(x) for x in q)
    t0, t1, t2, t3 = (float(x) for x in t)
    dot = q0 * t0 + q1 * t1 + q2 * t2 + q3 * t3
    if dot < 0:
        t0, t1, t2, t3, dot = -t0, -t1, -t2, -t3, -dot
    angle = 2 * math.acos(min(1.0, dot))
    half = angle / 2
    rows = []
    for k in range(1, n + 1):
        s = min(k * step_angle / angle, 1.0)
        a, b = math.sin((1 - s) * half) / math.sin(half), math.sin(s * half) / math.sin(half)
        x = (a * q0 + b * t0, a * q1 + b * t1, a * q2 + b * t2, a * q3 + b * t3)
        norm = math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2] + x[3] * x[3])
        rows.append(tuple(v / norm for v in x))
    return np.array(rows)


def test_slerp_path_repeats_the_arrival_row_and_says_where_it_arrives():
    from opend_mj.sim.mocap_path import MocapPathPlanner

    planner = MocapPathPlanner(8, 0.75 / 480, 4 / 480)
    rng = np.random.default_rng(0)
    arrived_early = 0
    for _ in range(500):
        q = rng.normal(size=4)
        target = q / np.linalg.norm(q) + rng.normal(size=4) * rng.choice([0.003, 0.02, 0.5])
        path, writes = planner.slerp(q.tolist(), target.tolist())
        path = np.array(path)
        assert path.tobytes() == _slerp_every_row(q, target, 4 / 480, 8).tobytes()
        assert 1 <= writes <= 8 and (path[writes - 1:] == path[-1]).all()
        arrived_early += writes < 8
    assert arrived_early > 50


@pytest.mark.parametrize("compiled", [False, True])
def test_substeps_after_the_mocap_arrives_in_one_call_match_one_call_per_substep(door_case, compiled):
    """`fast_substeps` runs the substeps after the mocap reaches its target pose as one mj_step(n)
    call: the same state, to the bit, as writing every row of the path and stepping once each (the
    Python step's and the compiled step's)."""
    import mujoco

    cabinet, target = door_case
    env = make_environment(EpisodeSpec(cabinet.dir, target["joint"], "allegro", seed=0),
                           TaskConfig(enable_rgbd=False, compiled_step=compiled), observations=False)
    try:
        env.reset()
        task, physics = env.task, env.physics
        if compiled and task._fast is None:
            pytest.skip("the compiled step is not available here (no C compiler, or OPEND_FASTSTEP=0)")
        model, data = physics.model.ptr, physics.data.ptr
        quat = task.start_pose[1]
        mid = task._mocap_id
        copy = mujoco.MjData(model)
        merged = 0
        kinds = set()
        for k in range(60):
            # toward the cabinet from where the mocap is: within its top speed (1.25 cm per control
            # step) on two steps of three, beyond it on the third; turning a little, or not at all
            delta = np.array([0.002 + 0.006 * (k % 3), 0.001 * np.sin(k), 0.0])
            if k % 5 == 4:  # turning where it stands
                delta = np.zeros(3)
            quat = quat + 0.004 * (k % 4) * np.array([np.cos(k * 0.1), 0, 0, np.sin(k * 0.1)])
            action = task.make_action(data.mocap_pos[mid] + delta, quat / np.linalg.norm(quat),
                                      task.hand.spec.open_pose)
            task.before_step(physics, action, None)
            mujoco.mj_copyData(copy, model, data)
            path_pos, path_quat, writes = task.mocap_path()
            for i in range(task._substeps):  # the reference: every row written, one mj_step each
                if path_pos is not None:
                    copy.mocap_pos[task._mocap_id] = path_pos[i]
                if path_quat is not None:
                    copy.mocap_quat[task._mocap_id] = path_quat[i]
                mujoco.mj_step(model, copy)
            mujoco.mj_kinematics(model, copy)
            merged += writes < task._substeps
            kinds.add((path_pos is None, path_quat is None))
            task.fast_substeps(physics, cameras=False)
            for field in ("qpos", "qvel", "act", "mocap_pos", "mocap_quat", "xpos", "qacc_warmstart"):
                assert getattr(data, field).tobytes() == getattr(copy, field).tobytes(), (k, field)
            assert data.time == copy.time
        assert merged > 10  # the merged tail was exercised
        assert {(False, False), (False, True), (True, False)} <= kinds  # moving and turning, or one of them
    finally:
        env.close()
