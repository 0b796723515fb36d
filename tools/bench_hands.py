"""Steps per second of mj_step for each hand: alone in the air, and while grasping and pulling the
test bar (approach, close, pull). Usage: python tools/bench_hands.py [hand ...] [--seconds S]"""

from __future__ import annotations

import argparse
import time

import mujoco
from dm_control import mjcf

from opend_mj.sim import hands
from opend_mj.sim.hands import scene as hand_scene


def bench_alone(name: str, seconds: float) -> float:
    root, handle = hand_scene.build_scene(name)
    physics = mjcf.Physics.from_mjcf_model(root)
    m, d = physics.model.ptr, physics.data.ptr
    handle.hand.set_finger_targets(physics, handle.hand.spec.open_pose)
    n = int(seconds / m.opt.timestep)
    t0 = time.perf_counter()
    for _ in range(n):
        mujoco.mj_step(m, d)
    return n / (time.perf_counter() - t0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("hands", nargs="*", default=hands.list_hands())
    ap.add_argument("--seconds", type=float, default=4.0, help="simulated seconds for 'alone'")
    args = ap.parse_args()
    print("| hand | alone, mj_step/s | grasping horizontal bar, mj_step/s | grasping vertical bar, mj_step/s"
          " | bar pulled H, cm | bar pulled V, cm |")
    print("|---|---:|---:|---:|---:|---:|")
    for name in args.hands:
        alone = bench_alone(name, args.seconds)
        rh = hand_scene.bar_pull_trial(name, "horizontal")
        rv = hand_scene.bar_pull_trial(name, "vertical")
        print(f"| {name} | {alone:.0f} | {rh.steps_per_s:.0f} | {rv.steps_per_s:.0f}"
              f" | {rh.bar_moved * 100:.1f} | {rv.bar_moved * 100:.1f} |", flush=True)


if __name__ == "__main__":
    main()
