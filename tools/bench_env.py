"""Environment steps per second: `opend/OpenCabinet-v0`, state-only and RGB-D, one process and a
2-process vector environment (`gymnasium.make_vec`, async, spawn). Random normalised actions; an
episode that ends is reset (auto-reset in the vector environment), and the reset time (the scene
build, or its reuse) is counted in the figures, as an RL user sees it; the first reset is not.

    python tools/bench_env.py [--cabinets cabinets] [--hand allegro] [--steps 1500] [--image-size 256]
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym  # noqa: E402

import opend_mj.sim.gym_env  # noqa: E402,F401  (registers the ids)

ENV_ID = "opend/OpenCabinet-v0"


def single(kwargs: dict, steps: int) -> tuple[float, int]:
    env = gym.make(ENV_ID, **kwargs)
    env.action_space.seed(0)
    env.reset(seed=0)
    resets = 0
    start = time.perf_counter()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            env.reset()
            resets += 1
    seconds = time.perf_counter() - start
    env.close()
    return steps / seconds, resets


def vector(kwargs: dict, steps: int, n: int = 2) -> float:
    envs = gym.make_vec(ENV_ID, num_envs=n, vectorization_mode="async", vector_kwargs={"context": "spawn"},
                        **kwargs)
    envs.action_space.seed(0)
    envs.reset(seed=list(range(n)))
    start = time.perf_counter()
    for _ in range(steps):
        envs.step(envs.action_space.sample())
    seconds = time.perf_counter() - start
    envs.close()
    return n * steps / seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cabinets", default="cabinets")
    parser.add_argument("--hand", default="allegro")
    parser.add_argument("--split", default="train")
    parser.add_argument("--steps", type=int, default=1500, help="steps per environment")
    parser.add_argument("--image-size", type=int, default=256)
    args = parser.parse_args()
    base = {"cabinets": args.cabinets, "hand": args.hand, "split": args.split}
    modes = [("state", {"obs_mode": "state"}),
             (f"rgbd {args.image_size}x{args.image_size}", {"obs_mode": "rgbd", "image_size": args.image_size})]
    rows = []
    for label, extra in modes:
        rate, resets = single({**base, **extra}, args.steps)
        vec = vector({**base, **extra}, args.steps)
        rows.append((label, rate, vec, resets))
        print(f"{label}: {rate:.0f} steps/s (1 process), {vec:.0f} steps/s (2-process vector env)", flush=True)
    print()
    print(f"| `{ENV_ID}` ({args.hand}, {args.split} split, random delta actions, {args.steps} steps per env, "
          "60 Hz control, physics 1/480 s) | 1 process | 2-process vector env (async, spawn) |")
    print("|---|---:|---:|")
    for label, rate, vec, _ in rows:
        print(f"| {label} steps/s | {rate:.0f} | {vec:.0f} |")
    sim = 1.0 / 60.0
    print(f"| (real-time factor, state, 1 process) | {rows[0][1] * sim:.1f}x | {rows[0][2] * sim:.1f}x |")


if __name__ == "__main__":
    main()
