"""Benchmark of the task: control steps/s of the dm_control Task against raw mj_step on the same
compiled model (the overhead ratio), and RGB / depth frames per second at 256 x 256.

    python tools/bench_task.py [--cabinets cabinets] [--count 5] [--hand allegro]

Figures are medians over cabinets; each measures a few seconds of simulated time.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import opend_mj  # noqa: F401  (chooses off-screen EGL before mujoco loads)
import mujoco  # noqa: I001
import numpy as np

from opend_mj.camera import RGBDCamera
from opend_mj.dataset import load_manifest
from opend_mj.task import EpisodeSpec, TaskConfig, make_environment


def bench_one(cabinet_dir: Path, joint: str, hand: str, seconds: float) -> dict:
    config = TaskConfig(enable_rgbd=False)
    env = make_environment(EpisodeSpec(cabinet_dir, joint, hand, seed=0), config)
    env.reset()
    task = env.task
    n_control = int(seconds * config.control_hz)
    substeps = round(1 / config.control_hz / config.physics_timestep)
    pos, quat = task.start_pose
    # A gentle circle of the hand root so that the step is not trivially idle.
    actions = [task.make_action(pos + 0.05 * np.array([0, np.sin(k / 20), np.cos(k / 20) - 1]), quat,
                                task.hand.spec.open_pose) for k in range(n_control)]
    start = time.perf_counter()
    for a in actions:
        env.step(a)
    task_rate = n_control / (time.perf_counter() - start)

    env.reset()  # the same start state, then raw mj_step on the very same MjModel / MjData
    model, data = env.physics.model.ptr, env.physics.data.ptr
    start = time.perf_counter()
    for _ in range(n_control * substeps):
        mujoco.mj_step(model, data)
    raw_rate = n_control * substeps / (time.perf_counter() - start)

    env.reset()
    with RGBDCamera(env.physics, "front", 256, 256) as cam:
        cam.render_rgb()
        start = time.perf_counter()
        for _ in range(30):
            cam.render_rgb()
        rgb_fps = 30 / (time.perf_counter() - start)
        start = time.perf_counter()
        for _ in range(30):
            cam.render_depth()
        depth_fps = 30 / (time.perf_counter() - start)
    env.close()
    return {"task_steps_per_s": task_rate, "raw_control_equiv_per_s": raw_rate / substeps,
            "raw_mj_steps_per_s": raw_rate, "ratio": (raw_rate / substeps) / task_rate,
            "rgb_fps": rgb_fps, "depth_fps": depth_fps, "realtime_factor": task_rate / config.control_hz}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cabinets", type=Path, default=Path("cabinets"))
    parser.add_argument("--count", type=int, default=5)
    parser.add_argument("--hand", default="allegro")
    parser.add_argument("--seconds", type=float, default=3.0)
    args = parser.parse_args()
    manifest = load_manifest(args.cabinets)
    cabinets = manifest.cabinets[:: max(1, len(manifest.cabinets) // args.count)][: args.count]
    rows = []
    for cab in cabinets:
        r = bench_one(args.cabinets / cab["path"], cab["targets"][0]["joint"], args.hand, args.seconds)
        rows.append(r)
        print(f"{cab['id']}: task {r['task_steps_per_s']:.0f} ctrl/s, raw {r['raw_mj_steps_per_s']:.0f} mj_step/s "
              f"(ratio {r['ratio']:.2f}), RGB {r['rgb_fps']:.0f} fps, depth {r['depth_fps']:.0f} fps", flush=True)
    med = {k: statistics.median(r[k] for r in rows) for k in rows[0]}
    print(f"\n## Task benchmark ({args.hand}, {len(rows)} cabinets, medians)\n")
    print("| figure | value |\n|---|---:|")
    print(f"| Task control steps/s (60 Hz, 8 substeps) | {med['task_steps_per_s']:.0f} |")
    print(f"| raw mj_step steps/s, same model | {med['raw_mj_steps_per_s']:.0f} |")
    print(f"| raw, as control steps/s | {med['raw_control_equiv_per_s']:.0f} |")
    print(f"| overhead ratio raw / Task | {med['ratio']:.2f}x |")
    print(f"| real-time factor of the Task (no rendering) | {med['realtime_factor']:.1f}x |")
    print(f"| RGB frames/s, 256x256 | {med['rgb_fps']:.0f} |")
    print(f"| depth frames/s, 256x256 | {med['depth_fps']:.0f} |")


if __name__ == "__main__":
    main()
