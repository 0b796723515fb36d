"""`policy.watch_env.FrontWatchWrapper`: ``front_watch`` in the observations of the gymnasium environments.

A stub solver answers with the target handle's true image box, so that the wrapper's own part is
tested fast and deterministically; the stub (and the drawer opened by setting its joint) exists only
here: the wrapper itself reads neither. One slow test runs the shipped Faster R-CNN.
"""

from __future__ import annotations

import numpy as np
import pytest

import gymnasium as gym
import opend_mj.sim.gym_env  # noqa: F401  (registers the ids)
from opend_mj.policy.handle_box import HandleBox
from opend_mj.policy.perception.watch import WATCH_DIM, WATCH_NAMES
from opend_mj.policy.watch_env import WATCH_KEY, FrontWatchWrapper

I = {name: i for i, name in enumerate(WATCH_NAMES)}


class TrueBoxStub:
    """A test's solver: the target handle's true box (or None with ``blind``), read from the wrapped
    environment's scene. Never one an agent may use."""

    exact = True  # the box is the handle's: not snapped to depth

    def __init__(self, blind: bool = False):
        self.env = None
        self.blind = blind
        self.calls = 0

    def solve(self, rgb, depth, instruction, view):
        self.calls += 1
        if self.blind:
            return None
        scene = self.env.unwrapped.core.scene
        box = scene.task.handle_boxes(scene.physics)[scene.task.target.joint]
        return None if box is None else HandleBox(*box)


def _wrapped(dataset, obs_mode="state", every=3, blind=False):
    inner = gym.make("opend/OpenDrawer-v0", cabinets=str(dataset), split="all", hand="franka", obs_mode=obs_mode,
                     image_size=128, terminate_on_success=False)
    stub = TrueBoxStub(blind)
    stub.env = inner
    return FrontWatchWrapper(inner, solver=stub, every=every), stub


def _hold(env):
    """The delta action that keeps the hand where it is (fingers at mid-range)."""
    return np.zeros(env.action_space.shape, np.float32)


def _open_drawer_by_hand(env, travel: float) -> None:
    """The test fabricates the motion: the target drawer's joint set ``travel`` m open, at rest."""
    scene = env.unwrapped.core.scene
    target = scene.task.target
    joint = scene.physics.bind(scene.task.cabinet.joint_element(target.joint))
    joint.qpos = target.closed + target.open_sign * travel
    joint.qvel = 0.0


def _opening(env) -> float:
    scene = env.unwrapped.core.scene
    target = scene.task.target
    return target.opening(float(scene.physics.bind(scene.task.cabinet.joint_element(target.joint)).qpos[0]))


def test_key_in_space_and_observation_and_looked_after_every_steps(small_dataset):
    env, stub = _wrapped(small_dataset, every=3)
    try:
        space = env.observation_space[WATCH_KEY]
        assert space.shape == (WATCH_DIM,) and space.dtype == np.float32
        assert set(env.env.observation_space.spaces) | {WATCH_KEY} == set(env.observation_space.spaces)
        obs, info = env.reset(seed=0)
        assert info["target_type"] == "drawer" and env.located and stub.calls == 1
        assert "handle_pos" not in obs  # not privileged: the wrapper had no ground truth to read either
        assert env.observation_space.contains(obs)
        v = obs[WATCH_KEY]
        assert v.shape == (WATCH_DIM,) and v.dtype == np.float32
        assert v[I["looked"]] == 0 and v[I["seen"]] == 0
        assert np.allclose(v[[I["site_dx"], I["site_dy"], I["site_dz"]]],
                           obs["grasp_site_pos"] - env.percept.handle.centre, atol=1e-5)
        scene = env.unwrapped.core.scene
        renders = []
        real = scene.render_depth
        scene.render_depth = lambda: renders.append(1) or real()  # count the wrapper's depth renders
        try:
            looked = []
            for _ in range(7):
                obs, *_ = env.step(_hold(env))
                assert env.observation_space.contains(obs)
                looked.append(float(obs[WATCH_KEY][I["looked"]]))
        finally:
            del scene.render_depth
        assert looked == [0, 0, 1, 1, 1, 1, 1]  # steps 1..7: the first look at step 3
        assert len(renders) == 2  # state mode: one depth render per look (steps 3 and 6), none between
        assert obs[WATCH_KEY][I["seen"]] == 0  # nothing moved
        assert obs[WATCH_KEY][I["age"]] == pytest.approx(env.unwrapped.core.control_dt, abs=1e-6)
    finally:
        env.close()


def test_shift_reads_a_drawers_travel_alike_in_state_and_rgbd_mode(small_dataset):
    vectors = {}
    for mode in ("state", "rgbd"):
        env, _ = _wrapped(small_dataset, obs_mode=mode, every=2)
        try:
            first, _ = env.reset(seed=0)
            _open_drawer_by_hand(env, 0.12)
            obs, *_ = env.step(_hold(env))
            assert obs[WATCH_KEY][I["looked"]] == 0
            obs, *_ = env.step(_hold(env))
            v = obs[WATCH_KEY]
            travel = _opening(env)
            assert travel == pytest.approx(0.12, abs=0.01)  # the drawer stayed where it was set
            assert v[I["looked"]] == 1 and v[I["seen"]] == 1
            assert v[I["shift"]] == pytest.approx(travel, abs=0.02)
            assert v[I["handle_dx"]] == pytest.approx(-travel, abs=0.02)  # pulled toward the camera (-x)
            # the grasp site relative to the handle as carried: the hand stayed, the handle came nearer
            assert v[I["site_dx"]] == pytest.approx(first[WATCH_KEY][I["site_dx"]] + travel, abs=0.02)
            vectors[mode] = v.copy()
        finally:
            env.close()
    # state mode renders the look itself: the same depth as rgbd mode's observation, the same numbers
    assert np.allclose(vectors["state"], vectors["rgbd"], atol=1e-6)


def test_same_seed_same_numbers(small_dataset):
    env, _ = _wrapped(small_dataset, every=2)
    try:
        runs = []
        for _ in range(2):
            obs, _ = env.reset(seed=4)
            rows = [obs[WATCH_KEY]]
            _open_drawer_by_hand(env, 0.08)
            for _ in range(4):
                obs, *_ = env.step(_hold(env))
                rows.append(obs[WATCH_KEY])
            runs.append(np.array(rows))
        assert np.array_equal(runs[0], runs[1])
        assert runs[0][-1][I["looked"]] == 1
    finally:
        env.close()


def test_no_handle_located_gives_zeros(small_dataset):
    env, stub = _wrapped(small_dataset, every=2, blind=True)
    try:
        obs, _ = env.reset(seed=0)
        assert not env.located and env.percept is None and stub.calls == 1
        rows = [obs[WATCH_KEY]] + [env.step(_hold(env))[0][WATCH_KEY] for _ in range(3)]
        for v in rows:
            assert v.dtype == np.float32 and not v.any()
    finally:
        env.close()


def test_refuses_ground_truth_solvers_and_other_environments(small_dataset):
    inner = gym.make("opend/OpenDrawer-v0", cabinets=str(small_dataset), split="all", hand="franka")
    try:
        with pytest.raises(ValueError, match="ground truth"):
            FrontWatchWrapper(inner, solver="oracle")

        class ReadsTheSimulator(TrueBoxStub):
            needs_ground_truth = True

        with pytest.raises(ValueError, match="ground truth"):
            FrontWatchWrapper(inner, solver=ReadsTheSimulator())
    finally:
        inner.close()

    class Other(gym.Env):
        observation_space = gym.spaces.Dict({"x": gym.spaces.Box(0, 1, (1,))})
        action_space = gym.spaces.Box(0, 1, (1,))

    with pytest.raises(TypeError, match="OpenCabinet-v0"):
        FrontWatchWrapper(Other(), solver=TrueBoxStub())


@pytest.mark.slow
def test_fasterrcnn_locates_and_watches(small_dataset):
    """The shipped detector (oracle-free) through the wrapper, in state mode."""
    inner = gym.make("opend/OpenDrawer-v0", cabinets=str(small_dataset), split="all", hand="franka",
                     terminate_on_success=False)
    env = FrontWatchWrapper(inner, solver="fasterrcnn", every=2)
    try:
        obs, _ = env.reset(seed=0)
        assert env.located
        _open_drawer_by_hand(env, 0.12)
        for _ in range(2):
            obs, *_ = env.step(_hold(env))
        v = obs[WATCH_KEY]
        assert v[I["looked"]] == 1 and v[I["seen"]] == 1
        assert v[I["shift"]] == pytest.approx(_opening(env), abs=0.02)
    finally:
        env.close()
