"""The compiled environment step against the Python step on every cabinet of a dataset.

    python tools/compare_steps.py --cabinets DIR [--split all] [--hand allegro] [--steps 200]

One scripted episode per cabinet (its first target; reach the instructed handle from the
privileged box, close the fingers, pull, turning the wrist all the time, a random action beyond
[-1, 1] every tenth step), stepped by both environments (``compiled_step`` True and False) side by
side: every step's observation, reward, flags and ``info`` must be equal to the bit, and the whole
MjData at the episode's end. Prints one JSON line: cabinets, steps, steps with touch, with the
handle contact term, with the target opened, and the cabinets that differed (exit status 1 if any).
"""

from __future__ import annotations

import argparse
import json
import sys

import gymnasium as gym
import mujoco
import numpy as np

import opend_mj.sim.gym_env  # noqa: F401  (registers the ids)
from opend_mj.assets.layout import load_manifest
from opend_mj.sim import fast
from opend_mj.sim.scripted import reach_grasp_pull

ENV_ID = "opend/OpenCabinet-v0"
#: the sparse constraint Jacobian's index arrays, never written with a dense Jacobian
_SPARSE_INDEX = {"efc_J_colind", "efc_J_rowadr", "efc_J_rownnz", "efc_J_rowsuper"}


def mjdata_bytes(data, model) -> dict:
    unused = set() if mujoco.mj_isSparse(model) else _SPARSE_INDEX
    out = {name: value.tobytes() for name in dir(data) if not name.startswith("_") and name not in unused
           for value in [getattr(data, name)] if isinstance(value, np.ndarray)}
    out.update(time=data.time, ncon=data.ncon, nefc=data.nefc, warnings=data.warning.number.tobytes())
    return out


def compare_cabinet(compiled, python, cabinet: str, seed: int, steps: int, rng, stats: dict) -> None:
    obs, _ = compiled.reset(seed=seed, options={"cabinet": cabinet})
    ref, _ = python.reset(seed=seed, options={"cabinet": cabinet})
    if compiled.core._fast is None:
        raise SystemExit(f"the compiled step is not in use: {fast.status()}")
    same = lambda a, b: list(a) == list(b) and all(a[k].tobytes() == b[k].tobytes() for k in a)  # noqa: E731
    assert same(obs, ref), "reset"
    for t in range(steps):
        action = reach_grasp_pull(obs, t, compiled.action_space.shape, rng)
        obs, reward, terminated, truncated, info = compiled.step(action)
        ref = python.step(action)
        assert same(obs, ref[0]) and (reward, terminated, truncated) == ref[1:4], f"step {t}"
        assert json.dumps(info, sort_keys=True) == json.dumps(ref[4], sort_keys=True), f"info of step {t}"
        stats["steps"] += 1
        stats["touched"] += bool(obs["touch"].any())
        stats["contact"] += bool(info["reward_terms"]["contact"])
        stats["opened"] += info["open_ratio"] > 0.0
        if terminated or truncated:
            break
    a, b = compiled.core.scene, python.core.scene
    assert mjdata_bytes(a._data, a.physics.model.ptr) == mjdata_bytes(b._data, b.physics.model.ptr), "MjData"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cabinets", default="cabinets")
    parser.add_argument("--split", default="all")
    parser.add_argument("--hand", default="allegro")
    parser.add_argument("--steps", type=int, default=200)
    args = parser.parse_args()
    kwargs = dict(cabinets=args.cabinets, split=args.split, hand=args.hand, privileged=True, max_scenes=1,
                  time_limit=args.steps / 60 + 1)
    compiled = gym.make(ENV_ID, **kwargs).unwrapped
    python = gym.make(ENV_ID, compiled_step=False, **kwargs).unwrapped
    ids = sorted({cab["id"] for cab, _ in load_manifest(args.cabinets).targets(args.split)})
    rng = np.random.default_rng(0)
    stats = {"cabinets": 0, "steps": 0, "touched": 0, "contact": 0, "opened": 0, "differ": []}
    try:
        for k, cabinet in enumerate(ids):
            try:
                compare_cabinet(compiled, python, cabinet, k, args.steps, rng, stats)
            except AssertionError as exc:
                stats["differ"].append(f"{cabinet}: {exc}")
            stats["cabinets"] += 1
    finally:
        compiled.close()
        python.close()
    print(json.dumps(stats))
    return 1 if stats["differ"] else 0


if __name__ == "__main__":
    sys.exit(main())
