"""Replay planner demonstrations (`opend demos`) in the batched MuJoCo Warp environment.

Each demo's scene (cabinet, target, room, scene seed, hand; the hand at the benchmark's start, no
start noise) becomes a `WarpBatchEnv` with absolute control; demos of the same scene share one batch
(one world each). The stored task actions (``actions_executed`` where a noisy recording kept them,
else ``actions``) are stepped; at each demo's last action its success verdict and open ratio are
read and compared with the recorded ones. ``--cpu`` also replays each demo in the CPU environment
(`OpenDCore`, same options), which must give the recorded verdict exactly (it checks the set-up).

    python tools/replay_demos_warp.py demos/planner.hdf5 [more.hdf5 ...] [--device cpu] [--cpu]

Prints one line per demo and the share that end with the recorded verdict. Needs the optional
extra ``.[warp]``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np


def scene_key(demo) -> tuple:
    spec = json.loads(demo.attrs["episode"])
    return (str(Path(spec["cabinet_dir"]).parent), demo.attrs["cabinet"], demo.attrs["target_joint"],
            int(demo.attrs["room"]), int(spec["seed"]), demo.attrs["hand"])


def env_kwargs(key, length: int, cabinets: str | None) -> dict:
    root, cabinet, joint, room, seed, hand = key
    return dict(cabinets=cabinets or root, hand=hand, control="absolute", start_noise=0.0, start_yaw_noise=0.0,
                time_limit=max(15.0, (length + 10) / 60.0), terminate_on_success=False, split="all",
                options={"cabinet": cabinet, "target": joint, "room": room, "scene_seed": seed,
                         "start_offset": (0.0, 0.0, 0.0), "start_yaw": 0.0})


def replay_cpu(key, demo, cabinets) -> tuple[bool, float]:
    from opend_mj.sim.envs import OpenDCore, make_config

    kw = env_kwargs(key, len(demo.actions), cabinets)
    options = kw.pop("options")
    core = OpenDCore(make_config(cabinet_ids=(key[1],), **kw))
    try:
        _, info = core.reset(0, options)
        for a in _actions(demo):
            _, _, _, _, info = core.step(a)
        return bool(info["success"]), float(info["open_ratio"])
    finally:
        core.close()


def _actions(demo) -> np.ndarray:
    return np.asarray(demo.extra.get("actions_executed", demo.actions), float)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("demos", nargs="+", help="demonstration files (opend demos)")
    parser.add_argument("--device", default=None, help="Warp device (cpu, cuda:0); default: Warp's")
    parser.add_argument("--cabinets", default=None, help="compiled dataset (default: the demos' own)")
    parser.add_argument("--limit", type=int, default=None, help="first K demos only")
    parser.add_argument("--cpu", action="store_true", help="also replay each demo in the CPU environment")
    args = parser.parse_args(argv)

    from opend_mj.sim import warp_env

    if not warp_env.available():
        print(warp_env.MISSING, file=sys.stderr)
        return 2
    from opend_mj.apps.demos import read_demos
    from opend_mj.sim.warp_env import WarpBatchEnv

    demos = []
    for path in args.demos:
        _, ds = read_demos(path)
        demos += [(path, i, d) for i, d in enumerate(ds)]
    demos = demos[: args.limit] if args.limit else demos
    groups: dict[tuple, list] = defaultdict(list)
    for item in demos:
        groups[scene_key(item[2])].append(item)
    agree = total = cpu_agree = 0
    max_diff = 0.0
    for key, items in groups.items():
        lengths = [len(d.actions) for _, _, d in items]
        kw = env_kwargs(key, max(lengths), args.cabinets)
        options = kw.pop("options")
        start = time.perf_counter()
        env = WarpBatchEnv(len(items), key[1], key[2], room=key[3], scene_seed=key[4], reset_pool=1,
                           reset_options={k: options[k] for k in ("start_offset", "start_yaw")},
                           device=args.device, **kw)
        import torch

        env.reset()
        acts = [_actions(d) for _, _, d in items]
        final = [None] * len(items)
        for t in range(max(lengths)):
            batch = np.stack([a[min(t, len(a) - 1)] for a in acts])
            _, _, _, _, info = env.step(torch.as_tensor(batch))
            for w, n in enumerate(lengths):
                if t == n - 1:
                    final[w] = (bool(info["success"][w]), float(info["open_ratio"][w]))
        seconds = time.perf_counter() - start
        env.close()
        for w, (path, i, d) in enumerate(items):
            success, ratio = final[w]
            rec_success, rec_ratio = bool(d.attrs["success"]), float(d.attrs["open_ratio"])
            total += 1
            agree += success == rec_success
            max_diff = max(max_diff, abs(ratio - rec_ratio))
            line = (f"{Path(path).name}#{i} {key[5]} {key[1]}/{key[2]} room {key[3]}: {len(d.actions)} steps, "
                    f"recorded {'success' if rec_success else 'failure'} {rec_ratio:.4f}, "
                    f"warp {'success' if success else 'failure'} {ratio:.4f} (|diff| {abs(ratio - rec_ratio):.1e})")
            if args.cpu:
                c_success, c_ratio = replay_cpu(key, d, args.cabinets)
                cpu_agree += c_success == rec_success
                line += f", cpu {'success' if c_success else 'failure'} {c_ratio:.4f}"
            print(line + f"  [batch of {len(items)}: {seconds:.0f} s]", flush=True)
    print(f"{agree}/{total} demos end with the recorded verdict in the Warp environment"
          f" (largest open-ratio difference {max_diff:.1e})"
          + (f"; {cpu_agree}/{total} in the CPU environment" if args.cpu else ""))
    return 0 if agree == total else 1


if __name__ == "__main__":
    sys.exit(main())
