"""What an instruction file costs end to end, from the targets the parser does not read as their template.

A phrasing read as its target's template gives exactly the template's episode (solvers and planner
see the same canonical instruction), so a reworded run differs from the template run only at the
targets whose phrasing is refused or misread. This runs those targets' episodes both ways (template
and reworded) and prints, per solver and hand, the template successes lost in points of the split's
targets, without running the whole split twice.

    python tools/language_gap.py --cabinets build/opend-train --split all \
        --instruction-file tests/data/instruction_corpus.csv --solver fasterrcnn --solver cliport --out build/gap
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

from opend_mj.evaluation.jobs import make_jobs
from opend_mj.evaluation.phrasings import assign_phrasings, load_instruction_file
from opend_mj.evaluation.pool import run_jobs
from opend_mj.language import InstructionNotUnderstood, canonical_instruction
from opend_mj.sim.hands import list_hands


def not_as_template(jobs) -> list:
    """The jobs whose phrasing the parser refuses or reads as another template."""
    out = []
    for job in jobs:
        try:
            if canonical_instruction(job.phrasing) == job.instruction:
                continue
        except InstructionNotUnderstood:
            pass
        out.append(job)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cabinets", type=Path, required=True)
    ap.add_argument("--split", default="test", choices=("train", "test", "all"))
    ap.add_argument("--instruction-file", type=Path, required=True)
    ap.add_argument("--solver", action="append", required=True)
    ap.add_argument("--hand", action="append", default=None)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--out", type=Path, required=True, help="folder for the results files")
    args = ap.parse_args()
    hands = args.hand or list_hands()
    spec = load_instruction_file(args.instruction_file)
    args.out.mkdir(parents=True, exist_ok=True)
    for solver in args.solver:
        worded = not_as_template(assign_phrasings(make_jobs(args.cabinets, hands, solver, split=args.split), spec))
        plain = [replace(j, phrasing=None) for j in worded]
        n_targets = len({(j.cabinet, j.joint) for j in make_jobs(args.cabinets, hands[:1], solver, split=args.split)})
        print(f"{solver}: {len({(j.cabinet, j.joint) for j in worded})} of {n_targets} targets not read as "
              f"their template; {len(worded)} episodes each way", flush=True)
        if not worded:
            print("  no episode to run: the reworded run is the template run")
            continue
        paths = {k: args.out / f"{solver}_{args.split}_{k}.jsonl" for k in ("templates", "reworded")}
        run_jobs(plain, paths["templates"], workers=args.workers)
        run_jobs(worded, paths["reworded"], workers=args.workers)
        recs = {k: [json.loads(line) for line in p.read_text().splitlines() if line.strip()] for k, p in paths.items()}
        for hand in hands:
            won = {k: sum(bool(r["success"]) for r in v if r["hand"] == hand) for k, v in recs.items()}
            lost = won["templates"] - won["reworded"]
            print(f"  {hand}: templates open {won['templates']}, rewordings {won['reworded']} -> "
                  f"{100 * lost / n_targets:.1f} points of {n_targets} targets")


if __name__ == "__main__":
    main()
