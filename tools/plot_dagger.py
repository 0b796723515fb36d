"""Plot validation success against DAgger rounds, per hand, from the kept rounds of `opend train-policy --dagger`.

    python tools/plot_dagger.py --out docs/dagger.png            # checkpoints/bc_rounds/<hand>/round_<i>.json

Each kept round's figures (``round_<i>.json`` in ``--rounds DIR/<hand>``) give its validation
success on the training cabinets kept apart, overall and per kind; the plot has one panel per hand:
overall (solid), drawers and doors (dashed, dotted), each overall point labelled with the labelled
rollouts it trained on, and a square around the rounds that revisited their failed targets. Where the shipped policy's generated test-split record exists
(``results/bc/<hand>_shipped_test.jsonl``), its success is a star after the last round. The figure
shows where more rounds stop helping.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=Path, default=Path("checkpoints/bc_rounds"),
                        help="folder with one subfolder of kept rounds per hand")
    parser.add_argument("--tests", type=Path, default=Path("results/bc"),
                        help="folder of the shipped policies' test records (<hand>_shipped_test.jsonl)")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)

    import matplotlib

    from opend_mj.apps.dagger import kept_rounds

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    hands = {d.name: kept_rounds(d) for d in sorted(args.rounds.iterdir()) if d.is_dir()} if args.rounds.is_dir() else {}
    hands = {h: r for h, r in hands.items() if r}
    if not hands:
        parser.error(f"{args.rounds}: no kept rounds (round_<i>.json under <hand>/)")
    fig, axes = plt.subplots(1, len(hands), figsize=(max(6.0, 3.6 * len(hands)), 3.8), squeeze=False, sharey=True)
    for ax, (hand, rounds) in zip(axes[0], hands.items()):
        x = [r["round"] for r in rounds]
        line, = ax.plot(x, [r["val_success"] for r in rounds], marker="o", label="validation")
        for key, style in (("val_drawer", "--"), ("val_door", ":")):
            ax.plot(x, [r.get(key) for r in rounds], linestyle=style, color=line.get_color(), alpha=0.7,
                    label=key.split("_")[1] + "s")
        revisited = [r for r in rounds if r.get("revisit")]
        if revisited:  # rounds that also rolled out their failed targets again (`--revisit`)
            ax.plot([r["round"] for r in revisited], [r["val_success"] for r in revisited], marker="s",
                    markersize=8, markerfacecolor="none", color=line.get_color(), linestyle="none",
                    label="with revisits")
        for r in rounds:
            ax.annotate(str(r["rollouts"]), (r["round"], r["val_success"]), textcoords="offset points",
                        xytext=(0, 7), ha="center", fontsize=7)
        test = args.tests / f"{hand}_shipped_test.jsonl"
        if test.is_file():
            records = [json.loads(line) for line in test.read_text().splitlines() if line.strip()]
            rate = 100.0 * sum(bool(r.get("success")) for r in records) / max(1, len(records))
            ax.plot([x[-1] + 0.3], [rate], marker="*", markersize=11, color="k", linestyle="none",
                    label=f"shipped, test split ({len(records)})")
        ax.set_title(f"{hand} ({rounds[0]['val_episodes']} validation episodes)", fontsize=9)
        ax.set_xlabel("DAgger round (labels: rollouts trained on)", fontsize=8)
        ax.set_xticks(x)
        ax.set_ylim(0, 100)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="lower right")
    axes[0][0].set_ylabel("opened (> 20 %), %")
    fig.suptitle("Behaviour cloning with DAgger (the planner as expert), generated cabinets", fontsize=10)
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=120)
    print(f"{', '.join(f'{h}: {len(r)} rounds' for h, r in hands.items())} -> {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
