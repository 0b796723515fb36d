"""How much data is enough: success of behaviour-cloning policies against their number of demonstrations.

Reads `opend run --policy bc` results files, one per policy, each named with the number of
demonstrations it was trained on, and draws success (overall, drawers, doors; with 95 % Wilson
intervals) against that number, one line per hand, with the planner's success on the same episodes
as a reference where given. Prints the table as Markdown.

    python tools/bc_data_scale.py --run 50=build/bc/allegro_n50_test.jsonl --run 200=... \
        [--planner results/fasterrcnn_test.jsonl] --out build/bc_data_scale.png
"""

from __future__ import annotations

import argparse
import math
from collections import defaultdict
from pathlib import Path


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    if n == 0:
        return 0.0, 0.0
    p = k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return c - h, c + h


def rates(records: list[dict]) -> dict[str, tuple[int, int]]:
    out = {}
    for kind in ("overall", "drawer", "door"):
        sel = [r for r in records if kind == "overall" or r.get("target_type") == kind]
        out[kind] = (sum(bool(r.get("success")) and "error" not in r for r in sel), len(sel))
    return out


def main(argv=None) -> None:
    from opend_mj.evaluation.results import load_results

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--run", action="append", required=True, metavar="[SERIES:]N=RESULTS",
                    help="number of training demonstrations = results file of that policy (repeatable)")
    ap.add_argument("--planner", action="append", default=[], metavar="RESULTS",
                    help="the planner's results on the same episodes (a reference line per hand)")
    ap.add_argument("--out", type=Path, default=Path("build/bc_data_scale.png"))
    ap.add_argument("--title", default="Behaviour cloning: success against demonstrations")
    args = ap.parse_args(argv)

    by_hand: dict[tuple[str, str], list[tuple[int, dict]]] = defaultdict(list)
    for item in args.run:
        head, sep, path = item.partition("=")
        series, _, n = head.rpartition(":")
        if not sep or not n.strip().isdigit():
            ap.error(f"--run {item!r}: expected N=RESULTS")
        records = load_results(Path(path), repair=False)
        if not records:
            ap.error(f"{path}: no records")
        hands = {r["hand"] for r in records}
        if len(hands) != 1:
            ap.error(f"{path}: records of several hands {sorted(hands)}")
        by_hand[(hands.pop(), series.strip())].append((int(n), rates(records)))
    planner = {}
    for path in args.planner:
        records = load_results(Path(path), repair=False)
        for hand in {r["hand"] for r in records}:
            planner[hand] = rates([r for r in records if r["hand"] == hand])

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    print("| hand | series | demos | overall | drawers | doors |\n|---|---|---|---|---|---|")
    styles = {"overall": ("-o", 2.0), "drawer": ("--s", 0.8), "door": (":^", 0.8)}
    planner_drawn = set()
    for i, ((hand, series), rows) in enumerate(sorted(by_hand.items())):
        rows.sort()
        ns = [n for n, _ in rows]
        colour = f"C{i}"
        name = f"{hand} {series}".strip()
        for kind, (style, width) in styles.items():
            ks = [r[kind] for _, r in rows]
            p = [100 * k / n if n else 0 for k, n in ks]
            ax.plot(ns, p, style, color=colour, lw=width, ms=6 if kind == "overall" else 4,
                    label=f"{name}: {kind}")
            if kind == "overall":
                lo = [100 * wilson(k, n)[0] for k, n in ks]
                hi = [100 * wilson(k, n)[1] for k, n in ks]
                ax.fill_between(ns, lo, hi, alpha=0.12, color=colour)
        for n, r in rows:
            cells = " | ".join(f"{100 * k / m:.1f} % ({k}/{m})" if m else "-" for k, m in r.values())
            print(f"| {hand} | {series or '-'} | {n} | {cells} |")
        if hand in planner and hand not in planner_drawn:
            planner_drawn.add(hand)
            k, m = planner[hand]["overall"]
            ax.axhline(100 * k / m, color="grey", lw=1, ls="-.", label=f"{hand} planner (same solver)")
            print(f"| {hand} | planner | | " + " | ".join(f"{100 * k / m:.1f} % ({k}/{m})" if m else "-"
                                                       for k, m in planner[hand].values()) + " |")
    ax.set_xscale("log")
    from matplotlib.ticker import NullFormatter

    ticks = sorted({n for rows in by_hand.values() for n, _ in rows})
    ax.set_xticks(ticks, [str(n) for n in ticks], rotation=60, fontsize=7)  # close counts stay legible
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel("successful planner demonstrations used for training")
    ax.set_ylabel("success on the test split (%)")
    ax.set_ylim(0, 100)
    ax.grid(alpha=0.3)
    ax.set_title(args.title, fontsize=10)
    ax.legend(fontsize=6, loc="upper left", bbox_to_anchor=(0.0, 0.95))
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=120)
    print(f"-> {args.out}")


if __name__ == "__main__":
    main()
