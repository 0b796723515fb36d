"""What the camera sees of pulled fronts: run the oracle planner's episodes and count how
`Planner.kind_from_front` reads each pull (door / drawer / unclear) against the target's true kind.

    python tools/front_stats.py --cabinets build/opend-train --split train --out build/fm/real.jsonl
    python tools/front_stats.py --cabinets build/opend-train --split train --swap --out build/fm/real_swap.jsonl

``--swap`` pulls every handle as the other kind (a drawer's as a door, a door's as a drawer): the pulls
a learned solver's wrong handle gets. The thresholds in `KindConfig` (``front_*``) come from these
counts on the real train part and the procedural train split; resumable per results file.
"""

from __future__ import annotations

import argparse
import collections
import json
import multiprocessing as mp
import os
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
HANDS = ("franka", "allegro", "shadow", "skeleton")
#: The kind a handle is named as with ``--swap``.
OTHER_KIND = {"door": "drawer", "drawer": "door"}


def _init(swap: bool) -> None:
    import opend_mj.policy.planner.loop as loop  # the stage loop reads the kind named

    if swap:
        named = loop.target_kind
        loop.target_kind = lambda instruction: OTHER_KIND.get(named(instruction), named(instruction))


def _work(group):
    from opend_mj.evaluation.runner import run_episode_group

    return run_episode_group(group)


def summarise(path: Path, swap: bool = False) -> str:
    """How the fronts read per true kind, and how many handles the planner gives up
    (`Planner.wrong_kind`: path and front read together) with each handle named as it is, or as
    the other kind (``swap``: every give-up is then right)."""
    from opend_mj.policy.planner import Planner, PlannerConfig

    planner = Planner(solver=None, spec=None, config=PlannerConfig())
    counts: collections.Counter = collections.Counter()
    given_up: collections.Counter = collections.Counter()
    for line in open(path):
        r = json.loads(line)
        front = r["front_seen"][0] if r.get("front_seen") else None
        front_kind = planner.kind_from_front(front)
        counts[(r["target_type"], front_kind or "unclear")] += 1
        path_kind = r["kind_seen"][0][0] if r.get("kind_seen") else None
        named = OTHER_KIND.get(r["target_type"], r["target_type"]) if swap else r["target_type"]
        given_up[r["target_type"]] += planner.wrong_kind(named, path_kind, front_kind) is not None
    rows = [f"{path}: {sum(counts.values())} pulls" + (", each handle named as the other kind" if swap else "")]
    for kind in ("drawer", "door"):
        n = sum(v for (k, _), v in counts.items() if k == kind)
        rows.append(f"  {kind}s ({n}): read as " + ", ".join(f"{seen} {counts[(kind, seen)]}"
                                                            for seen in ("drawer", "door", "unclear"))
                    + f"; given up {given_up[kind]}")
    return "\n".join(rows)


def main() -> None:
    from tqdm import tqdm

    from opend_mj.evaluation.jobs import group_jobs, make_jobs

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cabinets", type=Path, required=True)
    ap.add_argument("--split", default="train")
    ap.add_argument("--hand", action="append", default=None)
    ap.add_argument("--swap", action="store_true", help="pull every handle as the other kind")
    ap.add_argument("--limit", type=int, default=None, help="first K targets of the split only")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    jobs = make_jobs(args.cabinets, args.hand or HANDS, "oracle", split=args.split, limit=args.limit)
    done = set()
    if args.out.exists():
        done = {(r["cabinet_dir"], r["joint"], r["hand"]) for r in map(json.loads, open(args.out))}
    jobs = [j for j in jobs if (j.cabinet_dir, j.joint, j.hand) not in done]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    keep = ("cabinet_dir", "joint", "hand", "target_type", "instruction", "success", "kind_seen", "front_seen")
    with mp.get_context("fork").Pool(args.workers, initializer=_init, initargs=(args.swap,)) as pool, \
            open(args.out, "a") as f, tqdm(total=len(jobs), unit="ep", desc="pulls") as bar:
        for records in pool.imap_unordered(_work, group_jobs(jobs)):
            for r in records:
                f.write(json.dumps({k: r.get(k) for k in keep}) + "\n")
            f.flush()
            bar.update(len(records))
    print(summarise(args.out, args.swap))


if __name__ == "__main__":
    main()
