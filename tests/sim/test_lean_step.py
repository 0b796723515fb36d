"""The lean environment step against the reference step, bit for bit; the shared-memory vector env."""

from __future__ import annotations

import json

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium")

import opend_mj.sim.gym_env  # noqa: E402,F401  (registers the ids)
from opend_mj.sim.scripted import reach_grasp_pull  # noqa: E402

ENV_ID = "opend/OpenCabinet-v0"


def _same(x, y, where: str) -> None:
    if isinstance(x, dict):
        assert set(x) == set(y), where
        for key in x:
            _same(x[key], y[key], f"{where}/{key}")
    elif isinstance(x, np.ndarray):
        assert x.dtype == y.dtype and x.shape == y.shape, where
        assert x.tobytes() == y.tobytes(), f"{where}: {x} != {y}"
    else:
        assert type(x) is type(y) and x == y, f"{where}: {x!r} != {y!r}"


@pytest.mark.parametrize("hand", ["allegro", "franka"])
def test_lean_step_gives_the_reference_observations_and_rewards_to_the_bit(small_dataset, hand):
    kwargs = dict(cabinets=str(small_dataset), split="all", hand=hand, privileged=True)
    lean = gym.make(ENV_ID, **kwargs).unwrapped
    reference = gym.make(ENV_ID, lean_step=False, **kwargs).unwrapped
    touched = contact = 0
    try:
        for seed in (0, 3):
            obs, info = lean.reset(seed=seed)
            ref_obs, ref_info = reference.reset(seed=seed)
            _same(obs, ref_obs, "reset")
            assert json.dumps(info, sort_keys=True) == json.dumps(ref_info, sort_keys=True)
            for t in range(220):
                action = reach_grasp_pull(obs, t, lean.action_space.shape)
                obs, reward, terminated, truncated, info = lean.step(action)
                ref = reference.step(action)
                _same(obs, ref[0], f"seed {seed} step {t}")
                assert (reward, terminated, truncated) == ref[1:4]
                assert json.dumps(info, sort_keys=True) == json.dumps(ref[4], sort_keys=True)
                touched += bool(obs["touch"].any())
                contact += info["reward_terms"]["contact"]
                if terminated or truncated:
                    break
    finally:
        lean.close()
        reference.close()
    assert touched > 10 and contact > 10  # the episodes exercised touch and the handle contact term


def test_image_modes_render_only_what_they_name_and_match_the_reference(small_dataset):
    kwargs = dict(cabinets=str(small_dataset), split="all", hand="franka", image_size=32)
    for mode, images in (("rgb", {"rgb"}), ("depth", {"depth"}), ("rgbd", {"rgb", "depth"})):
        lean = gym.make(ENV_ID, obs_mode=mode, **kwargs)
        reference = gym.make(ENV_ID, obs_mode=mode, lean_step=False, **kwargs)
        try:
            lean.action_space.seed(0)
            obs, _ = lean.reset(seed=2)
            ref_obs, _ = reference.reset(seed=2)
            assert {"rgb", "depth"} & set(obs) == images and obs in lean.observation_space
            _same(obs, ref_obs, mode)
            for _ in range(3):
                action = lean.action_space.sample()
                _same(lean.step(action)[0], reference.step(action)[0], mode)
            if "rgb" in images:
                assert obs["rgb"].shape == (32, 32, 3)
        finally:
            lean.close()
            reference.close()


@pytest.mark.parametrize("num_envs, envs_per_worker, step_in_main, workers", [
    (2, 1, False, 2), (2, 1, True, 1),  # an environment per process
    (4, 2, False, 2), (4, 2, True, 1),  # 2 workers x 2; main x 2 + 1 worker x 2
    (3, 2, False, 2)])  # the last worker takes what is left
def test_shared_memory_vector_env_matches_single_envs_and_autoresets(small_dataset, num_envs, envs_per_worker,
                                                                      step_in_main, workers):
    # truncated at step 15 (0.25 s)
    kwargs = dict(cabinets=str(small_dataset), split="all", hand="franka", time_limit=0.24)
    envs = gym.make_vec(ENV_ID, num_envs=num_envs, step_in_main=step_in_main, envs_per_worker=envs_per_worker,
                        **kwargs)
    singles = [gym.make(ENV_ID, **kwargs) for _ in range(num_envs)]
    try:
        assert type(envs).__name__ == "OpenDVectorEnv" and envs.num_envs == num_envs
        assert len(envs.unwrapped.worker_cpu_seconds()) == workers
        obs, info = envs.reset(seed=4)
        for i, single in enumerate(singles):
            one, one_info = single.reset(seed=4 + i)  # environment i runs the episode of seed 4 + i
            for key in one:
                assert np.array_equal(obs[key][i], one[key]), key
            assert info["cabinet"][i] == one_info["cabinet"] and info["episode_seed"][i] == 4 + i
        rng = np.random.default_rng(0)
        for t in range(15):
            actions = rng.uniform(-1, 1, envs.action_space.shape).astype(np.float32)
            obs, reward, terminated, truncated, info = envs.step(actions)
            for i, single in enumerate(singles):
                s_obs, s_reward, s_term, s_trunc, s_info = single.step(actions[i])
                for key in s_obs:
                    assert np.array_equal(obs[key][i], s_obs[key]), (t, key)
                assert (reward[i], terminated[i], truncated[i]) == (s_reward, s_term, s_trunc)
                assert info["open_ratio"][i] == s_info["open_ratio"] and info["success"][i] == s_info["success"]
                for key, value in s_info["reward_terms"].items():
                    assert info["reward_terms"][key][i] == value, key
        assert truncated.all() and obs["time"][0, 0] == pytest.approx(15 / 60)
        obs, reward, terminated, truncated, info = envs.step(np.zeros(envs.action_space.shape))  # autoreset
        assert (reward == 0).all() and not (terminated | truncated).any() and (obs["time"][:, 0] == 0).all()
        for i, single in enumerate(singles):  # the next episode of environment i's seed sequence
            one, one_info = single.reset()
            for key in one:
                assert np.array_equal(obs[key][i], one[key]), key
            for key in ("cabinet", "target", "room", "episode_seed", "instruction"):
                assert info[key][i] == one_info[key], key
        assert len(set(info["episode_seed"])) == num_envs
    finally:
        envs.close()
        for single in singles:
            single.close()


def test_vector_env_with_two_renderers_in_a_process_gives_each_environment_its_images(small_dataset):
    kwargs = dict(cabinets=str(small_dataset), split="all", hand="franka", obs_mode="rgbd", image_size=32)
    envs = gym.make_vec(ENV_ID, num_envs=3, envs_per_worker=2, step_in_main=True, **kwargs)  # main x 2 + 1
    singles = [gym.make(ENV_ID, **kwargs) for _ in range(3)]
    try:
        obs, _ = envs.reset(seed=7)
        rng = np.random.default_rng(0)
        for t in range(4):
            for i, single in enumerate(singles):
                one = single.reset(seed=7 + i)[0] if t == 0 else single.step(actions[i])[0]
                for key in ("rgb", "depth", "camera_pose"):
                    assert np.array_equal(obs[key][i], one[key]), (t, i, key)
            actions = rng.uniform(-1, 1, envs.action_space.shape).astype(np.float32)
            obs = envs.step(actions)[0]
        assert len({obs["rgb"][i].tobytes() for i in range(3)}) == 3  # three different scenes
    finally:
        envs.close()
        for single in singles:
            single.close()

def test_vector_env_layouts_and_errors_name_the_environment(small_dataset):
    from opend_mj.sim.vector_env import env_groups

    assert env_groups(5, 2, False) == (None, [range(0, 2), range(2, 4), range(4, 5)])
    assert env_groups(4, 2, True) == (range(0, 2), [range(2, 4)])
    assert env_groups(2, 1, True) == (range(0, 1), [range(1, 2)])
    for bad in (0, -1, 1.5, True):
        with pytest.raises(ValueError, match="envs_per_worker"):
            env_groups(4, bad, False)
    envs = gym.make_vec(ENV_ID, num_envs=4, envs_per_worker=2, cabinets=str(small_dataset), split="all",
                        hand="franka")
    try:
        envs.reset(seed=0)
        actions = np.zeros(envs.action_space.shape)
        actions[3, 0] = np.nan  # the second environment of worker 1
        with pytest.raises(RuntimeError, match=r"(?s)worker 1 \(environments 2-3\).*non-finite.*in environment 3"):
            envs.step(actions)
    finally:
        envs.close()


def test_maniskill_criterion_judges_success_by_the_joint_range(small_dataset):
    env = gym.make(ENV_ID, cabinets=str(small_dataset), split="all", hand="franka", privileged=True,
                   range_success=0.02, terminate_on_success=False, target_types=("drawer",))  # pulled straight
    try:
        obs, info = env.reset(seed=0)
        seen = set()
        for t in range(220):
            obs, reward, terminated, truncated, info = env.step(reach_grasp_pull(obs, t, env.action_space.shape))
            ratio = info["reward_terms"]["range_ratio"]
            assert info["success"] == (ratio >= 0.02)
            assert (reward == 1.0) == (info["success"] and not info["others_moved"])
            seen.add(info["success"])
        assert seen == {False, True}  # the scripted pull crossed 2 % of the range
    finally:
        env.close()


def _random_poses(rng, count):
    """(mocap position, mocap quaternion, target position, target quaternion): targets within one
    substep, within one control step and beyond it; turns of none, a hair, a step's worth, a lot."""
    for i in range(count):
        pos = rng.normal(size=3)
        quat = rng.normal(size=4)
        quat /= np.linalg.norm(quat)
        reach = (0.0, 1e-4, 0.005, 0.05)[i % 4]
        target = pos + rng.normal(size=3) * reach
        turn = (0.0, 1e-7, 0.003, 0.5)[(i // 4) % 4]
        target_quat = quat + rng.normal(size=4) * turn
        target_quat = -target_quat if i % 7 == 0 else target_quat  # the other sign of the same turn
        yield pos, quat, target, target_quat / np.linalg.norm(target_quat)


def test_mocap_path_planner_gives_the_reference_path_to_the_bit():
    from opend_mj.sim.mocap_path import MocapPathPlanner, plan_reference

    rng = np.random.default_rng(0)
    for n, travel, angle in ((8, 0.75 / 480, 4 / 480), (2, 0.75 / 120, 4 / 120), (1, 0.75 / 60, 4 / 60)):
        planner = MocapPathPlanner(n, travel, angle)
        kinds = set()
        for pos, quat, target, target_quat in _random_poses(rng, 400):
            q_lean, q_ref = quat.copy(), quat.copy()  # both write the target quaternion when not turning
            rows, quat_rows, writes = planner.plan(pos.copy(), q_lean, target.tolist(), target_quat)
            ref_pos, ref_quat, ref_writes = plan_reference(pos.copy(), q_ref, target, target_quat, n, travel, angle)
            assert writes == ref_writes and q_lean.tobytes() == q_ref.tobytes()
            for mine, ref in ((rows, ref_pos), (quat_rows, ref_quat)):
                assert (mine is None) == (ref is None)
                if mine is not None:
                    assert np.array(mine).tobytes() == ref.tobytes()
            kinds.add((rows is None, quat_rows is None, writes < n))
        assert len(kinds) >= (5 if n > 1 else 3)  # still, moving, turning, arriving early, ...


def test_delta_actions_give_the_reference_task_action_to_the_bit():
    from opend_mj.sim.actions import ActionAdapter
    from opend_mj.sim.task import TaskConfig

    for hand in ("allegro", "franka"):
        adapter = ActionAdapter(hand, TaskConfig())
        rng = np.random.default_rng(1)
        for pos, quat, _, _ in _random_poses(rng, 300):
            action = rng.uniform(-1.3, 1.3, adapter.delta_dim)
            action[3:6] *= rng.choice([0.0, 1e-14, 1.0])  # no turn, a turn below 1e-12 rad, a turn
            if rng.random() < 0.2:  # fingers at and just above the bottom of their range
                action[6:] = rng.choice([-1.0, np.nextafter(-1.0, 0.0), -1.0 + 2**-30], adapter.n_fingers)
            for a in (action, action.astype(np.float32), action.tolist()):
                ref = adapter.from_delta_reference(a, pos, quat)
                assert adapter.from_delta(a, pos, quat).tobytes() == ref.tobytes()
                p, q, f = adapter.delta_parts(a, pos, quat)
                assert np.concatenate([p, q, f]).tobytes() == ref.tobytes()
        bad = np.zeros(adapter.delta_dim)
        bad[7] = np.nan
        with pytest.raises(ValueError, match="non-finite"):
            adapter.delta_parts(bad, pos, quat)
        with pytest.raises(ValueError, match="shape"):
            adapter.delta_parts(bad[:-1], pos, quat)


def test_root_targets_on_and_beyond_the_workspace_are_clipped_as_numpy_clips(small_dataset):
    env = gym.make(ENV_ID, cabinets=str(small_dataset), split="all", hand="franka").unwrapped
    try:
        env.reset(seed=1)
        task = env.core.scene.task
        lo, hi = task._workspace
        fingers = np.asarray(task.hand.spec.open_pose, float)
        rng = np.random.default_rng(2)
        for k in range(60):
            pos = rng.uniform(lo - 0.5, hi + 0.5)
            if k % 2:  # exactly on a bound
                pos[k % 3] = lo[k % 3] if k % 4 == 1 else hi[k % 3]
            quat = rng.normal(size=4)
            task.apply_action(pos.tolist(), quat, fingers)
            assert np.array(task._root_target[0]).tobytes() == np.minimum(np.maximum(pos, lo), hi).tobytes()
            assert task._root_target[1].tobytes() == (quat / np.sqrt(quat @ quat)).tobytes()
        with pytest.raises(ValueError, match="zero norm"):
            task.apply_action(pos.tolist(), np.zeros(4), fingers)
    finally:
        env.close()


def test_distance_to_the_handle_box_matches_the_reference_to_the_bit(small_dataset):
    env = gym.make(ENV_ID, cabinets=str(small_dataset), split="all", hand="franka").unwrapped
    try:
        env.reset(seed=0)
        probe = env.core.scene.probe
        site = probe._site_pos
        saved = site.copy()
        rng = np.random.default_rng(3)
        lo0, hi0 = probe.target_box()
        inside = 0
        for k in range(300):
            lo = lo0 + rng.normal(size=3) * 0.01
            hi = lo + np.abs(rng.normal(size=3)) * 0.05
            site[:] = lo + (hi - lo) * rng.uniform(-1.0, 2.0, 3)
            if k % 5 == 0:
                site[k % 3] = (lo[k % 3], hi[k % 3])[k % 2]  # on a face
            if k == 7:
                site[1] = np.nan
            mine, ref = probe.distance((lo, hi)), probe.distance_reference((lo, hi))
            assert np.array(mine).tobytes() == np.array(ref).tobytes(), (k, mine, ref)
            inside += mine == 0.0
        site[:] = saved
        assert 10 < inside < 290
    finally:
        env.close()
