"""Environment steps per second of the batched MuJoCo Warp environment, beside the CPU environment's.

    python tools/bench_warp.py [--cabinets cabinets] [--hand allegro] [--worlds 1 16 256 4096]
                               [--budget 600] [--device cuda:0]

On the device Warp finds (an NVIDIA GPU if there is one, else the CPU; ``--device`` names one), one
`WarpBatchEnv` per N (the first test-split drawer of the dataset, state observations, dense reward,
random delta actions) is built, stepped once (kernel compiles and warm-up, not timed) and then timed
over as many control steps as its share of ``--budget`` seconds allows (at least 2). A larger N is
skipped when the smaller one's rate says two of its steps would not fit in what is left. In the same
run, the CPU environment (`OpenDCore`, one process, the compiled step) is timed on the same episode.
Prints one line per N: env steps/s (control steps of all worlds together, each 8 physics steps), its
ratio to the CPU environment's, seconds per batched step; then the device in words and the load
average (above the core count, other work shared the machine and the rates understate it).
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time

import numpy as np


def first_drawer(cabinets: str) -> tuple[str, str]:
    from opend_mj.assets.layout import load_manifest

    for cab, tgt in load_manifest(cabinets).targets("test"):
        if tgt.get("type") == "drawer":
            return cab["id"], tgt["joint"]
    raise SystemExit(f"no test-split drawer in {cabinets}")


def cpu_rate(cabinets: str, hand: str, cabinet: str, joint: str, seconds: float) -> float:
    from opend_mj.sim.envs import OpenDCore, make_config

    core = OpenDCore(make_config(cabinets=cabinets, hand=hand, split="all", cabinet_ids=(cabinet,)))
    options = {"cabinet": cabinet, "target": joint, "room": 0, "scene_seed": 0}
    rng = np.random.default_rng(0)
    core.reset(0, options)
    n, start = 0, time.perf_counter()
    actions = rng.uniform(-1, 1, (1000, core.adapter.delta_dim))
    while time.perf_counter() - start < seconds:
        _, _, terminated, truncated, _ = core.step(actions[n % 1000], observe=False)
        n += 1
        if terminated or truncated:
            core.reset(n, options)
    rate = n / (time.perf_counter() - start)
    core.close()
    return rate


def device_words(wp, device) -> str:
    if device.is_cuda:
        return f"{device.name} ({device.alias}), Warp {wp.__version__}"
    cores = os.cpu_count()
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            names = [line.split(":", 1)[1].strip() for line in f if line.startswith("model name")]
        cpu = names[0] if names else cpu
    except OSError:
        pass
    return f"CPU: {cpu}, {cores} cores (Warp {wp.__version__}, CPU kernels)"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cabinets", default="cabinets")
    parser.add_argument("--hand", default="allegro")
    parser.add_argument("--worlds", type=int, nargs="+", default=[1, 16, 256, 4096])
    parser.add_argument("--budget", type=float, default=600.0, help="seconds for the whole run (compiles aside)")
    parser.add_argument("--device", default=None, help="Warp device (cpu, cuda:0); default: Warp's preferred")
    parser.add_argument("--cpu-seconds", type=float, default=10.0, help="seconds the CPU environment is timed")
    args = parser.parse_args(argv)

    from opend_mj.sim import warp_env

    if not warp_env.available():
        print(warp_env.MISSING, file=sys.stderr)
        return 2
    import torch
    import warp as wp

    wp.config.quiet = True
    wp.init()
    device = wp.get_device(args.device) if args.device else wp.get_preferred_device()
    cabinet, joint = first_drawer(args.cabinets)
    deadline = time.perf_counter() + args.budget
    cpu = cpu_rate(args.cabinets, args.hand, cabinet, joint, args.cpu_seconds)
    print(f"episode: {cabinet}/{joint}, hand {args.hand}, state observations, dense reward, random delta actions")
    print(f"CPU environment (OpenDCore, 1 process, compiled step): {cpu:,.0f} env steps/s")
    print(f"{'N':>6} {'env steps/s':>12} {'x CPU env':>9} {'s/step':>8} {'steps':>6} {'build s':>8} {'first s':>8}",
          flush=True)
    per_world = None  # seconds per world-step of the last N (to predict the next)
    for n in sorted(args.worlds):
        left = deadline - time.perf_counter()
        if per_world is not None and 2 * per_world * n > left:
            print(f"{n:>6} skipped: two steps would take about {2 * per_world * n:.0f} s, {left:.0f} s left")
            continue
        t0 = time.perf_counter()
        try:
            env = warp_env.WarpBatchEnv(n, cabinet, joint, cabinets=args.cabinets, hand=args.hand,
                                        device=str(device), reset_pool=min(n, 64))
        except Exception as exc:  # out of memory on the device, above all
            print(f"{n:>6} could not be built: {type(exc).__name__}: {str(exc).splitlines()[0][:120]}")
            continue
        build = time.perf_counter() - t0
        env.reset()
        gen = torch.Generator(device=env.device).manual_seed(0)
        action = lambda: torch.rand(n, env.action_dim, generator=gen, device=env.device, dtype=torch.float64) * 2 - 1
        t1 = time.perf_counter()
        env.step(action())
        wp.synchronize_device(device)
        first = time.perf_counter() - t1
        left = deadline - time.perf_counter()
        share = left / max(1, sum(1 for m in args.worlds if m >= n))
        steps, start = 0, time.perf_counter()
        while steps < 2 or (time.perf_counter() - start < share and steps < 200):
            env.step(action())
            steps += 1
        wp.synchronize_device(device)
        seconds = (time.perf_counter() - start) / steps
        per_world = seconds / n
        rate = n / seconds
        print(f"{n:>6} {rate:>12,.0f} {rate / cpu:>9.2f} {seconds:>8.3f} {steps:>6} {build:>8.1f} {first:>8.1f}",
              flush=True)
        env.close()
        del env
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"device: {device_words(wp, device)}; load average (1 min) at the end: {load:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
