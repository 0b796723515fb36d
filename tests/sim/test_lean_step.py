"""The lean environment step against the reference step, bit for bit; the shared-memory vector env."""

from __future__ import annotations

import json

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium")

import opend_mj.sim.gym_env  # noqa: E402,F401  (registers the ids)

ENV_ID = "opend/OpenCabinet-v0"


def _scripted(obs: dict, t: int, shape) -> np.ndarray:
    """Reach the handle (privileged box centre), close the fingers on it, pull; turning the wrist a
    little all the time (so that every step plans a rotation)."""
    a = np.zeros(shape, np.float32)
    d = obs["handle_pos"] - obs["grasp_site_pos"]
    if t < 140:
        a[:3], a[6:] = np.clip(d / 0.0125, -1, 1), -1
    elif t < 160:
        a[:3], a[6:] = np.clip(d / 0.0125, -1, 1) * 0.3, 1
    else:
        a[0], a[6:] = -0.4, 1
    a[3:6] = np.sin(t * 0.1 + np.arange(3)) * 0.3
    return a


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
                action = _scripted(obs, t, lean.action_space.shape)
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


@pytest.mark.parametrize("step_in_main", [False, True])
def test_shared_memory_vector_env_matches_single_envs_and_autoresets(small_dataset, step_in_main):
    kwargs = dict(cabinets=str(small_dataset), split="all", hand="franka", time_limit=0.24)  # truncated at step 15 (0.25 s)
    envs = gym.make_vec(ENV_ID, num_envs=2, step_in_main=step_in_main, **kwargs)
    singles = [gym.make(ENV_ID, **kwargs) for _ in range(2)]
    try:
        assert type(envs).__name__ == "OpenDVectorEnv"
        assert len(envs.unwrapped.worker_cpu_seconds()) == (1 if step_in_main else 2)
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
    finally:
        envs.close()
        for single in singles:
            single.close()


def test_maniskill_criterion_judges_success_by_the_joint_range(small_dataset):
    env = gym.make(ENV_ID, cabinets=str(small_dataset), split="all", hand="franka", privileged=True,
                   range_success=0.02, terminate_on_success=False)
    try:
        obs, info = env.reset(seed=0)
        seen = set()
        for t in range(220):
            obs, reward, terminated, truncated, info = env.step(_scripted(obs, t, env.action_space.shape))
            ratio = info["reward_terms"]["range_ratio"]
            assert info["success"] == (ratio >= 0.02)
            assert (reward == 1.0) == (info["success"] and not info["others_moved"])
            seen.add(info["success"])
        assert seen == {False, True}  # the scripted pull crossed 2 % of the range
    finally:
        env.close()
