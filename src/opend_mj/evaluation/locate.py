"""Locate quality of a handle solver on its own (`opend evaluate-solver`), without running episodes.

For every target of a split, the scene an episode would see (same cabinet, room, seed, light,
instruction wording and perturbation as `opend run`, the depth image as the task's sensor gives it)
is rendered once, the solver is asked for the named handle, and the answer is graded against the
simulator's handle boxes of every target:

* ``located``: the box centre lies inside the named handle's box (3 px margin, as the episode
  runner's failure stages use);
* ``wrong_handle``: it lies inside another target's handle box instead;
* ``missed``: no box, or a centre on no handle.

Both the solver's raw box and the box the planner acts on (`policy.planner.loop.settle_box`: a
learned solver's box snapped to depth, a box over a pair of pulls narrowed to the nearer one) are
graded.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

from opend_mj.evaluation.episode import EpisodeJob  # noqa: E402
from opend_mj.evaluation.grading import box_centre, box_contains  # noqa: E402
from opend_mj.evaluation.jobs import make_jobs  # noqa: E402


@dataclass
class LocateRecord:
    """One target's verdict."""

    cabinet: str
    joint: str
    split: str
    target_type: str
    instruction: str
    solver: str
    seed: int
    light_scale: float
    paraphrase: int
    perturb: str | None
    box: list | None
    gt_box: list | None
    verdict: str  # located | wrong_handle | missed
    verdict_refined: str
    seconds: float


def grade(box, target_joint: str, boxes: dict[str, tuple | None]) -> str:
    """located / wrong_handle / missed for a predicted ``box`` (u0, v0, u1, v1) or None."""
    if box is None:
        return "missed"
    u, v = box_centre(box)
    if box_contains(boxes.get(target_joint), u, v):
        return "located"
    if any(box_contains(b, u, v) for j, b in boxes.items() if j != target_joint):
        return "wrong_handle"
    return "missed"


def locate_jobs(cabinets_dir: Path, split: str = "test", seed: int = 0, light_scale: float = 1.0,
                paraphrase: int = 0, limit: int | None = None, hand: str = "allegro",
                perturb: str | None = None) -> list[EpisodeJob]:
    """The targets of a split as episode jobs (one hand: the hand is out of the image at the start);
    ``perturb``: a canonical perturbation spec (`sim.perturb.parse_perturb`) or None."""
    return make_jobs(cabinets_dir, [hand], "oracle", split=split, seed=seed, light_scale=light_scale,
                     limit=limit, paraphrase=paraphrase, perturb=perturb)


def locate_frames(jobs: list[EpisodeJob]):
    """For each job, the scene its episode would see at the start: yields (job, task, rgb, depth,
    camera view, every target's handle box). The depth is the task's sensor's, fused over the frames
    an episode fuses (under depth_noise, not the render's). One environment per cabinet."""
    from opend_mj.evaluation.jobs import group_jobs
    from opend_mj.evaluation.runner import instruction_for, make_episode_env
    from opend_mj.sim.camera import RGBDCamera

    for group in group_jobs(jobs):
        env = make_episode_env(group[0])
        try:
            for job in group:
                env.task.set_target(job.joint, instruction_for(job))
                env.reset()
                physics, task = env.physics, env.task
                with RGBDCamera(physics, "front", task.config.image_size, task.config.image_size) as cam:
                    rgb, depth = cam.render()
                depth = task.sense_depth(rgb, depth, frames=task.config.depth_frames)
                yield job, task, rgb, depth, task.camera_view(physics), task.handle_boxes(physics)
        finally:
            env.close()


def evaluate_locate(cabinets_dir: Path, solver_name: str, split: str = "test", seed: int = 0,
                    light_scale: float = 1.0, paraphrase: int = 0, limit: int | None = None,
                    progress: bool = True, out: Path | None = None,
                    perturb: str | None = None) -> list[LocateRecord]:
    """Grade ``solver_name`` on every target of ``split`` (under ``perturb``, a canonical spec, if
    given); writes the records to ``out`` (JSONL) if given."""
    from tqdm import tqdm

    from opend_mj.policy.factory import build_solver
    from opend_mj.policy.planner.config import PlannerConfig
    from opend_mj.policy.planner.loop import settle_box

    jobs = locate_jobs(cabinets_dir, split, seed, light_scale, paraphrase, limit, perturb=perturb)
    state: dict = {}
    solver = build_solver(solver_name, ground_truth=lambda: state["boxes"][state["joint"]])
    planner_config = PlannerConfig()
    records: list[LocateRecord] = []
    bar = tqdm(total=len(jobs), desc=f"locate ({solver_name})", unit="target", disable=not progress,
               dynamic_ncols=True)
    t0 = time.perf_counter()
    for job, task, rgb, depth, view, boxes in locate_frames(jobs):
        state.update(boxes=boxes, joint=job.joint)
        found = solver.solve(rgb, depth, task.instruction, view)
        box = list(found.as_tuple()) if found is not None else None
        settled, _ = settle_box(solver, found, depth, view, planner_config)
        refined = list(settled.as_tuple()) if settled is not None else None
        gt = boxes.get(job.joint)
        records.append(LocateRecord(
            cabinet=job.cabinet, joint=job.joint, split=job.split, target_type=task.target.kind,
            instruction=task.instruction, solver=solver_name, seed=job.seed, light_scale=job.light_scale,
            paraphrase=job.paraphrase, perturb=job.perturb, box=[round(x, 2) for x in box] if box else None,
            gt_box=[round(x, 2) for x in gt] if gt else None, verdict=grade(box, job.joint, boxes),
            verdict_refined=grade(refined, job.joint, boxes), seconds=round(time.perf_counter() - t0, 3)))
        bar.update(1)
        bar.set_postfix(located=f"{sum(r.verdict == 'located' for r in records)}/{len(records)}")
        t0 = time.perf_counter()
    bar.close()
    if out is not None:
        out = Path(out)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text("".join(json.dumps(asdict(r)) + "\n" for r in records))
    return records


def summarise(records: list[LocateRecord]) -> list[dict]:
    """Rates per (solver, kind): located, wrong handle, missed; raw box and after depth refinement.

    Records of several episode seeds (the same targets in other rooms, light and camera) are pooled:
    ``targets`` counts views, and ``located_by_seed`` holds each seed's own located rate."""
    rows = []
    solvers = sorted({r.solver for r in records})
    for solver in solvers:
        for kind in ("drawer", "door", "overall"):
            rs = [r for r in records if r.solver == solver and (kind == "overall" or r.target_type == kind)]
            if not rs:
                continue
            n = len(rs)

            def pct(field: str, verdict: str) -> float:
                return round(100.0 * sum(getattr(r, field) == verdict for r in rs) / n, 1)

            seeds = sorted({r.seed for r in rs})
            by_seed = [round(100.0 * sum(r.verdict == "located" for r in rs if r.seed == k)
                             / sum(r.seed == k for r in rs), 1) for k in seeds]
            rows.append({"solver": solver, "kind": kind, "targets": n, "seeds": seeds, "located_by_seed": by_seed,
                         "located": pct("verdict", "located"), "wrong_handle": pct("verdict", "wrong_handle"),
                         "missed": pct("verdict", "missed"),
                         "located_refined": pct("verdict_refined", "located"),
                         "wrong_handle_refined": pct("verdict_refined", "wrong_handle")})
    return rows


def format_summary(rows: list[dict]) -> str:
    """A Markdown table of :func:`summarise`'s rows; with several seeds, a column of each seed's rate."""
    several = any(len(r.get("seeds", ())) > 1 for r in rows)
    head = ("| solver | kind | targets | located % | wrong handle % | missed % | located as the planner acts % | "
            "wrong handle as the planner acts % |")
    lines = [head + (" located per seed % |" if several else ""), "|---" * (9 if several else 8) + "|"]
    for r in rows:
        line = (f"| {r['solver']} | {r['kind']} | {r['targets']} | {r['located']} | {r['wrong_handle']} | "
                f"{r['missed']} | {r['located_refined']} | {r['wrong_handle_refined']} |")
        if several:
            line += " " + " / ".join(f"{x:g}" for x in r["located_by_seed"]) + " |"
        lines.append(line)
    return "\n".join(lines)
