"""From a compiled dataset's manifest to the list of episodes of a run, and their grouping by scene."""

from __future__ import annotations

from pathlib import Path
from typing import Iterable

from opend_mj.assets.layout import CABINET_JSON, load_manifest
from opend_mj.evaluation.episode import EpisodeJob, scene_key


def make_jobs(cabinets_dir: Path, hands: Iterable[str], solver: str, split: str = "test", seed: int = 0,
              light_scale: float = 1.0, pull: str = "arc", limit: int | None = None,
              video_dir: Path | None = None, cabinet_ids: Iterable[str] | None = None,
              paraphrase: int = 0, physics_timestep: float | None = None,
              targets: Iterable[str] | None = None, kind: str | None = None,
              perturb: str | None = None) -> list[EpisodeJob]:
    """Episodes of a run, hand by hand over the split's (cabinet, target) pairs in manifest order.

    ``cabinet_ids`` keeps whole cabinets; ``targets`` keeps ``"ID"`` (every target of a cabinet) or
    ``"ID:JOINT"`` (one target), e.g. to rerun the failures of an earlier run; ``kind`` ("drawer"
    or "door") keeps that kind of target (before ``limit``).
    """
    cabinets_dir = Path(cabinets_dir)
    manifest = load_manifest(cabinets_dir)
    pairs = manifest.targets(split)
    if cabinet_ids is not None:
        ids = set(cabinet_ids)
        pairs = [(c, t) for c, t in pairs if c["id"] in ids]
    if targets is not None:
        wanted = set(targets)
        pairs = [(c, t) for c, t in pairs if c["id"] in wanted or f"{c['id']}:{t['joint']}" in wanted]
        found = {c["id"] for c, _ in pairs} | {f"{c['id']}:{t['joint']}" for c, t in pairs}
        if wanted - found:
            raise ValueError(f"{cabinets_dir}: no target {', '.join(sorted(wanted - found))} in split {split!r}")
    if kind is not None:
        pairs = [(c, t) for c, t in pairs if t.get("type") == kind]
    if limit is not None:
        pairs = pairs[:limit]
    jobs = []
    for hand in hands:
        for cab, tgt in pairs:
            cab_dir = cabinets_dir / cab.get("path", cab["id"]) if not Path(cab.get("path", "")).is_absolute() \
                else Path(cab["path"])
            if not (cab_dir / CABINET_JSON).is_file():
                cab_dir = cabinets_dir / cab["id"]
            jobs.append(EpisodeJob(cabinet=cab["id"], cabinet_dir=str(cab_dir), joint=tgt["joint"],
                                   split=cab["split"], hand=hand, solver=solver, seed=seed,
                                   light_scale=light_scale, pull=pull,
                                   video_dir=str(video_dir) if video_dir else None,
                                   target_type=tgt.get("type"), instruction=tgt.get("instruction"),
                                   paraphrase=paraphrase, physics_timestep=physics_timestep,
                                   perturb=perturb))
    return jobs


def group_jobs(jobs: list[EpisodeJob], max_size: int = 8) -> list[tuple[EpisodeJob, ...]]:
    """Consecutive jobs with the same `scene_key`, in order, at most ``max_size`` per group."""
    groups: list[list[EpisodeJob]] = []
    for job in jobs:
        if groups and len(groups[-1]) < max_size and scene_key(groups[-1][-1]) == scene_key(job):
            groups[-1].append(job)
        else:
            groups.append([job])
    return [tuple(g) for g in groups]


def check_perturbed_scenes(jobs: list[EpisodeJob]) -> int:
    """Refuse (`sim.perturb.PerturbError`, one line naming the cabinet and the perturbation) a run in
    which a perturbation makes a scene invalid: the camera inside the cabinet, a distractor at the
    hand's start or on its way. Geometry only (cabinet.json's bounds; nothing compiles), so it runs
    before any episode. Returns how many perturbed scenes were checked."""
    from opend_mj.evaluation.episode import scene_seed
    from opend_mj.sim.cabinet import load_cabinet_info
    from opend_mj.sim import perturb
    from opend_mj.sim.task import TaskConfig, scene_geometry

    seen = set()
    for job in jobs:
        if job.perturb is None or scene_key(job) in seen:
            continue
        seen.add(scene_key(job))
        info = load_cabinet_info(Path(job.cabinet_dir))
        bounds = (info["bounds"]["min"], info["bounds"]["max"])
        config = TaskConfig(perturb=job.perturb, perturb_config=perturb.DEFAULT_CONFIG)
        shift = perturb.SceneShift.draw(job.perturb, scene_seed(job), bounds, config.perturb_config)
        pose, start = scene_geometry(bounds, config, shift)
        shift.check(bounds, pose.pos, start, label=f"{job.cabinet_dir}")
    return len(seen)
