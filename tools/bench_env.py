"""Environment steps per second against what MuJoCo itself allows, in one run (`make bench-env`).

    python tools/bench_env.py [--cabinets cabinets] [--hand allegro] [--steps 1500] [--image-steps 300]

Figures (`opend/OpenCabinet-v0`, random delta actions drawn before timing, so the policy's cost is
not counted; single environments time ``step`` alone and reset an ended episode outside the timing,
vector environments time everything, their autoresets included):

- raw mj_step: ``mj_step(model, data, n)`` on the environment's own compiled model (the hand at its
  start pose, in free air), one C call; / substeps per control step = the ceiling in control steps/s.
- state: the environment's steps/s (1 process) and their ratio to the ceiling. Raw and environment
  runs alternate three times (median of each), so that both see about the same machine load.
- vector: `OpenDVectorEnv` (``gym.make_vec``'s default for these ids: shared memory) with 1 and 2
  worker processes, and gymnasium's ``AsyncVectorEnv`` with 2 (pickled dict observations and info)
  for comparison; the ratio is 2 processes against the single in-process environment.
- RGB-D at each image size: environment steps/s, the renderer's own rate (``RGBDCamera.render``:
  rgb + depth of one scene update), and the ceiling of physics and rendering alone
  (1 / (1 / control-step ceiling + 1 / render rate)).

The machine's load average is printed first: on a shared machine every figure moves with it, and
only ratios measured in the same run compare. The state figures are also given in CPU time of the
process (``time.process_time``), which waiting for a core does not inflate.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402

import opend_mj.sim.gym_env  # noqa: E402,F401  (registers the ids)

ENV_ID = "opend/OpenCabinet-v0"


def _actions(space, steps: int, seed: int = 0) -> list[np.ndarray]:
    space.seed(seed)
    return [space.sample() for _ in range(steps)]


def _run_env(env, actions, clock=time.perf_counter) -> tuple[float, int]:
    """Steps/s of ``env.step`` alone (an ended episode is reset outside the timing: a reset that
    compiles a new scene takes about a second, which would swamp a few hundred steps)."""
    resets, seconds = 0, 0.0
    for a in actions:
        start = clock()
        _, _, terminated, truncated, _ = env.step(a)
        seconds += clock() - start
        if terminated or truncated:
            env.reset()
            resets += 1
    return len(actions) / seconds, resets


def _raw_rate(env, n: int, clock=time.perf_counter) -> float:
    """mj_step/s on a copy of the environment's current MjData (its own model)."""
    physics = env.unwrapped.core.scene.physics
    model = physics.model.ptr
    data = mujoco.MjData(model)
    mujoco.mj_copyData(data, model, physics.data.ptr)
    start = clock()
    mujoco.mj_step(model, data, n)
    return n / (clock() - start)


def state_figures(base: dict, steps: int) -> dict:
    env = gym.make(ENV_ID, obs_mode="state", **base)
    env.reset(seed=0)
    substeps = env.unwrapped.core.scene.task._substeps
    actions = _actions(env.action_space, steps)
    _run_env(env, actions[:100])  # warm-up
    raw, rates, resets, cpu_raw, cpu_rates = [], [], 0, [], []
    for _ in range(3):
        raw.append(_raw_rate(env, steps * substeps // 3))
        cpu_raw.append(_raw_rate(env, steps * substeps // 3, time.process_time))
        rate, r = _run_env(env, actions)
        rates.append(rate)
        cpu_rates.append(_run_env(env, actions, time.process_time)[0])
        resets += r
    raw.append(_raw_rate(env, steps * substeps // 3))
    env.close()
    raw_rate, cpu_raw_rate = statistics.median(raw), statistics.median(cpu_raw)
    return {"raw_mj_step": raw_rate, "substeps": substeps, "ceiling": raw_rate / substeps,
            "state": statistics.median(rates), "resets": resets,
            "cpu_ceiling": cpu_raw_rate / substeps, "cpu_state": statistics.median(cpu_rates)}


def vector_rate(base: dict, steps: int, n: int, mode: str | None = None) -> tuple[float, float]:
    """(steps of all environments per second, the main process's CPU seconds per vector step)."""
    kwargs = {"vectorization_mode": mode, "vector_kwargs": {"context": "spawn"}} if mode else {}
    envs = gym.make_vec(ENV_ID, num_envs=n, obs_mode="state", **kwargs, **base)
    try:
        envs.reset(seed=list(range(n)))
        actions = _actions(envs.action_space, steps)
        for a in actions[:50]:
            envs.step(a)
        start, cpu = time.perf_counter(), time.process_time()
        for a in actions:
            envs.step(a)
        wall, cpu = time.perf_counter() - start, time.process_time() - cpu
        return n * steps / wall, cpu / steps
    finally:
        envs.close()


def image_figures(base: dict, steps: int, size: int) -> dict:
    from opend_mj.sim.camera import RGBDCamera

    env = gym.make(ENV_ID, obs_mode="rgbd", image_size=size, **base)
    env.reset(seed=0)
    actions = _actions(env.action_space, steps)
    _run_env(env, actions[:20])
    rate, _ = _run_env(env, actions)
    physics = env.unwrapped.core.scene.physics
    env.unwrapped.core.scene.close()  # one renderer per process: measure the camera alone
    with RGBDCamera(physics, "front", size, size) as cam:
        cam.render()
        start = time.perf_counter()
        for _ in range(steps // 3):
            cam.render()
        render_rate = (steps // 3) / (time.perf_counter() - start)
    env.close()
    return {"rgbd": rate, "render": render_rate}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cabinets", default="cabinets")
    parser.add_argument("--hand", default="allegro")
    parser.add_argument("--split", default="train")
    parser.add_argument("--steps", type=int, default=1500, help="state steps per environment and run")
    parser.add_argument("--image-steps", type=int, default=300, help="RGB-D steps per image size")
    parser.add_argument("--sizes", default="128,256", help="RGB-D image sizes (square), comma-separated")
    args = parser.parse_args()
    base = {"cabinets": args.cabinets, "hand": args.hand, "split": args.split}
    load = os.getloadavg()
    print(f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} CPUs", flush=True)

    s = state_figures(base, args.steps)
    print(f"raw mj_step {s['raw_mj_step']:.0f}/s -> ceiling {s['ceiling']:.0f} control steps/s; "
          f"state env {s['state']:.0f} steps/s ({s['state'] / s['ceiling']:.2f} of the ceiling)", flush=True)
    vec1, main1 = vector_rate(base, args.steps, 1)
    vec2, main2 = vector_rate(base, args.steps, 2)
    async2, main_async = vector_rate(base, args.steps, 2, mode="async")
    print(f"vector env: 1 process {vec1:.0f}, 2 processes {vec2:.0f} steps/s; gymnasium async 2 processes "
          f"{async2:.0f}", flush=True)
    images = []
    for size in (int(x) for x in args.sizes.split(",")):
        f = image_figures(base, args.image_steps, size)
        ceiling = 1.0 / (1.0 / s["ceiling"] + 1.0 / f["render"])
        images.append((size, f, ceiling))
        print(f"rgbd {size}: env {f['rgbd']:.0f} steps/s, renderer alone {f['render']:.0f} frames/s, "
              f"physics + rendering ceiling {ceiling:.0f}", flush=True)

    print(f"\n## Environment benchmark (`{ENV_ID}`, {args.hand}, {args.split} split, random delta actions, "
          f"60 Hz control, {s['substeps']} physics substeps; load average {load[0]:.1f} on {os.cpu_count()} CPUs)\n")
    print("| figure | value | against |")
    print("|---|---:|---:|")
    print(f"| raw `mj_step`/s on the env's own model | {s['raw_mj_step']:.0f} | |")
    print(f"| ceiling: control steps/s (raw / {s['substeps']}) | {s['ceiling']:.0f} | |")
    print(f"| **state steps/s, 1 process** | **{s['state']:.0f}** | **{s['state'] / s['ceiling']:.2f} of the ceiling** |")
    print(f"| the same in CPU time of the process (steps per CPU second; ceiling {s['cpu_ceiling']:.0f}) | "
          f"{s['cpu_state']:.0f} | {s['cpu_state'] / s['cpu_ceiling']:.2f} of the ceiling |")
    us = 1e6
    print(f"| state steps/s, vector env, 1 worker process (main process CPU per step {main1 * us:.0f} us) | "
          f"{vec1:.0f} | {vec1 / s['state']:.2f}x 1 process |")
    print(f"| **state steps/s, vector env, 2 worker processes** (main process CPU per step {main2 * us:.0f} us) | "
          f"**{vec2:.0f}** | **{vec2 / s['state']:.2f}x 1 process, {vec2 / vec1:.2f}x 1 worker** |")
    print(f"| state steps/s, gymnasium AsyncVectorEnv, 2 processes (main process CPU per step {main_async * us:.0f} us) "
          f"| {async2:.0f} | {async2 / s['state']:.2f}x 1 process |")
    for size, f, ceiling in images:
        print(f"| RGB-D {size}x{size} steps/s, 1 process | {f['rgbd']:.0f} | {f['rgbd'] / ceiling:.2f} of physics + "
              f"rendering ({ceiling:.0f}) |")
        print(f"| renderer alone, RGB-D {size}x{size} frames/s | {f['render']:.0f} | |")


if __name__ == "__main__":
    main()
