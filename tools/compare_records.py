"""Compare two results files episode by episode, wall-clock fields aside.

Episodes are matched by (cabinet, joint, hand, solver, split, seed, light_scale, pull, paraphrase,
instruction); every other field must be equal (floats exactly, unless ``--tolerance``). Prints each
mismatch and a summary; exits 1 when anything differs or is missing.

    python tools/compare_records.py results/oracle_test.jsonl /tmp/new.jsonl
    python tools/compare_records.py a.jsonl b.jsonl --hand allegro   # only allegro's episodes of both
    python tools/compare_records.py a.jsonl b.jsonl --ignore cabinet_dir  # runs given other --cabinets paths
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

#: Fields that depend on the machine and its load, not on the episode.
WALL_CLOCK_FIELDS = ("wall_seconds",)
#: Fields that name an episode.
KEY_FIELDS = ("cabinet", "joint", "hand", "solver", "split", "seed", "light_scale", "pull", "paraphrase",
              "instruction")


def load(path: Path, hands: set[str] | None = None) -> dict[tuple, dict]:
    """The records of ``path`` by episode key (a clear error for a bad line or a repeated key)."""
    out: dict[tuple, dict] = {}
    for n, line in enumerate(Path(path).read_text().splitlines(), 1):
        if not line.strip():
            continue
        try:
            rec = json.loads(line)
        except json.JSONDecodeError as exc:
            raise SystemExit(f"{path}:{n}: not a JSON line: {exc}") from exc
        if hands and rec.get("hand") not in hands:
            continue
        key = tuple(rec.get(k) for k in KEY_FIELDS)
        if key in out:
            raise SystemExit(f"{path}:{n}: episode {key} appears twice")
        out[key] = rec
    return out


def differences(a, b, tolerance: float = 0.0, path: str = "", ignore: tuple = WALL_CLOCK_FIELDS) -> list[str]:
    """Where ``a`` and ``b`` differ, as "path: a != b" lines (nested dicts and lists walked; the
    top-level fields in ``ignore`` skipped)."""
    if isinstance(a, dict) and isinstance(b, dict):
        out = []
        for k in sorted(set(a) | set(b), key=str):
            if path == "" and k in ignore:
                continue
            if k not in a or k not in b:
                out.append(f"{path}{k}: {'missing' if k not in a else a[k]!r} != {'missing' if k not in b else b[k]!r}")
                continue
            out += differences(a[k], b[k], tolerance, f"{path}{k}.", ignore)
        return out
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return [f"{path[:-1]}: {len(a)} items != {len(b)} items ({a!r} != {b!r})"]
        out = []
        for i, (x, y) in enumerate(zip(a, b)):
            out += differences(x, y, tolerance, f"{path}{i}.")
        return out
    if isinstance(a, float) and isinstance(b, float) and tolerance > 0:
        if (math.isnan(a) and math.isnan(b)) or abs(a - b) <= tolerance:
            return []
    elif a == b or (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b)):
        return []
    return [f"{path[:-1]}: {a!r} != {b!r}"]


def compare(a_path: Path, b_path: Path, hands: set[str] | None = None, tolerance: float = 0.0,
            limit: int = 20, ignore: tuple = ()) -> tuple[int, list[str]]:
    """(number of episodes that differ or are missing, report lines); ``ignore``: top-level fields
    not compared beside the wall-clock ones."""
    a, b = load(a_path, hands), load(b_path, hands)
    ignore = WALL_CLOCK_FIELDS + tuple(ignore)
    lines, bad = [], 0
    for key in sorted(set(a) | set(b), key=str):
        name = "/".join(str(k) for k in key[:4])
        if key not in a or key not in b:
            bad += 1
            lines.append(f"{name}: only in {a_path if key in a else b_path}")
            continue
        diff = differences(a[key], b[key], tolerance, ignore=ignore)
        if diff:
            bad += 1
            lines.append(f"{name}: {len(diff)} fields differ")
            lines += [f"    {d}" for d in diff[:limit]]
    same = len(set(a) & set(b)) - sum(1 for k in set(a) & set(b) if differences(a[k], b[k], tolerance, ignore=ignore))
    lines.append(f"{len(a)} episodes in {a_path}, {len(b)} in {b_path}: {same} identical "
                 f"(aside from {', '.join(ignore)}), {bad} differ or are missing")
    return bad, lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("a", type=Path)
    ap.add_argument("b", type=Path)
    ap.add_argument("--hand", action="append", default=None, help="compare only this hand's episodes")
    ap.add_argument("--tolerance", type=float, default=0.0, help="largest difference between equal floats")
    ap.add_argument("--limit", type=int, default=20, help="fields shown per differing episode")
    ap.add_argument("--ignore", action="append", default=[], metavar="FIELD",
                    help="also skip this top-level field (e.g. cabinet_dir where --cabinets differed)")
    args = ap.parse_args(argv)
    bad, lines = compare(args.a, args.b, set(args.hand) if args.hand else None, args.tolerance, args.limit,
                         tuple(args.ignore))
    print("\n".join(lines))
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
