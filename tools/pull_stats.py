"""How far the planner opens what it opens: per hand, success at the paper's criterion (open ratio
> 20 %) and at ManiSkill3's (the joint at >= 75 % of its range), per part kind, and where pulls
ended; with a second results file, the episodes each criterion won and lost between the two.

    python tools/pull_stats.py results/oracle_real.jsonl
    python tools/pull_stats.py before.jsonl after.jsonl [--targets 270]

``--targets N``: score over N targets per hand (targets a build excluded count as failures, so the
figures stay comparable with a build that kept them). Records without ``range_ratio`` (error
records) count as failures. ``pull_end`` (where each pull of an episode ended: ``stall``, ``travel``,
``turn``, ``back_stop``, ``time``, ``slipped``, ...) is counted where the records carry it.
"""

from __future__ import annotations

import argparse
import collections
import json
import sys
from pathlib import Path

from opend_mj.sim.hands import list_hands
#: the two criteria: the paper's open ratio > 20 %, ManiSkill3's >= 75 % of the joint range
CRITERIA = (("open_ratio", 0.2, "> 20 %"), ("range_ratio", 0.75, ">= 75 % of range"))


def in_order(hands) -> list[str]:
    """``hands`` in the registry's order, unknown ones after it by name."""
    known = list_hands()
    return [h for h in known if h in hands] + sorted(set(hands) - set(known))


def load(path: Path) -> dict[tuple, dict]:
    """Records by (cabinet, joint, hand, seed); a line that is not JSON is a clear error."""
    out = {}
    for i, line in enumerate(Path(path).read_text().splitlines(), 1):
        if not line.strip():
            continue
        try:
            r = json.loads(line)
        except json.JSONDecodeError as exc:
            sys.exit(f"{path}:{i}: not a JSON line ({exc})")
        out[(r["cabinet"], r["joint"], r["hand"], r.get("seed", 0))] = r
    return out


def passes(r: dict, field: str, threshold: float) -> bool:
    v = r.get(field)
    if v is None:
        return False
    return v >= threshold if field == "range_ratio" else v > threshold


def table(records: dict[tuple, dict], targets: int | None = None) -> list[str]:
    """One line per hand: both criteria overall and per kind."""
    lines = []
    by_hand = collections.defaultdict(list)
    for r in records.values():
        by_hand[r["hand"]].append(r)
    for hand in in_order(by_hand):
        rs = by_hand[hand]
        n = targets or len(rs)
        cells = []
        for field, thr, name in CRITERIA:
            ok = sum(passes(r, field, thr) for r in rs)
            kinds = []
            for kind in ("drawer", "door"):
                k = [r for r in rs if r.get("target_type") == kind]
                kinds.append(f"{kind}s {sum(passes(r, field, thr) for r in k)}/{len(k)}")
            cells.append(f"{name}: {100 * ok / n:5.1f} % ({ok}/{n}; {', '.join(kinds)})")
        ends = collections.Counter(e for r in rs for e in (r.get("pull_end") or []))
        line = f"{hand:9s} " + " | ".join(cells)
        if ends:
            line += " | pulls ended: " + ", ".join(f"{k} {v}" for k, v in ends.most_common())
        lines.append(line)
    return lines


def changes(before: dict, after: dict) -> list[str]:
    """Per hand and criterion: episodes won and lost (in both files), with the lost ones named."""
    lines = []
    common = sorted(set(before) & set(after))
    for hand in in_order({k[2] for k in common}):
        keys = [k for k in common if k[2] == hand]
        if not keys:
            continue
        for field, thr, name in CRITERIA:
            won = [k for k in keys if passes(after[k], field, thr) and not passes(before[k], field, thr)]
            lost = [k for k in keys if passes(before[k], field, thr) and not passes(after[k], field, thr)]
            named = ", ".join(f"{k[0]} {k[1]}" for k in lost)
            lines.append(f"{hand:9s} {name:17s} won {len(won):3d}  lost {len(lost):3d}" + (f"  ({named})" if lost else ""))
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("results", nargs="+", type=Path, help="one results file, or before and after")
    ap.add_argument("--targets", type=int, default=None, help="score over this many targets per hand")
    args = ap.parse_args(argv)
    if len(args.results) > 2:
        ap.error("give one results file, or two (before, after)")
    for path in args.results:
        if not path.is_file():
            ap.error(f"{path}: no such results file")
    runs = [load(p) for p in args.results]
    for path, recs in zip(args.results, runs):
        print(f"## {path} ({len(recs)} episodes)")
        print("\n".join(table(recs, args.targets)))
    if len(runs) == 2:
        print("## won / lost, episodes in both files")
        print("\n".join(changes(*runs)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
