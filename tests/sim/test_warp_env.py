"""The batched MuJoCo Warp environment (`opend_mj.sim.warp_env`) against the CPU environment, on Warp's
CPU device: the same start states, the same action sequences, the same verdicts.

Skips (with a reason that names the optional extra) where ``mujoco_warp`` is not installed
(``make install-warp``). The first run compiles Warp's kernels (about a minute on 2 cores; cached in
~/.cache/warp); after that the file takes about a minute on a busy 2-core CPU.

Tolerances (Warp steps in float32, the CPU environment in float64): in free air every observation
within 1e-3; once the hand presses on the cabinet, root and grasp site within 2 cm through the
grasp (a hand caught in one simulation may slip free in the other as it pulls), rewards within
0.05 on average, open ratios within 0.02 (0.01 for a planner demonstration); success verdicts, the
time observation, the mocap pose and the truncation step as the CPU's. The CPU environment's own
readers (`SceneReader.fill`, `RewardProbe.read`) run on a world's Warp state give the batched
observation within 1e-5 (float32 rounding) and the same contact, success and others-moved flags.
"""

from __future__ import annotations

import numpy as np
import pytest

from opend_mj.sim import warp_env

if not warp_env.available():
    pytest.skip(f"mujoco_warp missing: {warp_env.MISSING} (make install-warp)", allow_module_level=True)

import torch  # noqa: E402

from opend_mj.sim.envs import OpenDCore, make_config  # noqa: E402
from opend_mj.sim.scripted import reach_grasp_pull  # noqa: E402

N = 3
POSE_KEYS = ("hand_qpos", "root_pos", "root_quat", "grasp_site_pos", "grasp_site_quat", "mocap_pos", "mocap_quat")


def _episode(small_dataset, hand: str, seed: int, **kwargs):
    """The CPU environment and the (cabinet, target, room, scene seed) its reset(seed) draws."""
    core = OpenDCore(make_config(cabinets=str(small_dataset), split="all", hand=hand, **kwargs))
    episode = core.sampler.sample(seed)
    return core, episode


def _batch(small_dataset, hand, episode, seed, **kwargs):
    return warp_env.WarpBatchEnv(N, episode.cabinet, episode.joint, room=episode.room, scene_seed=episode.scene_seed,
                                 seed=seed, device="cpu", cabinets=str(small_dataset), split="all", hand=hand,
                                 **kwargs)


@pytest.mark.slow
@pytest.mark.parametrize("hand", ["allegro", "franka"])
def test_batched_worlds_follow_the_cpu_environment(small_dataset, hand):
    """N worlds (different start poses) step the scripted reach-grasp-pull actions that the CPU
    environment produced: the same first observations; while the hand moves in free air (the first
    40 steps) every observation within 1e-3; then, as fingers press on the cabinet (float32 contacts
    part from float64 ones: finger angles and touch forces differ), root and grasp site within 2 cm
    through the reach and the grasp; in the pull, where a hand caught in one simulation may slip
    free in the other (seen: 27 cm apart within 10 steps), the same open ratios (0.02) and
    verdicts; throughout, the mocap pose and time as the CPU's, rewards within 0.05 on average."""
    seed = 5
    core, episode = _episode(small_dataset, hand, seed, privileged=True)
    env = _batch(small_dataset, hand, episode, seed, privileged=True, reset_pool=N)
    options = env._options
    layout = {key: sl for key, sl, _ in env.layout}
    steps, free_air, grasped = 260, 40, 160  # reach_grasp_pull: reach, close the fingers (140-159), pull
    try:
        # the CPU environment, closed loop on its own observations: the action sequences
        cpu = []
        first = []
        for w in range(N):
            obs, info = core.reset(seed + w, options)
            first.append(core.flat.copy())
            rows = []
            for t in range(steps):
                a = reach_grasp_pull(obs, t, (env.action_dim,))
                obs, reward, terminated, truncated, info = core.step(a)
                rows.append((a, core.flat.copy(), reward, info["success"], info["open_ratio"]))
                if terminated or truncated:
                    break
            cpu.append(rows)
        # the batch, open loop on those actions
        obs, info = env.reset()
        for w in range(N):
            assert np.array_equal(obs[w].numpy(), first[w]), "a world's first observation is the CPU reset's"
        early = late = mocap = reward_sum = ratio_diff = cpu_check = 0.0
        count = 0
        for t in range(max(len(r) for r in cpu)):
            batch = np.stack([r[min(t, len(r) - 1)][0] for r in cpu])
            obs, reward, terminated, truncated, info = env.step(torch.as_tensor(batch))
            if t == 40:  # the CPU readers on a world's Warp state
                flat, terms = env.cpu_terms(0)
                cpu_check = float(np.abs(flat - obs[0].numpy()).max())
                assert terms.contact == bool(info["reward_terms"]["contact"][0])
                assert terms.success == bool(info["success"][0])
                assert terms.others_moved == bool(info["others_moved"][0])
            for w in range(N):
                if t >= len(cpu[w]):
                    continue
                _, ref, ref_reward, ref_success, ref_ratio = cpu[w][t]
                row = (info["final_obs"][w] if bool(terminated[w] | truncated[w]) else obs[w]).numpy()
                if t < free_air:
                    early = max(early, float(np.abs(row - ref).max()))
                if t < grasped:
                    for key in ("root_pos", "grasp_site_pos"):
                        late = max(late, float(np.abs(row[layout[key]] - ref[layout[key]]).max()))
                for key in ("mocap_pos", "mocap_quat"):
                    mocap = max(mocap, float(np.abs(row[layout[key]] - ref[layout[key]]).max()))
                assert row[layout["time"]][0] == ref[layout["time"]][0]
                reward_sum += abs(float(reward[w]) - ref_reward)
                count += 1
                ratio_diff = max(ratio_diff, abs(float(info["open_ratio"][w]) - ref_ratio))
                if t == len(cpu[w]) - 1:
                    assert bool(info["success"][w]) == ref_success, f"world {w}: verdict differs"
        print(f"{hand}: free air {early:.1e}, root/grasp site (reach, grasp) {late:.1e}, mocap {mocap:.1e}, "
              f"mean reward "
              f"{reward_sum / count:.1e}, open ratio {ratio_diff:.1e}, CPU readers on the Warp state {cpu_check:.1e}")
        assert cpu_check < 1e-5
        assert early < 1e-3 and late < 0.02 and mocap < 1e-6
        assert reward_sum / count < 0.05 and ratio_diff < 0.02
    finally:
        env.close()
        core.close()


@pytest.mark.slow
def test_a_planner_demonstration_ends_with_its_verdict(small_dataset):
    """`opend demos`' recording of a Franka planner episode, replayed (absolute task actions, the
    benchmark's hand start) in two worlds: both end as the recording did, open ratio within 0.01."""
    from opend_mj.apps.planner_demos import RecordConfig, demo_jobs, record_episode

    job = demo_jobs(small_dataset, ["franka"], split="all", limit=1)[0]
    _, demo = record_episode(job, None, RecordConfig())
    import json

    spec = json.loads(demo.attrs["episode"])
    env = warp_env.WarpBatchEnv(2, demo.attrs["cabinet"], demo.attrs["target_joint"], room=int(demo.attrs["room"]),
                                scene_seed=int(spec["seed"]), reset_pool=1, device="cpu",
                                reset_options={"start_offset": (0.0, 0.0, 0.0), "start_yaw": 0.0},
                                cabinets=str(small_dataset), split="all", hand="franka", control="absolute",
                                terminate_on_success=False, time_limit=60.0)
    try:
        env.reset()
        for a in demo.actions:
            _, _, _, _, info = env.step(torch.as_tensor(np.stack([a, a])))
        ratios = info["open_ratio"].tolist()
        print(f"recorded {demo.attrs['success']} {demo.attrs['open_ratio']:.5f}, Warp {ratios}")
        assert info["success"].tolist() == [bool(demo.attrs["success"])] * 2
        assert max(abs(r - float(demo.attrs["open_ratio"])) for r in ratios) < 0.01
    finally:
        env.close()


def test_worlds_reset_themselves_when_their_episode_ends(small_dataset):
    """A short time limit: every world truncates on the CPU environment's step, is reset from the
    pool (its next start state, its first observation) and goes on."""
    hand, seed = "franka", 2
    core, episode = _episode(small_dataset, hand, seed, time_limit=0.05)
    env = _batch(small_dataset, hand, episode, seed, time_limit=0.05, reset_pool=2 * N)
    try:
        obs, _ = env.reset()
        zero = torch.zeros(N, env.action_dim, dtype=torch.float64)
        core.reset(seed, env._options)
        cpu_steps = 0
        while True:
            cpu_steps += 1
            _, _, terminated, truncated, _ = core.step(np.zeros(env.action_dim))
            if terminated or truncated:
                break
        for t in range(cpu_steps):
            obs, reward, terminated, truncated, info = env.step(zero)
        assert bool(truncated.all()) and not bool(terminated.any()) and "final_obs" in info
        assert env.episodes.tolist() == [2] * N
        for w in range(N):  # world w's second episode: pool entry N + w, i.e. the CPU reset of seed + N + w
            core.reset(seed + N + w, env._options)
            assert np.array_equal(obs[w].numpy(), core.flat)
        obs, reward, terminated, truncated, info = env.step(zero)
        assert not bool((terminated | truncated).any()) and torch.isfinite(obs).all()
        with pytest.raises(ValueError, match="non-finite"):  # as the CPU environment
            env.step(torch.full((N, env.action_dim), float("nan"), dtype=torch.float64))
    finally:
        env.close()
        core.close()


def test_physics_randomisation_draws_per_world_factors(small_dataset):
    """Batched Model arrays: each world its own mass, damping, friction loss and handle friction."""
    hand, seed = "franka", 1
    core, episode = _episode(small_dataset, hand, seed)
    core.close()
    env = _batch(small_dataset, hand, episode, seed,
                 randomize=warp_env.PhysicsRandomization(factor=(0.5, 2.0), seed=3))
    try:
        factors = env.physics_factors
        assert factors.shape == (N, 4) and (factors >= 0.5).all() and (factors <= 2.0).all()
        mass = env.model.body_mass.numpy()
        assert mass.shape[0] == N and not np.allclose(mass[0], mass[1])
        env.reset()
        obs, *_ = env.step(torch.zeros(N, env.action_dim, dtype=torch.float64))
        assert torch.isfinite(obs).all()
    finally:
        env.close()


def test_depth_and_rgb_from_warps_renderer_match_the_cpu_renderer(small_dataset):
    """The front camera's batched images (Warp's ray tracer) against the CPU environment's (OpenGL),
    same state: planar depth in metres within 5 mm on 99 % of the pixels, RGB within 12 levels on
    average (shading differs a little)."""
    hand, seed, size = "franka", 4, 32
    core, episode = _episode(small_dataset, hand, seed, obs_mode="rgbd", image_size=size)
    env = _batch(small_dataset, hand, episode, seed, obs_mode="rgbd", image_size=size, reset_pool=N)
    try:
        obs, info = env.reset()
        assert info["rgb"].shape == (N, size, size, 3) and info["rgb"].dtype == torch.uint8
        assert info["depth"].shape == (N, size, size) and info["depth"].dtype == torch.float32
        ref, _ = core.reset(seed + 1, env._options)
        depth, rgb = info["depth"][1].numpy(), info["rgb"][1].numpy()
        both = (depth > 0) & (ref["depth"] > 0)
        assert both.mean() > 0.99
        error = np.abs(depth - ref["depth"])[both]
        colour = np.abs(rgb.astype(int) - ref["rgb"].astype(int)).mean()
        print(f"depth: 99th percentile {np.percentile(error, 99) * 1000:.2f} mm, max {error.max() * 1000:.1f} mm; "
              f"rgb mean |diff| {colour:.2f} levels")
        assert np.percentile(error, 99) < 0.005 and colour < 12
    finally:
        env.close()
        core.close()
