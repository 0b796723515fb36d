"""Each target of a compiled dataset pushed open in its room (the build's feasibility check), as a table.

    python tools/feasibility_table.py --cabinets build/opend-train [--floor-contact]

``--floor-contact`` runs the same check with the cabinet's moving parts colliding with the floor (the
scene before `RoomArena.attach_cabinet` excluded that contact), to show what the mechanism changes.
Prints counts per outcome and one line per infeasible target.
"""

from __future__ import annotations

import argparse
import os
from collections import Counter
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cabinets", required=True, type=Path)
    ap.add_argument("--floor-contact", action="store_true")
    args = ap.parse_args()
    from tqdm import tqdm

    from opend_mj.sim import cabinet as cabinet_module
    from opend_mj.sim.feasibility import check_in_room

    if args.floor_contact:
        cabinet_module.Cabinet.moving_bodies = lambda self: []  # no exclusion: moving parts touch the floor
    folders = sorted(p.parent for p in args.cabinets.glob("*/cabinet.json"))
    results = []
    for folder in tqdm(folders, desc="feasibility", unit="cab"):
        results += [(folder.name, r) for r in check_in_room(folder)]
    count = Counter(r.reason or "feasible" for _, r in results)
    print(f"{len(results)} targets of {len(folders)} cabinets"
          f"{' (moving parts collide with the floor)' if args.floor_contact else ''}: "
          + ", ".join(f"{k} {v}" for k, v in sorted(count.items())))
    for cab, r in results:
        if not r.feasible:
            print(f"- {cab} {r.joint} [{r.reason}] {r.message}")


if __name__ == "__main__":
    main()
