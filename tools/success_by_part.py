"""Success of `opend run` records per part geometry: drawers, flaps (doors hinged about a horizontal
axis), and side-hinged doors by how far (m) the handle stands from the hinge line.

    python tools/success_by_part.py RECORDS.jsonl[@CABINETS] [RECORDS.jsonl[@CABINETS] ...] [--wide 0.5]

Each records file is read with the compiled cabinets it ran on (``@CABINETS``; default: the record's
own ``cabinet_dir``), whose ``cabinet.json`` gives each target's hinge axis, anchor and handle centre.
Prints one markdown row per file: successes / episodes per class. Wide doors (the handle ``--wide`` m
or more from the hinge) are where generated and real cabinets differ most (docs/cabinets.md).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

CLASSES = ("drawer", "flap", "door", "wide door")


def part_class(target: dict, wide: float) -> str:
    """The class of one target of a ``cabinet.json``: drawer, flap, door or wide door."""
    if target["type"] != "door":
        return "drawer"
    if abs(target["axis"][2]) < 0.5:
        return "flap"
    (hx, hy), (ax, ay) = target["handle"]["center"][:2], target["anchor"][:2]
    return "wide door" if math.hypot(hx - ax, hy - ay) >= wide else "door"


def tally(records: Path, cabinets: Path | None, wide: float) -> dict[str, list[int]]:
    """{class: [successes, episodes]} over the records of ``records`` (read, never repaired)."""
    from opend_mj.evaluation.results import load_results
    from opend_mj.sim.cabinet import load_cabinet_info

    if not Path(records).is_file():
        raise SystemExit(f"{records}: no such records file")
    counts = {c: [0, 0] for c in CLASSES}
    infos: dict[Path, dict] = {}
    for r in load_results(records, repair=False):
        folder = (cabinets / r["cabinet"]) if cabinets else Path(r["cabinet_dir"])
        if folder not in infos:
            infos[folder] = load_cabinet_info(folder)
        target = next(t for t in infos[folder]["targets"] if t["joint"] == r["joint"])
        cell = counts[part_class(target, wide)]
        cell[0] += bool(r.get("success"))
        cell[1] += 1
    return counts


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("records", nargs="+", help="RECORDS.jsonl[@CABINETS]")
    parser.add_argument("--wide", type=float, default=0.5, help="a door is wide from this handle-to-hinge distance (m)")
    args = parser.parse_args(argv)
    print("| records | " + " | ".join(CLASSES) + " | all |")
    print("|---|" + "---|" * (len(CLASSES) + 1))
    for item in args.records:
        path, _, cabinets = item.partition("@")
        counts = tally(Path(path), Path(cabinets) if cabinets else None, args.wide)
        done, total = sum(c[0] for c in counts.values()), sum(c[1] for c in counts.values())
        print(f"| {path} | " + " | ".join(f"{k}/{n}" for k, n in counts.values()) + f" | {done}/{total} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
