"""Plot success against DAgger rounds and training data, per hand, from `opend train-policy --dagger` summaries.

    python tools/plot_dagger.py build/bc/allegro/dagger/dagger.json build/bc/franka/dagger/dagger.json \
        --test allegro=build/bc/allegro/test.jsonl --out docs/dagger.png

Each summary (``dagger.json`` in a run's ``--dagger-dir``) gives, per round, the validation success
(training cabinets kept apart) and the data it trained on (demonstrations and labelled rollouts);
the plot has one line per hand, validation success against the round, each point labelled with its
demonstrations + rollouts. ``--test HAND=records.jsonl`` adds the final policy's success on the
generated test split as a marker after the last round.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("summaries", nargs="+", type=Path)
    parser.add_argument("--test", action="append", default=[], metavar="HAND=RECORDS",
                        help="the final policy's records on the test split (repeatable)")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tests = {}
    for item in args.test:
        hand, _, path = item.partition("=")
        records = [json.loads(line) for line in Path(path).read_text().splitlines() if line.strip()]
        tests[hand] = 100.0 * sum(bool(r.get("success")) for r in records) / max(1, len(records))
    fig, ax = plt.subplots(figsize=(7, 4.2))
    for path in args.summaries:
        summary = json.loads(path.read_text())
        rounds = summary["rounds"]
        x = [r["round"] for r in rounds]
        y = [r["val_success"] for r in rounds]
        line, = ax.plot(x, y, marker="o", label=f"{summary['hand']} (validation, {rounds[0]['val_episodes']} episodes)")
        for r in rounds:
            ax.annotate(f"{r['demos']}+{r['rollouts']}", (r["round"], r["val_success"]), textcoords="offset points",
                        xytext=(0, 7), ha="center", fontsize=7)
        if summary["hand"] in tests:
            ax.plot([x[-1] + 0.15], [tests[summary["hand"]]], marker="*", markersize=11, color=line.get_color(),
                    linestyle="none", label=f"{summary['hand']} (test split, final policy)")
    ax.set_xlabel("DAgger round (0: demonstrations only); labels: demonstrations + labelled rollouts")
    ax.set_ylabel("opened (> 20 %), %")
    ax.set_ylim(0, 100)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="lower right")
    ax.set_xticks(sorted({r["round"] for p in args.summaries for r in json.loads(p.read_text())["rounds"]}))
    ax.set_title("BC with DAgger (the planner as expert), generated cabinets", fontsize=10)
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=120)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
