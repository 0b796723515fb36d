"""The handle population of a compiled dataset, measured the way the planner sees it (depth).

    python tools/handle_stats.py --cabinets cabinets [--cabinets build/real-cabinets] [--limit N]

For every cabinet: one front RGB-D image; for every target its handle box (ground truth), the handle
estimated and measured from depth (bar thickness, length, stand-off gap, protrusion, knob size, free
space to the nearest neighbour), its height above the floor, the distance between neighbouring handle
centres, the doors / drawers per cabinet, and (from the build's feasibility report) how high the lowest
moving part of each cabinet stands above the floor. Prints quantiles per dataset side by side (markdown),
so a real dataset and the procedural one can be compared.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402


def measure_dataset(cabinets_dir: Path, limit: int | None = None, split: str = "all") -> dict[str, list[float]]:
    from opend_mj.assets.layout import load_manifest
    from opend_mj.policy.perception import estimate_handle, measure_handle
    from opend_mj.policy.perception import PerceptionConfig
    from opend_mj.policy.handle_box import HandleBox
    from opend_mj.sim.cabinet import load_cabinet_info
    from opend_mj.sim.camera import RGBDCamera
    from opend_mj.sim.task import EpisodeSpec, TaskConfig, make_environment

    manifest = load_manifest(cabinets_dir)
    cabinets = [c for c in manifest.cabinets if split == "all" or c["split"] == split][:limit]
    out: dict[str, list[float]] = {k: [] for k in (
        "bar thickness (mm)", "bar length (mm)", "stand-off gap (mm)", "protrusion (mm)", "knob size (mm)",
        "handle height (m)", "nearest handle edge (mm)", "doors per cabinet", "drawers per cabinet",
        "knobs (share)", "door handles that are horizontal bars (share)",
        "of those, along the door's top or bottom edge (share)", "of those, centred across the door (share)",
        "lowest moving part above the floor (m)", "cabinets with a front within 5 mm of the floor (share)")}
    for cab in cabinets:
        first = cab["targets"][0]["joint"]
        env = make_environment(EpisodeSpec(cabinets_dir / cab["path"], first, hand="franka", seed=0),
                               TaskConfig(enable_rgbd=False, time_limit=1e6))
        env.reset()
        physics = env.physics
        cam = RGBDCamera(physics, "front", env.task.config.image_size, env.task.config.image_size)
        try:
            _, depth = cam.render()
        finally:
            cam.close()
        view = env.task.camera_view(physics)
        boxes = env.task.handle_boxes(physics)
        centres = {}
        for t in env.task.cabinet.targets:
            corners = env.task.handle_corners(physics, t)
            centres[t.joint] = corners.mean(axis=0)
        for t in env.task.cabinet.targets:
            b = boxes.get(t.joint)
            if b is None:
                continue
            box = HandleBox(*b)
            handle = estimate_handle(box, depth, view, PerceptionConfig())
            if handle is None:
                continue
            shape = measure_handle(handle, box, depth, view)
            if handle.kind == "knob":
                out["knob size (mm)"].append(1000 * shape.length)
            else:
                out["bar thickness (mm)"].append(1000 * shape.thickness)
                out["bar length (mm)"].append(1000 * shape.length)
                out["stand-off gap (mm)"].append(1000 * shape.gap)
            out["knobs (share)"].append(1.0 if handle.kind == "knob" else 0.0)
            out["protrusion (mm)"].append(1000 * shape.protrusion)
            out["handle height (m)"].append(float(centres[t.joint][2]))
            out["nearest handle edge (mm)"].append(1000 * min(shape.clear.values()))
        info = load_cabinet_info(cabinets_dir / cab["path"])
        report = info.get("feasibility")  # the build's feasibility check: each part's lowest point as it opens
        if report and report.get("targets"):
            low = min(t["min_clearance"] for t in report["targets"] if t.get("min_clearance") is not None)
            out["lowest moving part above the floor (m)"].append(low)
            out["cabinets with a front within 5 mm of the floor (share)"].append(float(low < 0.005))
        for t in info["targets"]:  # door bars' placement, from the build
            if t["type"] != "door" or "part_box_min" not in t:
                continue
            horizontal = t["handle"]["orientation"] == "horizontal"
            out["door handles that are horizontal bars (share)"].append(float(horizontal))
            if horizontal:
                lo, hi, c = np.array(t["part_box_min"]), np.array(t["part_box_max"]), np.array(t["handle"]["center"])
                across, up = (c[1:] - lo[1:]) / np.maximum(hi[1:] - lo[1:], 1e-6)
                out["of those, along the door's top or bottom edge (share)"].append(float(up > 0.85 or up < 0.15))
                out["of those, centred across the door (share)"].append(float(abs(across - 0.5) < 0.1))
        kinds = [t.kind for t in env.task.cabinet.targets]
        out["doors per cabinet"].append(float(kinds.count("door")))
        out["drawers per cabinet"].append(float(kinds.count("drawer")))
        env.close()
    return out


def summary(values: list[float]) -> str:
    if not values:
        return "-"
    v = np.asarray(values, float)
    if set(np.unique(v)) <= {0.0, 1.0} and len(v) > 1:
        return f"{100 * v.mean():.0f} % (n {len(v)})"
    q = np.percentile(v, [10, 50, 90])
    return f"{q[0]:.3g} / {q[1]:.3g} / {q[2]:.3g} (n {len(v)})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cabinets", action="append", required=True, type=Path)
    ap.add_argument("--label", action="append", default=None)
    ap.add_argument("--limit", type=int, default=None)
    ap.add_argument("--split", default="all")
    args = ap.parse_args()
    labels = args.label or [str(p) for p in args.cabinets]
    stats = [measure_dataset(p, args.limit, args.split) for p in args.cabinets]
    print("| measure (10th / median / 90th percentile) | " + " | ".join(labels) + " |")
    print("|---|" + "---|" * len(labels))
    for key in stats[0]:
        print(f"| {key} | " + " | ".join(summary(s[key]) for s in stats) + " |")


if __name__ == "__main__":
    main()
