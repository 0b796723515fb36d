"""`opend robustness`: the benchmark under every perturbation axis at both levels, against nominal.

A robustness run is, for each solver or agent, the nominal episodes and the same episodes under
every `sim.perturb` axis at ``mild`` and ``strong`` (each its own ``perturb`` value in the records,
all in one resumable results file per entry: ``<out_dir>/<entry>_<split>.jsonl``). The table gives
each condition's success (open ratio > 20 %) with its 95 % Wilson interval and its difference from
nominal in points, and marks where it falls outside the bands (`Bands`: 5 points mild, 15 strong).
The table holds counts only (no cabinet ids), so a real-cabinet table may be committed.
"""

from __future__ import annotations

import json
from collections import defaultdict
from dataclasses import dataclass, replace
from pathlib import Path

from opend_mj.sim.perturb import AXES, LEVELS


@dataclass(frozen=True)
class Bands:
    """How far (points of success) below nominal a condition may fall and still count as robust."""

    mild: float = 5.0
    strong: float = 15.0

    def limit(self, level: str) -> float:
        return getattr(self, level)


def conditions(axes=AXES) -> list[str | None]:
    """Nominal (None) and every axis at every level, in table order."""
    unknown = [a for a in axes if a not in AXES]
    if unknown:
        raise ValueError(f"unknown perturbation axis {', '.join(map(repr, unknown))}; known: {', '.join(AXES)}")
    return [None] + [f"{a}={lv}" for a in axes for lv in LEVELS]


def robustness_jobs(cabinets_dir: Path, hands, solver: str, split: str = "test", seed: int = 0,
                    limit: int | None = None, axes=AXES, policy: str | None = None, policy_args: tuple = ()):
    """Every episode of a robustness run for one solver (or agent): nominal first, then each
    condition. Checks every perturbed scene first (`jobs.check_perturbed_scenes`): an invalid one
    raises `sim.perturb.PerturbError` before any episode runs."""
    from opend_mj.evaluation.jobs import check_perturbed_scenes, make_jobs

    jobs = []
    for cond in conditions(axes):
        part = make_jobs(cabinets_dir, hands, solver, split=split, seed=seed, limit=limit, perturb=cond)
        if policy is not None:
            part = [replace(j, policy=policy, policy_args=policy_args) for j in part]
        jobs += part
    check_perturbed_scenes(jobs)
    return jobs


def records_path(out_dir: Path, entry: str, split: str) -> Path:
    return Path(out_dir) / f"{entry.replace('/', '_').replace(':', '_')}_{split}.jsonl"


def _ok(r: dict) -> bool:
    from opend_mj.evaluation.scoring import _ok as ok

    return ok(r, 0.2)


def robustness_table(records: list[dict], bands: Bands = Bands(), split: str | None = None) -> dict:
    """Per (solver, hand): nominal and every condition's successes, episodes, rate and 95 % interval,
    and its difference (points) from nominal on the same episodes (cabinet, target, seed: a run cut
    short compares like with like), and whether that stays within the band. ``split``: only its
    records (None: all). Counts only: no cabinet ids."""
    from opend_mj.evaluation.scoring import wilson

    episodes: dict = defaultdict(lambda: defaultdict(dict))
    for r in records:
        if split is not None and r.get("split") != split:
            continue
        key = (r["cabinet"], r["joint"], int(r.get("seed", 0)))
        episodes[(r["solver"], r["hand"])][r.get("perturb") or "nominal"][key] = _ok(r)
    rows = []
    for (solver, hand), conds in sorted(episodes.items()):
        row = {"solver": solver, "hand": hand, "conditions": {}}
        nominal = conds.get("nominal", {})
        for name in ["nominal"] + [c for c in conditions() if c]:
            if name not in conds:
                continue
            oks = conds[name]
            k, n = sum(oks.values()), len(oks)
            lo, hi = wilson(k, n)
            cell = {"successes": k, "episodes": n, "rate": round(100.0 * k / n, 2),
                    "ci95": [round(100 * lo, 2), round(100 * hi, 2)]}
            paired = [key for key in oks if key in nominal]
            if name != "nominal" and paired:
                level = name.split("=")[1]
                base = 100.0 * sum(nominal[key] for key in paired) / len(paired)
                rate = 100.0 * sum(oks[key] for key in paired) / len(paired)
                cell.update(paired_episodes=len(paired), nominal_rate=round(base, 2), delta=round(rate - base, 2),
                            within_band=bool(rate >= base - bands.limit(level)))
            row["conditions"][name] = cell
        rows.append(row)
    return {"bands": {"mild": bands.mild, "strong": bands.strong}, "criterion": "open ratio > 20 %", "rows": rows}


def _cell_text(c: dict | None) -> str:
    if c is None:
        return "-"
    text = f"{c['rate']:.1f} [{c['ci95'][0]:.1f}-{c['ci95'][1]:.1f}] ({c['successes']}/{c['episodes']})"
    if "delta" in c:
        text += f" {c['delta']:+.1f}{'' if c['within_band'] else ' !'}"
    return text


def table_markdown(table: dict, title: str = "Robustness") -> str:
    """One row per (solver, hand, axis): the nominal rate and the mild and strong cells, each
    ``rate [95 % interval] (successes/episodes) points-against-nominal``, ``!`` outside its band."""
    b = table["bands"]
    lines = [f"## {title}", "",
             f"Success (open ratio > 20 %) in percent, [95 % Wilson interval], (successes/episodes), then the "
             f"difference in points from nominal on the same episodes; `!` marks a drop beyond the band "
             f"({b['mild']:g} points mild, {b['strong']:g} strong).", "",
             "| solver / agent | hand | axis | nominal | mild | strong |", "|---|---|---|---|---|---|"]
    for row in table["rows"]:
        nominal = _cell_text(row["conditions"].get("nominal"))
        if set(row["conditions"]) <= {"nominal"}:
            lines.append(f"| {row['solver']} | {row['hand']} | - | {nominal} | - | - |")
        for axis in AXES:
            cells = [row["conditions"].get(f"{axis}={lv}") for lv in LEVELS]
            if all(c is None for c in cells):
                continue
            lines.append(f"| {row['solver']} | {row['hand']} | `{axis}` | {nominal} | "
                         + " | ".join(_cell_text(c) for c in cells) + " |")
    outside = [(row["solver"], row["hand"], name, c["delta"]) for row in table["rows"]
               for name, c in row["conditions"].items() if c.get("within_band") is False]
    lines.append("")
    if outside:
        lines.append("Outside the bands: " + "; ".join(f"{s} / {h} under {n} ({d:+.1f})" for s, h, n, d in outside)
                     + ".")
    else:
        lines.append("Every measured condition is within its band.")
    return "\n".join(lines) + "\n"


def summary_legend(bands: dict) -> str:
    """What the columns of `table_summary_markdown` hold, for the bands (points) of its table."""
    return (f"Success (open ratio > 20 %) in percent, [95 % Wilson interval], (successes/episodes) at nominal; "
            f"the largest drop in points under a mild and a strong level; the conditions beyond their band "
            f"({bands['mild']:g} points mild, {bands['strong']:g} strong).")


def table_summary_markdown(table: dict, title: str = "Robustness", heading: str = "##",
                           legend: bool = True) -> str:
    """One row per (solver, hand): the nominal cell, the largest drop under a mild and under a strong
    level (points against nominal, and where), and the conditions outside their band; the full
    table (`table_markdown`) has every cell. ``legend``: say what the columns hold (a page of
    several tables with the same bands says it once, `summary_legend`)."""
    lines = [f"{heading} {title}", ""] + ([summary_legend(table["bands"]), ""] if legend else []) + [
             "| solver / agent | hand | axes | nominal | worst mild | worst strong | outside the bands |",
             "|---|---|---|---|---|---|---|"]
    for row in table["rows"]:
        conds = row["conditions"]
        axes = sorted({name.split("=")[0] for name in conds if "=" in name}, key=AXES.index)
        worst = []
        for level in LEVELS:
            drops = [(c["delta"], name.split("=")[0]) for name, c in conds.items()
                     if name.endswith(f"={level}") and "delta" in c]
            if drops:
                delta, axis = min(drops)
                worst.append(f"{delta:+.1f} (`{axis}`)")
            else:
                worst.append("-")
        outside = [name for name, c in conds.items() if c.get("within_band") is False]
        lines.append(f"| {row['solver']} | {row['hand']} | {len(axes)} | {_cell_text(conds.get('nominal'))} | "
                     + " | ".join(worst) + f" | {', '.join(f'`{n}`' for n in outside) or 'none'} |")
    return "\n".join(lines) + "\n"


def plot_table(table: dict, path: Path) -> Path:
    """Success per condition against nominal (dashed), one panel per hand, one series per solver or
    agent, with 95 % intervals; the conditions the table measured only."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    measured = {name for r in table["rows"] for name in r["conditions"]}
    names = [n for n in ["nominal"] + [f"{a}={lv}" for a in AXES for lv in LEVELS] if n in measured]
    hands = sorted({r["hand"] for r in table["rows"]})
    solvers = sorted({r["solver"] for r in table["rows"]})
    width = max(7.5, 0.85 * len(names) + 1.5)  # inches: about 0.85 per condition
    fig, axes = plt.subplots(len(hands), 1, figsize=(width, 3.6 * max(1, len(hands))), squeeze=False)
    for ax, hand in zip(axes[:, 0], hands):
        for i, solver in enumerate(solvers):
            row = next((r for r in table["rows"] if r["hand"] == hand and r["solver"] == solver), None)
            if row is None:
                continue
            xs, ys, lo, hi = [], [], [], []
            for j, name in enumerate(names):
                c = row["conditions"].get(name)
                if c is None:
                    continue
                xs.append(j + (i - (len(solvers) - 1) / 2) * 0.12)
                ys.append(c["rate"])
                lo.append(c["rate"] - c["ci95"][0])
                hi.append(c["ci95"][1] - c["rate"])
            line = ax.errorbar(xs, ys, yerr=[lo, hi], fmt="o", capsize=2, label=solver, markersize=4)
            nominal = row["conditions"].get("nominal")
            if nominal:
                ax.axhline(nominal["rate"], color=line[0].get_color(), linestyle="--", linewidth=0.8)
        ax.set_xticks(np.arange(len(names)))
        ax.set_xticklabels([n.replace("=", "\n") for n in names], fontsize=7)
        ax.set_ylim(0, 105)
        ax.set_ylabel("success (%)")
        ax.set_title(f"{hand} (dashed: nominal; bars: 95 % Wilson interval)", fontsize=9)
        ax.grid(axis="y", alpha=0.3)
        ax.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def write_outputs(records: list[dict], out_prefix: Path, title: str = "Robustness", split: str | None = None,
                  bands: Bands = Bands(), label: str = "", command: str = "") -> dict:
    """``<prefix>.md``, ``<prefix>.json`` (counts only) and ``<prefix>.png``; returns the table.
    ``label`` and ``command`` say what was run (the results page quotes them)."""
    out_prefix = Path(out_prefix)
    out_prefix.parent.mkdir(parents=True, exist_ok=True)
    table = robustness_table(records, bands, split)
    table["label"] = label
    table["command"] = command
    out_prefix.with_suffix(".json").write_text(json.dumps(table, indent=1, sort_keys=True) + "\n")
    out_prefix.with_suffix(".md").write_text(table_markdown(table, title))
    plot_table(table, out_prefix.with_suffix(".png"))
    return table


def load_table(path: Path) -> dict:
    """A table written by `write_outputs` (its JSON)."""
    return json.loads(Path(path).read_text())
