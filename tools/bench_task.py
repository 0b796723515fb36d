"""Benchmark of the task on real episodes: the dm_control Task against raw mj_step doing the same
simulation, the real-time factor of whole episodes, and RGB / depth frames per second.

    python tools/bench_task.py [--cabinets cabinets] [--count 8] [--hand allegro] [--timestep 1/120]

For each cabinet (first target, test split) one oracle episode is planned and its actions recorded:

- Task: the recorded actions replayed through ``env.step`` (reset first), no rendering.
- raw: the same episode again as the least a harness must do with MuJoCo alone: per substep, the
  recorded mocap pose and finger controls written into MjData and one ``mj_step``. Same model, same
  trajectory, same contacts; the ratio Task / raw is what the Task adds.
- free air: the previous version of this figure, a hand circling in the air (no contacts).
- episode loop: the planner driving the Task (no rendering), from the first step to the check.
- whole episode: everything ``opend run`` does for one episode (scene build, the one RGB-D frame,
  the planner), as a real-time factor.

Figures are medians over cabinets.
"""

from __future__ import annotations

import argparse
import statistics
import time
from dataclasses import replace
from fractions import Fraction
from pathlib import Path

import opend_mj  # noqa: F401  (chooses off-screen EGL before mujoco loads)
import mujoco  # noqa: I001
import numpy as np

from opend_mj.camera import RGBDCamera
from opend_mj.dataset import load_manifest
from opend_mj.evaluation import EpisodeJob, run_episode
from opend_mj.task import EpisodeSpec, TaskConfig, make_environment


def _plan_episode(env, hand: str):
    """Run the oracle planner on ``env``; returns (actions, ctrl, mocap path per step, loop seconds)."""
    from opend_mj.hands import load_spec
    from opend_mj.planner import Observation, Planner, PlannerConfig, Robot
    from opend_mj.solvers import get_solver

    task, physics = env.task, env.physics
    with RGBDCamera(physics, "front", 256, 256) as cam:
        rgb, depth = cam.render()
    solver = get_solver("oracle", ground_truth=lambda: task.handle_boxes(physics)[task.target.joint])
    actions, ctrls, paths = [], [], []
    step = env.step
    n_sub = task._substeps

    def recording_step(action):
        actions.append(np.array(action))
        ts = step(action)
        ctrls.append(physics.data.ctrl.copy())
        pos = task._path_pos if task._path_pos is not None else None
        quat = task._path_quat if task._path_quat is not None else None
        paths.append((pos, quat))
        return ts

    env.step = recording_step
    obs = Observation(rgb=rgb, depth=depth, instruction=task.instruction, camera_view=task.camera_view(physics))
    planner = Planner(solver, load_spec(hand), PlannerConfig())
    start = time.perf_counter()
    planner.run(Robot(env), obs)
    loop_s = time.perf_counter() - start
    del env.step
    # the recorded substep mocap poses (rows where the mocap stayed put repeat the current pose)
    mocap_pos = np.empty((len(actions), n_sub, 3))
    mocap_quat = np.empty((len(actions), n_sub, 4))
    env.reset()
    mid = task._mocap_id
    cur_pos = physics.data.mocap_pos[mid].copy()
    for k, (pos, quat) in enumerate(paths):
        root_quat = actions[k][3:7] / np.linalg.norm(actions[k][3:7])
        mocap_pos[k] = pos if pos is not None else cur_pos
        mocap_quat[k] = quat if quat is not None else root_quat
        cur_pos = mocap_pos[k, -1].copy()
    return actions, np.array(ctrls), mocap_pos, mocap_quat, loop_s


def bench_one(cabinet_dir: Path, joint: str, hand: str, config: TaskConfig, cabinet_id: str) -> dict:
    env = make_environment(EpisodeSpec(cabinet_dir, joint, hand, seed=0), config)
    env.reset()
    task, physics = env.task, env.physics
    actions, ctrls, mocap_pos, mocap_quat, loop_s = _plan_episode(env, hand)
    n_control = len(actions)
    sim_s = n_control * task.control_timestep

    env.reset()
    start = time.perf_counter()
    for a in actions:
        env.step(a)
    task_s = time.perf_counter() - start
    q_task = physics.data.qpos.copy()

    env.reset()  # the same start state, then raw mj_step on the very same MjModel / MjData
    model, data = physics.model.ptr, physics.data.ptr
    n_sub, mid = mocap_pos.shape[1], task._mocap_id
    start = time.perf_counter()
    for k in range(n_control):
        data.ctrl[:] = ctrls[k]
        for i in range(n_sub):
            data.mocap_pos[mid] = mocap_pos[k, i]
            data.mocap_quat[mid] = mocap_quat[k, i]
            mujoco.mj_step(model, data)
    raw_s = time.perf_counter() - start
    same = float(np.max(np.abs(data.qpos - q_task)))

    # free air (the old figure): the hand circling, no contacts
    env.reset()
    pos, quat = task.start_pose
    air = [task.make_action(pos + 0.05 * np.array([0, np.sin(k / 20), np.cos(k / 20) - 1]), quat,
                            task.hand.spec.open_pose) for k in range(180)]
    start = time.perf_counter()
    for a in air:
        env.step(a)
    air_task_s = time.perf_counter() - start
    env.reset()
    start = time.perf_counter()
    mujoco.mj_step(model, data, len(air) * n_sub)
    air_raw_s = time.perf_counter() - start

    env.reset()
    with RGBDCamera(physics, "front", 256, 256) as cam:
        cam.render_rgb()
        start = time.perf_counter()
        for _ in range(20):
            cam.render_rgb()
        rgb_fps = 20 / (time.perf_counter() - start)
        start = time.perf_counter()
        for _ in range(20):
            cam.render_depth()
        depth_fps = 20 / (time.perf_counter() - start)
    env.close()

    # a whole episode as `opend run` runs it (scene build, one RGB-D frame, planner)
    job = EpisodeJob(cabinet=cabinet_id, cabinet_dir=str(cabinet_dir), joint=joint, split="test", hand=hand,
                     solver="oracle", physics_timestep=config.physics_timestep)
    rec = run_episode(job)
    return {"task_steps_per_s": n_control / task_s, "raw_control_equiv_per_s": n_control / raw_s,
            "ratio": task_s / raw_s, "air_ratio": air_task_s / air_raw_s,
            "raw_mj_steps_per_s": n_control * n_sub / raw_s, "task_rtf": sim_s / task_s,
            "loop_rtf": sim_s / loop_s, "episode_rtf": rec["sim_seconds"] / rec["wall_seconds"],
            "episode_wall_s": rec["wall_seconds"], "sim_s": sim_s, "same_state": same,
            "rgb_fps": rgb_fps, "depth_fps": depth_fps, "success": bool(rec.get("success"))}


def parse_timestep(text: str) -> float:
    return float(Fraction(text))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cabinets", type=Path, default=Path("cabinets"))
    parser.add_argument("--count", type=int, default=8)
    parser.add_argument("--hand", default="allegro")
    parser.add_argument("--timestep", type=parse_timestep, default=None,
                        help="physics timestep, e.g. 1/480 (default: TaskConfig's)")
    args = parser.parse_args()
    config = TaskConfig(enable_rgbd=False, time_limit=1e6)
    if args.timestep:
        config = replace(config, physics_timestep=args.timestep)
    manifest = load_manifest(args.cabinets)
    pairs = manifest.targets("test")
    pairs = pairs[:: max(1, len(pairs) // args.count)][: args.count]
    rows = []
    for cab, tgt in pairs:
        r = bench_one(args.cabinets / cab["path"], tgt["joint"], args.hand, config, cab["id"])
        rows.append(r)
        print(f"{cab['id']} {tgt['joint']}: Task {r['task_steps_per_s']:.0f} ctrl/s, raw {r['raw_control_equiv_per_s']:.0f}"
              f" (ratio {r['ratio']:.2f}, free air {r['air_ratio']:.2f}); Task {r['task_rtf']:.0f}x, episode loop"
              f" {r['loop_rtf']:.0f}x, whole episode {r['episode_rtf']:.1f}x real time; replay max |dq| "
              f"{r['same_state']:.1e}", flush=True)
    med = {k: statistics.median(r[k] for r in rows) for k in rows[0]}
    substeps = round(1 / config.control_hz / config.physics_timestep)
    print(f"\n## Task benchmark ({args.hand}, {len(rows)} test episodes, physics timestep "
          f"1/{round(1 / config.physics_timestep)} s = {substeps} substeps per 60 Hz control step, medians)\n")
    print("| figure | value |\n|---|---:|")
    print(f"| Task control steps/s, recorded oracle episode replayed | {med['task_steps_per_s']:.0f} |")
    print(f"| raw mj_step loop, same episode, as control steps/s | {med['raw_control_equiv_per_s']:.0f} |")
    print(f"| raw mj_step/s in that loop | {med['raw_mj_steps_per_s']:.0f} |")
    print(f"| **Task / raw (episode)** | **{med['ratio']:.2f}x** |")
    print(f"| Task / raw (hand in free air, no contacts) | {med['air_ratio']:.2f}x |")
    print(f"| real-time factor, Task stepping | {med['task_rtf']:.0f}x |")
    print(f"| **real-time factor, episode loop (planner + Task, no rendering)** | **{med['loop_rtf']:.0f}x** |")
    print(f"| real-time factor, whole episode (scene build + 1 RGB-D frame + loop) | {med['episode_rtf']:.1f}x |")
    print(f"| whole episode, wall s (sim {med['sim_s']:.1f} s) | {med['episode_wall_s']:.2f} |")
    print(f"| RGB frames/s, 256x256 | {med['rgb_fps']:.0f} |")
    print(f"| depth frames/s, 256x256 | {med['depth_fps']:.0f} |")
    print(f"| oracle successes in the whole-episode runs | {sum(r['success'] for r in rows)} / {len(rows)} |")


if __name__ == "__main__":
    main()
