"""Tune a handle solver's settings on rendered frames: render a split's locate frames once (cached to a
pickle), then grade any number of solver variants on them (no re-rendering).

    python tools/locate_sweep.py --cabinets build/opend-train --split train --frames build/frames_train.pkl \
        --variant "fasterrcnn" --variant "fasterrcnn:checkpoint=out/x.pt,proposals=False"

A variant is ``solver[:key=value,...]``; values are Python literals or strings. Prints located /
wrong handle / missed per variant (drawers, doors, overall). For tuning on train parts only.
"""

from __future__ import annotations

import argparse
import ast
import os
import pickle
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")


def render_frames(cabinets: Path, split: str, light_scale: float = 1.0, paraphrase: int = 0,
                  seed: int = 0) -> list[dict]:
    from tqdm import tqdm

    from opend_mj.evaluation.locate import locate_frames, locate_jobs

    jobs = locate_jobs(cabinets, split, seed, light_scale, paraphrase)
    return [dict(cabinet=job.cabinet, joint=job.joint, kind=task.target.kind, instruction=task.instruction,
                 rgb=rgb, depth=depth, view=view, boxes=boxes)
            for job, task, rgb, depth, view, boxes in tqdm(locate_frames(jobs), total=len(jobs), desc="render",
                                                           unit="target")]


def miss_causes(solver, frame: dict, kinds: dict[str, str]) -> list[str]:
    """Why a Faster R-CNN variant missed: its candidates (the depth proposals with the head's kind
    calls) against every target's box and kind (``kinds``: joint -> door / drawer)."""
    import numpy as np

    from opend_mj.evaluation.grading import box_contains
    from opend_mj.language import canonical_instruction, describe_instruction
    from opend_mj.policy.learned.detector import detect_handles
    from opend_mj.policy.perception import handle_proposals

    named = describe_instruction(canonical_instruction(frame["instruction"])).kind
    props = np.array([b for b, _ in handle_proposals(frame["depth"], frame["view"])], float).reshape(-1, 4)
    _, scored = detect_handles(solver.model, frame["rgb"], props, depth=frame["depth"])
    called = scored.kind_probability(named) >= 0.5 if len(props) else np.zeros(0, bool)
    on = []
    for b in props:
        u, v = (b[0] + b[2]) / 2, (b[1] + b[3]) / 2
        on.append(next((j for j, g in frame["boxes"].items() if box_contains(g, u, v)), None))
    causes = set()
    if frame["joint"] not in on:
        causes.add("no proposal on the named handle")
    elif not any(c for c, j in zip(called, on) if j == frame["joint"]):
        causes.add("the named handle's kind called wrong")
    for c, j in zip(called, on):
        if c and j is None:
            causes.add("a proposal on no target called the named kind")
        elif c and j != frame["joint"] and kinds.get(j) != named:
            causes.add("a handle of the other kind called the named kind")
    for j, kind in kinds.items():
        if j != frame["joint"] and kind == named and frame["boxes"].get(j) is not None:
            if j not in on:
                causes.add("another handle of the named kind not proposed")
            elif not any(c for c, jj in zip(called, on) if jj == j):
                causes.add("another handle of the named kind called the other kind")
    return sorted(causes) or ["the layout read wrong"]


def parse_variant(text: str) -> tuple[str, dict]:
    name, _, rest = text.partition(":")
    options = {}
    for item in filter(None, rest.split(",")):
        k, _, v = item.partition("=")
        try:
            options[k] = ast.literal_eval(v)
        except (ValueError, SyntaxError):
            options[k] = v
    return name, options


def main() -> None:
    from collections import Counter

    from opend_mj.evaluation.locate import grade
    from opend_mj.policy.solvers import get_solver
    from opend_mj.sim.cabinet import load_cabinet_info

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cabinets", type=Path, required=True)
    ap.add_argument("--split", default="train")
    ap.add_argument("--frames", type=Path, required=True)
    ap.add_argument("--light-scale", type=float, default=1.0)
    ap.add_argument("--paraphrase", type=int, default=0)
    ap.add_argument("--seed", type=int, default=0, help="episode seed of the rendered scenes (room, camera, light)")
    ap.add_argument("--variant", action="append", default=[])
    ap.add_argument("--proposals", action="store_true",
                    help="also print how often the depth proposals hold the named handle, and how many per image")
    ap.add_argument("--show-misses", action="store_true")
    ap.add_argument("--causes", action="store_true",
                    help="for fasterrcnn variants: count the misses by cause (proposals, kind calls, layout)")
    args = ap.parse_args()
    import opend_mj.policy.perception as perception

    original, memo = perception.handle_proposals, {}

    def cached_proposals(depth, view, *a, **k):  # the same frames are graded by every variant
        key = (id(depth), repr(a), repr(k))
        if key not in memo:
            memo[key] = original(depth, view, *a, **k)
        return memo[key]

    perception.handle_proposals = cached_proposals
    if args.frames.exists():
        frames = pickle.loads(args.frames.read_bytes())
    else:
        frames = render_frames(args.cabinets, args.split, args.light_scale, args.paraphrase, args.seed)
        args.frames.parent.mkdir(parents=True, exist_ok=True)
        args.frames.write_bytes(pickle.dumps(frames))
    if args.proposals:
        held, counts = 0, []
        for f in frames:
            props = perception.handle_proposals(f["depth"], f["view"])
            counts.append(len(props))
            held += any(grade(box, f["joint"], f["boxes"]) == "located" for box, _ in props)
        print(f"proposals: the named handle among them in {100.0 * held / max(1, len(frames)):.1f} % of "
              f"{len(frames)} images, {sum(counts) / max(1, len(counts)):.2f} per image", flush=True)
    for text in args.variant:
        name, options = parse_variant(text)
        solver = get_solver(name, **options)
        verdicts = {"drawer": [], "door": []}
        causes: Counter = Counter()
        for f in frames:
            found = solver.solve(f["rgb"], f["depth"], f["instruction"], f["view"])
            v = grade(found.as_tuple() if found is not None else None, f["joint"], f["boxes"])
            verdicts[f["kind"]].append(v)
            why = []
            if args.causes and v != "located" and name == "fasterrcnn":
                info = load_cabinet_info(args.cabinets / f["cabinet"])
                why = miss_causes(solver, f, {t["joint"]: t["type"] for t in info["targets"]})
                causes.update(why)
            if args.show_misses and v != "located":
                print(f"  {v}: {f['cabinet']} {f['joint']} {f['instruction']!r} {'; '.join(why)}")
        allv = verdicts["drawer"] + verdicts["door"]

        def pct(vs, what):
            return 100.0 * sum(v == what for v in vs) / max(1, len(vs))

        print(f"{text}: located {pct(allv, 'located'):.1f} % (drawers {pct(verdicts['drawer'], 'located'):.1f}, "
              f"doors {pct(verdicts['door'], 'located'):.1f}), wrong {pct(allv, 'wrong_handle'):.1f}, "
              f"missed {pct(allv, 'missed'):.1f}; n = {len(allv)}", flush=True)
        for cause, n in causes.most_common():
            print(f"  {n:3d} misses with: {cause}")


if __name__ == "__main__":
    main()
