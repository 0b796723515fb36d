"""The environments over the dataset: gymnasium ids, seeding, vector envs, rewards, dm_env."""

from __future__ import annotations

import numpy as np
import pytest

import gymnasium as gym  # noqa: E402
import opend_mj.sim.gym_env  # noqa: E402,F401  (registers the ids)
from opend_mj.sim.envs import EnvConfig, OpenDCore, OpenDDmEnv  # noqa: E402

ENV_ID = "opend/OpenCabinet-v0"


def _make(dataset, **kwargs):
    return gym.make(ENV_ID, cabinets=str(dataset), split="all", hand=kwargs.pop("hand", "franka"), **kwargs)


def test_ids_are_registered():
    for env_id in ("opend/OpenCabinet-v0", "opend/OpenDrawer-v0", "opend/OpenDoor-v0"):
        assert env_id in gym.registry


@pytest.mark.parametrize("kwargs", [{"obs_mode": "state", "privileged": True},
                                    {"obs_mode": "rgbd", "image_size": 64, "control": "absolute"}])
def test_check_env_passes(small_dataset, kwargs):
    from gymnasium.utils.env_checker import check_env

    env = _make(small_dataset, **kwargs)
    try:
        check_env(env.unwrapped, skip_render_check=True)
    finally:
        env.close()


def test_state_mode_renders_nothing_and_rgbd_gives_images(small_dataset):
    env = _make(small_dataset, obs_mode="state")
    try:
        obs, info = env.reset(seed=0)
        assert not {"rgb", "depth", "handle_pos", "open_ratio"} & set(obs)
        assert env.unwrapped.core.scene._camera is None  # no renderer was ever made
        assert obs["hand_qpos"].shape == (2,) and obs["instruction"].shape == (14,)
        assert env.action_space.shape == (8,)  # 6 root + 2 fingers
        assert {"success", "open_ratio", "others_moved"} <= set(info)
    finally:
        env.close()
    env = _make(small_dataset, obs_mode="rgbd", image_size=64, instruction="text", hand="allegro")
    try:
        obs, info = env.reset(seed=0)
        assert obs["rgb"].shape == (64, 64, 3) and obs["rgb"].dtype == np.uint8 and obs["rgb"].std() > 5
        assert obs["depth"].shape == (64, 64) and np.isfinite(obs["depth"]).all()
        assert obs["instruction"] == info["instruction"] and obs["hand_qpos"].shape == (16,)
        assert env.action_space.shape == (22,)
    finally:
        env.close()


def test_same_seed_same_episode_and_first_observation(small_dataset):
    env = _make(small_dataset, privileged=True)
    other = _make(small_dataset, privileged=True)
    try:
        first, info1 = env.reset(seed=7)
        env.step(env.action_space.sample())
        env.reset(seed=8)
        again, info2 = env.reset(seed=7)  # a reused scene
        fresh, info3 = other.reset(seed=7)  # a scene of its own
        for info in (info2, info3):
            assert (info["cabinet"], info["target"], info["room"]) == (info1["cabinet"], info1["target"], info1["room"])
        for key in first:
            assert np.array_equal(first[key], again[key]), key
            assert np.array_equal(first[key], fresh[key]), key
    finally:
        env.close()
        other.close()


def test_different_seeds_sample_different_episodes(small_dataset):
    core = OpenDCore(EnvConfig(cabinets=str(small_dataset), split="all", hand="franka"))
    episodes = [core.sampler.sample(s) for s in range(12)]
    assert len({e.cabinet for e in episodes}) >= 2
    assert len({e.room for e in episodes}) >= 2
    assert len({e.start_offset for e in episodes}) == 12
    drawers = OpenDCore(EnvConfig(cabinets=str(small_dataset), split="all", hand="franka", target_types=("drawer",)))
    assert {drawers.sampler.sample(s).target_type for s in range(12)} == {"drawer"}


def test_options_fix_the_episode(small_dataset):
    env = _make(small_dataset)
    try:
        _, info = env.reset(seed=0)
        _, fixed = env.reset(seed=1, options={"cabinet": info["cabinet"], "target": info["target"], "room": 3})
        assert (fixed["cabinet"], fixed["target"], fixed["room"]) == (info["cabinet"], info["target"], 3)
        with pytest.raises(ValueError, match="no target"):
            env.reset(seed=1, options={"cabinet": "no_such_cabinet"})
    finally:
        env.close()


@pytest.mark.slow
def test_vector_env_of_two_processes_steps(small_dataset):
    envs = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode="async", vector_kwargs={"context": "spawn"},
                        cabinets=str(small_dataset), split="all", hand="franka")
    try:
        obs, info = envs.reset(seed=[0, 1])
        assert obs["hand_qpos"].shape == (2, 2) and len(info["cabinet"]) == 2
        for _ in range(2):
            obs, reward, terminated, truncated, info = envs.step(envs.action_space.sample())
        assert reward.shape == (2,) and ((reward >= 0) & (reward <= 1)).all()
        assert info["success"].shape == (2,) and info["open_ratio"].shape == (2,)
        assert np.allclose(obs["time"][:, 0], 2 / 60)
    finally:
        envs.close()


def _drawer_core(dataset, **kwargs) -> tuple[OpenDCore, int]:
    """A core env and a seed whose episode is a drawer (the planner opens those reliably)."""
    core = OpenDCore(EnvConfig(cabinets=str(dataset), split="all", hand="franka", target_types=("drawer",),
                               **kwargs))
    return core, 0


def test_dense_reward_is_zero_for_a_hand_that_never_moves(small_dataset):
    core, seed = _drawer_core(small_dataset)
    try:
        obs, info = core.reset(seed)
        still = np.concatenate([np.zeros(6), core.adapter.fingers_to_unit(core.spec.open_pose)])
        rewards = [core.step(still)[1] for _ in range(120)]
        assert rewards == [0.0] * 120
        sparse = OpenDCore(EnvConfig(cabinets=str(small_dataset), split="all", hand="franka", reward_mode="sparse"))
        sparse.reset(seed)
        assert {sparse.step(still)[1] for _ in range(30)} == {0.0}
        sparse.close()
    finally:
        core.close()


def test_dense_reward_rises_along_a_scripted_successful_episode(small_dataset):
    """The planner (with the true handle box) drives the environment through its absolute action."""
    from opend_mj.policy.agents import EpisodeInfo, PlannerAgent
    from opend_mj.policy.solvers import OracleSolver

    core, seed = _drawer_core(small_dataset, control="absolute", obs_mode="rgbd", instruction="text",
                              start_noise=0.0, start_yaw_noise=0.0)
    try:
        obs, info = core.reset(seed)
        task, physics = core.scene.task, core.scene.physics
        agent = PlannerAgent(solver=OracleSolver(lambda: task.handle_boxes(physics)[task.target.joint]),
                             use_grasp_file=False)
        low, high = core.action_bounds()
        agent.reset(EpisodeInfo(instruction=info["instruction"], hand="franka", hand_spec=core.spec,
                                camera_view=core.scene.camera_view(), control_dt=core.control_dt, time_limit=15.0,
                                action_names=tuple(core.action_names()), action_low=low, action_high=high))
        rewards, terms = [], []
        while True:
            action = agent.act(obs)
            assert action is not None, "the planner stopped before the drawer opened"
            obs, reward, terminated, truncated, info = core.step(action)
            rewards.append(reward)
            terms.append(info["reward_terms"])
            if terminated or truncated:
                break
        agent.close()
        assert info["success"] and terminated and rewards[-1] == 1.0
        assert all(0.0 <= r <= 1.0 for r in rewards)
        contact = next(i for i, t in enumerate(terms) if t["contact"])
        opening = next(i for i, t in enumerate(terms) if t["open"] > 0)
        n = len(rewards) // 10
        assert max(rewards[:n]) < rewards[contact] < rewards[-1]  # reach, then contact, then open
        assert np.mean(rewards[:n]) < np.mean(rewards[contact:opening + 1]) < np.mean(rewards[opening:])
        assert terms[contact]["reach"] > 0.9
    finally:
        core.close()


def test_dm_env_gives_the_gym_episode(small_dataset):
    from dm_env import StepType

    dm = OpenDDmEnv(seed=0, cabinets=str(small_dataset), split="all", hand="franka")
    env = _make(small_dataset)
    try:
        ts = dm.reset_with_seed(4)
        obs, info = env.reset(seed=4)
        assert ts.step_type == StepType.FIRST and dm.info["cabinet"] == info["cabinet"]
        for key, value in obs.items():
            assert np.allclose(ts.observation[key], value, atol=1e-6), key
        spec = dm.observation_spec()
        assert set(spec) == set(obs) and spec["hand_qpos"].shape == (2,)
        action = np.zeros(dm.action_spec().shape)
        ts = dm.step(action)
        assert ts.step_type == StepType.MID and ts.reward == 0.0 and ts.discount == 1.0
        assert dm.reset().step_type == StepType.FIRST
    finally:
        dm.close()
        env.close()
