"""Benchmark of the task on real episodes: the dm_control Task against raw mj_step doing the same
simulation, the real-time factor of whole episodes, and RGB / depth frames per second.

    python tools/bench_task.py [--cabinets cabinets] [--count 8] [--hand allegro] [--timestep 1/120]

For each cabinet (first target, test split) one oracle episode is planned and its actions recorded:

- Task: the recorded actions replayed through ``env.step`` (reset first), no rendering.
- raw: the same episode again as the least a harness must do with MuJoCo alone: per substep, the
  recorded mocap pose and finger controls written into MjData and one ``mj_step``. Same model, same
  trajectory, same contacts; the ratio Task / raw is what the Task adds.
- free air: the same comparison for a hand circling in the air (no contacts: the cheapest physics,
  so the Task's largest ratio).
- episode loop: the planner driving the Task (no rendering), from the first step to the check.
- whole episode: everything ``opend run`` does for one episode (scene build, the one RGB-D frame,
  the planner), as a real-time factor.
- planner wall time / raw physics: the episode loop's (and the whole episode's) wall seconds over
  the raw replay's seconds for the same control steps: what the planner and the Task add to MuJoCo.

Task and raw run back to back three times per episode (the ratio of each pair, then the median);
figures are medians over cabinets.
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

from opend_mj.sim.camera import RGBDCamera
from opend_mj.assets.layout import load_manifest
from opend_mj.evaluation.episode import EpisodeJob
from opend_mj.evaluation.runner import run_episode
from opend_mj.sim.task import EpisodeSpec, TaskConfig, make_environment


class _Recorder:
    """Wraps ``env.step``: keeps each action and what the Task wrote per substep (controls, mocap)."""

    def __init__(self, env):
        self.env, self.task = env, env.task
        self.actions, self.ctrls, self.paths = [], [], []
        self._step = env.step

    def step(self, action):
        self.actions.append(np.array(action))
        ts = self._step(action)
        self.ctrls.append(self.env.physics.data.ctrl.copy())
        self.paths.append(self.task.mocap_path()[:2])
        return ts

    def substep_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(ctrl per control step, mocap position and quaternion per substep) as the Task set them."""
        n, n_sub = len(self.actions), self.task._substeps
        mocap_pos, mocap_quat = np.empty((n, n_sub, 3)), np.empty((n, n_sub, 4))
        self.env.reset()
        cur_pos = self.env.physics.data.mocap_pos[self.task._mocap_id].copy()
        for k, (pos, quat) in enumerate(self.paths):
            root_quat = self.actions[k][3:7] / np.linalg.norm(self.actions[k][3:7])
            mocap_pos[k] = pos if pos is not None else cur_pos  # None: the mocap stayed put
            mocap_quat[k] = quat if quat is not None else root_quat  # None: set once to the target
            cur_pos = mocap_pos[k, -1].copy()
        return np.array(self.ctrls), mocap_pos, mocap_quat


def _plan_episode(env, hand: str) -> tuple[_Recorder, float]:
    """Run the oracle planner on ``env`` (recording its actions); returns the recorder, loop seconds."""
    from opend_mj.sim.hands import load_spec
    from opend_mj.policy.planner import Observation, Planner, PlannerConfig, Robot
    from opend_mj.policy.solvers import get_solver

    task, physics = env.task, env.physics
    with RGBDCamera(physics, "front", 256, 256) as cam:
        rgb, depth = cam.render()
    solver = get_solver("oracle", ground_truth=lambda: task.handle_boxes(physics)[task.target.joint])
    recorder = _Recorder(env)
    env.step = recorder.step
    obs = Observation(rgb=rgb, depth=depth, instruction=task.instruction, camera_view=task.camera_view(physics))
    start = time.perf_counter()
    Planner(solver, load_spec(hand), PlannerConfig()).run(Robot(env), obs)
    loop_s = time.perf_counter() - start
    del env.step
    return recorder, loop_s


def task_against_raw(env, recorder: _Recorder, repeats: int = 3) -> dict:
    """Replay the recorded actions through the Task, and the same substeps through raw mj_step.

    Task and raw run back to back ``repeats`` times; the ratio of each pair, then the median (the
    machine's load changes slowly, so the two halves of a pair see about the same machine).
    """
    physics = env.physics
    model, data = physics.model.ptr, physics.data.ptr
    ctrls, mocap_pos, mocap_quat = recorder.substep_arrays()
    actions, n_control, n_sub, mid = recorder.actions, len(recorder.actions), mocap_pos.shape[1], env.task._mocap_id

    def task_replay() -> float:
        env.reset()
        start = time.perf_counter()
        for a in actions:
            env.step(a)
        return time.perf_counter() - start

    def raw_replay() -> float:
        env.reset()  # the same start state, then raw mj_step on the very same MjModel / MjData
        start = time.perf_counter()
        for k in range(n_control):
            data.ctrl[:] = ctrls[k]
            for i in range(n_sub):
                data.mocap_pos[mid] = mocap_pos[k, i]
                data.mocap_quat[mid] = mocap_quat[k, i]
                mujoco.mj_step(model, data)
        return time.perf_counter() - start

    pairs, gap = [], 0.0
    for _ in range(repeats):
        task_s = task_replay()
        q_task = data.qpos.copy()
        raw_s = raw_replay()
        gap = max(gap, float(np.max(np.abs(data.qpos - q_task))))
        pairs.append((task_s, raw_s))
    task_s = statistics.median(t for t, _ in pairs)
    raw_s = statistics.median(r for _, r in pairs)
    return {"ratio": statistics.median(t / r for t, r in pairs), "task_s": task_s, "raw_s": raw_s,
            "n_control": n_control, "n_sub": n_sub, "same_state": gap}


def bench_one(cabinet_dir: Path, joint: str, hand: str, config: TaskConfig, cabinet_id: str) -> dict:
    env = make_environment(EpisodeSpec(cabinet_dir, joint, hand, seed=0), config, observations=False)  # as `opend run`
    env.reset()
    task, physics = env.task, env.physics
    recorder, loop_s = _plan_episode(env, hand)
    episode = task_against_raw(env, recorder)
    sim_s = episode["n_control"] * task.control_timestep

    # free air: the hand circling, no contacts (the cheapest physics: the Task's worst ratio)
    env.reset()
    pos, quat = task.start_pose
    air = _Recorder(env)
    for k in range(180):
        air.step(task.make_action(pos + 0.05 * np.array([0, np.sin(k / 20), np.cos(k / 20) - 1]), quat,
                                  task.hand.spec.open_pose))
    free_air = task_against_raw(env, air)

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
    n_control, n_sub = episode["n_control"], episode["n_sub"]
    return {"task_steps_per_s": n_control / episode["task_s"], "raw_control_equiv_per_s": n_control / episode["raw_s"],
            "ratio": episode["ratio"], "air_ratio": free_air["ratio"],
            "raw_mj_steps_per_s": n_control * n_sub / episode["raw_s"], "task_rtf": sim_s / episode["task_s"],
            "raw_rtf": sim_s / episode["raw_s"], "loop_rtf": sim_s / loop_s,
            "episode_rtf": rec["sim_seconds"] / rec["wall_seconds"], "episode_wall_s": rec["wall_seconds"],
            "sim_s": sim_s, "same_state": max(episode["same_state"], free_air["same_state"]),
            "loop_over_raw": loop_s / episode["raw_s"], "episode_over_raw": rec["wall_seconds"] / episode["raw_s"],
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
    # One untimed planner episode first: the planner's first run in a process imports what it needs
    # (scipy and others, about a second), which `opend run` pays once per worker, not per episode.
    cab, tgt = pairs[0]
    warm = make_environment(EpisodeSpec(args.cabinets / cab["path"], tgt["joint"], args.hand, seed=0), config,
                            observations=False)
    warm.reset()
    _plan_episode(warm, args.hand)
    warm.close()
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
    print(f"| **Task / raw (episode; median of 3 back-to-back pairs)** | **{med['ratio']:.2f}x** |")
    print(f"| Task / raw (hand in free air, no contacts) | {med['air_ratio']:.2f}x |")
    print(f"| real-time factor, raw mj_step (the ceiling for anything built on it) | {med['raw_rtf']:.0f}x |")
    print(f"| real-time factor, Task stepping | {med['task_rtf']:.0f}x |")
    print(f"| **real-time factor, episode loop (planner + Task, no rendering)** | **{med['loop_rtf']:.0f}x** |")
    print(f"| real-time factor, whole episode (scene build + 1 RGB-D frame + loop) | {med['episode_rtf']:.1f}x |")
    print(f"| **planner episode loop wall time / raw physics time of the same steps** | **{med['loop_over_raw']:.2f}x** |")
    print(f"| whole `opend run` episode wall time / raw physics time of its steps | {med['episode_over_raw']:.2f}x |")
    print(f"| whole episode, wall s (sim {med['sim_s']:.1f} s) | {med['episode_wall_s']:.2f} |")
    print(f"| RGB frames/s, 256x256 | {med['rgb_fps']:.0f} |")
    print(f"| depth frames/s, 256x256 | {med['depth_fps']:.0f} |")
    print(f"| oracle successes in the whole-episode runs | {sum(r['success'] for r in rows)} / {len(rows)} |")


if __name__ == "__main__":
    main()
