"""Grasp search (`opend search-grasp`): the finger closing and grasp depth that open the most
training targets, found by running episodes (so it lives above the runner, not in the planner)."""

from __future__ import annotations

import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from opend_mj.assets.layout import load_manifest
from opend_mj.evaluation.jobs import make_jobs
from opend_mj.evaluation.pool import run_jobs
from opend_mj.evaluation.results import load_results
from opend_mj.policy.planner import GraspProfile


def search_grasp(hand: str, cabinets_dir: Path, n_cabinets: int = 3, scales=(0.8, 1.0, 1.15),
                 depths=(-0.01, 0.0, 0.008), workers: int = 1) -> GraspProfile:
    """Grid search of finger closing (fraction of the spec's grasp profile) and grasp depth on the
    handles of the first ``n_cabinets`` training cabinets, as the paper did: the first setting (in
    grid order, scale 1 / depth 0 first) with the most opened targets, ties broken by mean open
    ratio. Returns the chosen :class:`GraspProfile` (not saved)."""
    manifest = load_manifest(Path(cabinets_dir))
    ids = [c["id"] for c in manifest.cabinets if c["split"] == "train"][:n_cabinets]
    base = make_jobs(Path(cabinets_dir), [hand], "oracle", split="train", cabinet_ids=ids)
    grid = sorted(((s, d) for s in scales for d in depths), key=lambda sd: (abs(sd[0] - 1.0), abs(sd[1])))
    trials = []
    with tempfile.TemporaryDirectory() as tmp:
        for k, (s, d) in enumerate(grid):
            jobs = [replace(j, planner_overrides=(("grasp.close_scale", s), ("grasp.depth", {"bar": d, "knob": d})),
                            use_grasp_file=False, seed=k) for j in base]
            out = Path(tmp) / f"trial_{k}.jsonl"
            run_jobs(jobs, out, workers=workers, progress=False)
            recs = load_results(out)
            n_ok = sum(bool(r.get("success")) for r in recs)
            mean = float(np.mean([r.get("open_ratio", 0.0) or 0.0 for r in recs])) if recs else 0.0
            trials.append({"close_scale": s, "grasp_depth": d, "success": n_ok, "episodes": len(recs),
                           "mean_open_ratio": round(mean, 4)})
    best = max(trials, key=lambda t: (t["success"], t["mean_open_ratio"]))
    return GraspProfile(hand=hand, close_scale=best["close_scale"],
                        grasp_depth={"bar": best["grasp_depth"], "knob": best["grasp_depth"]},
                        search=trials)
