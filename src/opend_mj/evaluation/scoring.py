"""`opend score`: the paper's tables from results files.

Success is recomputed from ``open_ratio`` at thresholds 20 / 50 / 90 % (20 % is the benchmark's, the
paper's), and from the fraction of the joint range opened at 75 % (ManiSkill3's criterion for its
OpenCabinet tasks: ``range_ratio``, or the record's raw ``joint_value`` and ``joint_range``; a record
with neither, written before they were recorded, shows n/a). Error records (``"error"`` in the line)
count as failures at stage ``error``. When several files hold the same episode key, the last one wins
(an agent's episode run ``--agent-in-process`` is an entry of its own: `entry_name`).

Files compared with each other should hold the same episodes: `episode_set_warnings` names each pair
that does not (an episode here is its key without the solver or agent: `task_key`), and
`merge_runs` with ``common`` keeps only the episodes every file holds (`opend score --common`).
"""

from __future__ import annotations

import csv
from collections import Counter, defaultdict
from pathlib import Path
from typing import Iterable

THRESHOLDS = (0.2, 0.5, 0.9)
#: ManiSkill3's success criterion: the target joint at or beyond this fraction of its range.
RANGE_THRESHOLD = 0.75
SPLITS = ("train", "test")
KINDS = ("drawer", "door", "overall")
STAGE_ORDER = ("language", "locate", "approach", "grasp", "pull", "physics", "error")
#: Why the top tier is empty on the generated cabinets, even with oracle boxes (the generator's joint limits).
TOP_TIER_NOTE = ("Few parts can pass 90 %: a part stops at its joint limit. The generated cabinets' drawers travel "
                 "70-90 % of their length (85 % the most any record shows) and their doors turn 90-115 degrees "
                 "(64 % of 180 at most), so on them this tier is 0 for every run.")


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """The Wilson score interval of a success rate of ``k`` in ``n`` (95 % for z = 1.96), as
    fractions; (0, 1) for no episodes. Unlike the normal approximation it stays inside [0, 1] and
    is not empty at 0 or n successes."""
    if n <= 0:
        return 0.0, 1.0
    p = k / n
    den = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z * ((p * (1 - p) / n + z * z / (4 * n * n)) ** 0.5) / den
    return max(0.0, centre - half), min(1.0, centre + half)


def interval_text(k: int, n: int) -> str:
    """``[lo-hi]``: the 95 % Wilson interval in percent (one decimal)."""
    lo, hi = wilson(k, n)
    return f"[{100 * lo:.1f}-{100 * hi:.1f}]"


def intervals_overlap(a: tuple[int, int], b: tuple[int, int]) -> bool:
    """Whether the 95 % Wilson intervals of two (successes, episodes) overlap (their difference is
    then not clear at that level)."""
    (alo, ahi), (blo, bhi) = wilson(*a), wilson(*b)
    return alo <= bhi and blo <= ahi


def load_records(paths: Iterable[Path]) -> list[dict]:
    """Every record of the files, the last file's winning where several hold one episode key."""
    return merge_runs(load_runs(paths))


def task_key(record: dict) -> tuple:
    """An episode's identity across runs: its `episode_key` without the solver or agent that ran it
    (cabinet, target joint, hand, seed, light scale, pull, wording, physics step, perturbation)."""
    from opend_mj.evaluation.episode import EPISODE_FIELDS

    return tuple(f.normalise(f.value(record)) for f in EPISODE_FIELDS if f.in_key and f.name != "solver")


def load_runs(paths: Iterable[Path]) -> list[tuple[Path, list[dict]]]:
    """Each results file with its records, in the order given."""
    from opend_mj.evaluation.results import load_results

    return [(Path(p), load_results(Path(p), repair=False)) for p in paths]


def episode_set_warnings(runs: list[tuple[Path, list[dict]]]) -> list[str]:
    """One line per pair of files whose episode sets (`task_key`) differ, with their counts."""
    sets = [(path, {task_key(r) for r in records}) for path, records in runs]
    lines = []
    for i, (a, sa) in enumerate(sets):
        for b, sb in sets[i + 1:]:
            if sa != sb:
                lines.append(f"{a} holds {len(sa)} episodes and {b} {len(sb)}, {len(sa & sb)} of them in both: "
                             f"their rates are over different episodes (--common scores only those every file holds)")
    return lines


def merge_runs(runs: list[tuple[Path, list[dict]]], common: bool = False) -> list[dict]:
    """The records of several files, the last file's winning where several hold one episode key;
    with ``common``, only those of the episodes (`task_key`) that every file holds."""
    from opend_mj.evaluation.episode import episode_key

    shared = None
    if common:
        for _, records in runs:
            keys = {task_key(r) for r in records}
            shared = keys if shared is None else shared & keys
    merged: dict[tuple, dict] = {}
    for _, records in runs:
        for r in records:
            if shared is None or task_key(r) in shared:
                # an in-process agent's episode never replaces one run apart
                merged[(*episode_key(r), r.get("agent_isolation") == "in-process")] = r
    return list(merged.values())


def _ok(r: dict, threshold: float) -> bool:
    return "error" not in r and float(r.get("open_ratio") or 0.0) > threshold


def range_fraction(r: dict) -> float | None:
    """Fraction of its joint range the target was opened (0 for an error or a diverged episode);
    None when the record says neither ``range_ratio`` nor ``joint_value`` with ``joint_range``."""
    if "error" in r:
        return 0.0
    if r.get("range_ratio") is not None:
        return float(r["range_ratio"])
    q, span = r.get("joint_value"), r.get("joint_range")
    if q is not None and span:
        lo, hi = float(span[0]), float(span[1])
        closed = float(r["closed_value"]) if r.get("closed_value") is not None else min(max(0.0, lo), hi)
        sign = 1.0 if closed - lo <= hi - closed else -1.0
        return max(0.0, (float(q) - closed) * sign) / max(hi - lo, 1e-9)
    if r.get("open_ratio") is None and not r.get("success"):
        return 0.0  # a failed episode that recorded no joint at all (physics diverged)
    return None


def _ok_range(r: dict, threshold: float = RANGE_THRESHOLD) -> bool | None:
    f = range_fraction(r)
    return None if f is None else f >= threshold


def _kind(r: dict) -> str | None:
    """door / drawer; None for a record that says neither (it counts in "overall" only)."""
    if r.get("target_type"):
        return r["target_type"]
    instruction = str(r.get("instruction", "")).strip()
    if not instruction:
        return None
    from opend_mj.language import InstructionNotUnderstood, target_kind

    try:
        return target_kind(instruction)
    except InstructionNotUnderstood:
        return None


def entry_name(r: dict) -> str:
    """The solver / agent column of a record: its solver, with its perturbation where it has one
    (``oracle [light=strong]``), so perturbed and nominal runs never pool; an agent that ran in the
    simulator's process (``--agent-in-process``, where it could reach the scene) is marked
    ``(agent in-process)`` and never pools with the same agent run apart."""
    name = f"{r['solver']} [{r['perturb']}]" if r.get("perturb") else r["solver"]
    return f"{name} (agent in-process)" if r.get("agent_isolation") == "in-process" else name


def containment_lines(records: list[dict]) -> list[str]:
    """A table section: how the agents were run, per (hand, agent): the isolation, the opend-mj
    versions, the sha256 of the agent's source and the agent process's memory limit, as their records
    say ("not recorded" for records written before agents ran apart). Empty without agent records."""
    rows = []
    for (hand, name), recs in groups(records).items():
        agents = [r for r in recs if r.get("policy") or r.get("agent_isolation")]
        if not agents:
            continue

        def values(field: str, fmt=str) -> str:
            seen = sorted({fmt(r[field]) if r.get(field) is not None else "not recorded" for r in agents})
            return ", ".join(seen)

        memory = values("agent_memory", lambda b: f"{int(b) / (1 << 30):.3g} GiB")
        rows.append(f"| {hand} | {name} | {len(agents)} | {values('agent_isolation')} | {values('opend_version')} | "
                    f"{values('agent_sha256', lambda h: str(h)[:12])} | {memory} |")
    if not rows:
        return []
    return ["## How agents were run", "",
            "process: the agent ran in a process of its own, holding no simulator (observation in, action out); "
            "in-process: beside the simulator (`--agent-in-process`, for debugging), where it can reach the scene "
            "and its figures are not the benchmark's. sha256: the first 12 digits of the agent's source file's.", "",
            "| hand | solver / agent | episodes | agent isolation | opend-mj | agent sha256 | memory limit |",
            "|---|---|---|---|---|---|---|", *rows, ""]


def groups(records: list[dict]) -> dict[tuple[str, str], list[dict]]:
    out: dict[tuple[str, str], list[dict]] = defaultdict(list)
    for r in records:
        out[(r["hand"], entry_name(r))].append(r)
    return dict(sorted(out.items()))


def success_table(records: list[dict], threshold: float = 0.2, measure: str = "open") -> list[dict]:
    """Rows (hand, solver) x columns (split, kind): success rate, successes, episodes.

    ``measure``: ``"open"`` (open ratio > threshold, the paper's) or ``"range"`` (fraction of the joint
    range >= threshold, ManiSkill3's). A cell with an episode whose range is unknown has rate None."""
    if measure not in ("open", "range"):
        raise ValueError(f"measure must be 'open' or 'range', not {measure!r}")
    rows = []
    for (hand, solver), recs in groups(records).items():
        row = {"hand": hand, "solver": solver, "threshold": threshold, "measure": measure}
        for split in SPLITS:
            for kind in KINDS:
                sel = [r for r in recs if r.get("split") == split and (kind == "overall" or _kind(r) == kind)]
                n = len(sel)
                if measure == "open":
                    oks = [_ok(r, threshold) for r in sel]
                else:
                    oks = [_ok_range(r, threshold) for r in sel]
                k = sum(bool(o) for o in oks)
                row[f"{split}_{kind}"] = (k / n if n and None not in oks else None, k, n)
        rows.append(row)
    return rows


def _fmt(cell) -> str:
    """``rate (k/n) [lo-hi]``: percent, counts and the 95 % Wilson interval."""
    rate, k, n = cell
    if not n:
        return "-"
    return "n/a" if rate is None else f"{100 * rate:.1f} ({k}/{n}) {interval_text(k, n)}"


def ranking(records: list[dict], threshold: float = 0.2) -> list[dict]:
    """Agents and solvers ranked: (hand, solver) rows by test success, then train success (20 %).

    One row per (hand, solver) with its success rates, episode counts and how many episodes opened
    a wrong target; ties keep the name order.
    """
    rows = []
    full = {(r["hand"], r["solver"]): r for r in success_table(records, RANGE_THRESHOLD, "range")}
    for row in success_table(records, threshold):
        recs = groups(records)[(row["hand"], row["solver"])]
        wide = full[(row["hand"], row["solver"])]
        rows.append({**row, "episodes": len(recs), "wrong_targets": sum(bool(r.get("others_moved")) for r in recs),
                     "test_overall_range": wide["test_overall"], "train_overall_range": wide["train_overall"]})

    def rate(cell):
        return -1.0 if cell[0] is None else cell[0]

    rows.sort(key=lambda r: (-rate(r["test_overall"]), -rate(r["train_overall"])))
    for i, r in enumerate(rows, 1):
        r["rank"] = i
    for r in rows:  # which other entries' 95 % intervals overlap this one's (same split as ranked)
        split = "test_overall" if r["test_overall"][2] else "train_overall"
        r["overlaps"] = [o["rank"] for o in rows if o is not r and o[split][2] and r[split][2]
                         and intervals_overlap(r[split][1:], o[split][1:])]
    return rows


def overlap_note(row: dict) -> str:
    """The ranking's note: which ranks a row's 95 % interval overlaps (not clearly different)."""
    if not row.get("overlaps"):
        return "clear of all others"
    return "overlaps " + ", ".join(f"#{k}" for k in row["overlaps"])


def _episodes_with(records: list[dict], field: str, title: str, column: str, only_with: bool = False) -> list[str]:
    """A table section: per (hand, solver, split), the episodes whose record has ``field`` set, and
    how many of them succeeded (``only_with``: rows with at least one such episode only)."""
    lines = [f"## {title}", "", f"| hand | solver | split | episodes | {column} | of which successes |",
             "|---|---|---|---|---|---|"]
    for (hand, solver), recs in groups(records).items():
        for split in SPLITS:
            sel = [r for r in recs if r.get("split") == split]
            marked = [r for r in sel if r.get(field)]
            if sel and (marked or not only_with):
                lines.append(f"| {hand} | {solver} | {split} | {len(sel)} | {len(marked)} | "
                             f"{sum(_ok(r, 0.2) for r in marked)} |")
    return lines + [""]


def endings_table(records: list[dict]) -> list[str]:
    """A table section: per (hand, agent, split, kind), where the failed episodes of the records that
    carry it (``ending``, agents' runs: `grading.episode_ending`) ended."""
    from opend_mj.evaluation.grading import ENDINGS

    lines = ["## Where failed episodes ended (agents; per kind)", "",
             "Never reached: the hand never came within 2 cm of the handle; never held: it never moved the part "
             "3 % open; slipped: it moved the part and was off it for the last 0.5 s; stalled: on the part to the "
             "end, short of 20 %; pushed back: the part had opened 5 % or more and ends below half of that.", "",
             "| hand | agent | split | kind | episodes | failures | " + " | ".join(e.replace("_", " ") for e in ENDINGS)
             + " |", "|" + "---|" * (6 + len(ENDINGS))]
    for (hand, solver), recs in groups(records).items():
        recs = [r for r in recs if "ending" in r]
        for split in SPLITS:
            for kind in ("drawer", "door"):
                sel = [r for r in recs if r.get("split") == split and _kind(r) == kind]
                if not sel:
                    continue
                fails = [r for r in sel if not _ok(r, 0.2)]
                c = Counter(r.get("ending") for r in fails)
                lines.append(f"| {hand} | {solver} | {split} | {kind} | {len(sel)} | {len(fails)} | "
                             + " | ".join(str(c.get(e, 0)) for e in ENDINGS) + " |")
    return lines + [""]


def report_markdown(records: list[dict]) -> str:
    lines = [f"# Results ({len(records)} episodes)", ""]
    lines.append("## Ranking (open ratio > 20 %; by test overall, then train overall)")
    lines.append("")
    lines.append("Beside each 20 % figure, ManiSkill3's criterion: the joint at >= 75 % of its range. Every "
                 "rate has its 95 % Wilson interval in brackets; the last column names the entries whose "
                 "interval (of the ranked overall rate) overlaps this one's: their order is not clear.")
    lines.append("")
    lines.append("| rank | solver / agent | hand | test overall | test >= 75 % range | test drawer | test door | "
                 "train overall | train >= 75 % range | episodes | wrong target opened | 95 % intervals |")
    lines.append("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in ranking(records):
        lines.append(f"| {r['rank']} | {r['solver']} | {r['hand']} | {_fmt(r['test_overall'])} | "
                     f"{_fmt(r['test_overall_range'])} | {_fmt(r['test_drawer'])} | {_fmt(r['test_door'])} | "
                     f"{_fmt(r['train_overall'])} | {_fmt(r['train_overall_range'])} | "
                     f"{r['episodes']} | {r['wrong_targets']} | {overlap_note(r)} |")
    lines.append("")
    for th in THRESHOLDS:
        lines.append(f"## Success rate, open ratio > {int(round(th * 100))} %")
        lines.append("")
        if th >= 0.9:
            lines += [TOP_TIER_NOTE, ""]
        head = "| hand | solver | " + " | ".join(f"{s} {k}" for s in SPLITS for k in KINDS) + " |"
        lines.append(head)
        lines.append("|" + "---|" * (2 + len(SPLITS) * len(KINDS)))
        for row in success_table(records, th):
            cells = [_fmt(row[f"{s}_{k}"]) for s in SPLITS for k in KINDS]
            lines.append(f"| {row['hand']} | {row['solver']} | " + " | ".join(cells) + " |")
        lines.append("")
    lines.append(f"## Success rate, joint at >= {int(round(RANGE_THRESHOLD * 100))} % of its range (ManiSkill3)")
    lines.append("")
    lines.append(head)
    lines.append("|" + "---|" * (2 + len(SPLITS) * len(KINDS)))
    for row in success_table(records, RANGE_THRESHOLD, "range"):
        cells = [_fmt(row[f"{s}_{k}"]) for s in SPLITS for k in KINDS]
        lines.append(f"| {row['hand']} | {row['solver']} | " + " | ".join(cells) + " |")
    lines.append("")
    lines.append("## Failure stages (episodes below 20 %)")
    lines.append("")
    lines.append("| hand | solver | split | failures | " + " | ".join(STAGE_ORDER) + " |")
    lines.append("|" + "---|" * (4 + len(STAGE_ORDER)))
    for (hand, solver), recs in groups(records).items():
        for split in SPLITS:
            fails = [r for r in recs if r.get("split") == split and not _ok(r, 0.2)]
            if not [r for r in recs if r.get("split") == split]:
                continue
            c = Counter("error" if "error" in r else (r.get("failed_stage") or "pull") for r in fails)
            lines.append(f"| {hand} | {solver} | {split} | {len(fails)} | "
                         + " | ".join(str(c.get(s, 0)) for s in STAGE_ORDER) + " |")
    lines.append("")
    lines.append("## Re-grasps per episode and doors pushed open from inside")
    lines.append("")
    lines.append("| hand | solver | split | episodes | mean re-grasps | episodes with a re-grasp | successes after a re-grasp | doors pushed (successes) |")
    lines.append("|---|---|---|---|---|---|---|---|")
    for (hand, solver), recs in groups(records).items():
        for split in SPLITS:
            sel = [r for r in recs if r.get("split") == split and "error" not in r]
            if not sel:
                continue
            n_re = [int(r.get("regrasps") or 0) for r in sel]
            again = [r for r in sel if int(r.get("regrasps") or 0) > 0]
            pushed = [r for r in sel if r.get("pushed")]
            lines.append(f"| {hand} | {solver} | {split} | {len(sel)} | {sum(n_re) / len(sel):.2f} | {len(again)} | "
                         f"{sum(_ok(r, 0.2) for r in again)} | {len(pushed)} ({sum(_ok(r, 0.2) for r in pushed)}) |")
    lines.append("")
    if any(r.get("ending") for r in records):
        lines += endings_table(records)
    lines += _episodes_with(records, "others_moved", "Wrong targets opened", "with another target moved")
    if any(r.get("wrong_kind") for r in records):
        lines += _episodes_with(records, "wrong_kind", "Handles given up because they moved as the other kind "
                                "(learned solvers)", "with a handle given up", only_with=True)
    lines += containment_lines(records)
    lines.append("## Time per episode (mean)")
    lines.append("")
    lines.append("| hand | solver | episodes | sim s | wall s |")
    lines.append("|---|---|---|---|---|")
    for (hand, solver), recs in groups(records).items():
        sims = [float(r["sim_seconds"]) for r in recs if r.get("sim_seconds") is not None]
        walls = [float(r["wall_seconds"]) for r in recs if r.get("wall_seconds") is not None]
        lines.append(f"| {hand} | {solver} | {len(recs)} | {sum(sims) / max(1, len(sims)):.2f} | "
                     f"{sum(walls) / max(1, len(walls)):.2f} |")
    return "\n".join(lines) + "\n"


def write_csv(records: list[dict], path: Path) -> Path:
    path = Path(path)
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["hand", "solver", "measure", "threshold", "split", "kind", "success_rate", "successes",
                    "episodes", "ci95_low", "ci95_high"])
        for measure, th in [("open_ratio", t) for t in THRESHOLDS] + [("range", RANGE_THRESHOLD)]:
            for row in success_table(records, th, "open" if measure == "open_ratio" else "range"):
                for s in SPLITS:
                    for k in KINDS:
                        rate, n_ok, n = row[f"{s}_{k}"]
                        lo, hi = wilson(n_ok, n)
                        w.writerow([row["hand"], row["solver"], measure, th, s, k,
                                    "" if rate is None else f"{rate:.4f}", n_ok, n,
                                    "" if rate is None or not n else f"{lo:.4f}",
                                    "" if rate is None or not n else f"{hi:.4f}"])
    return path


def plot_success(records: list[dict], path: Path, threshold: float = 0.2) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    rows = success_table(records, threshold)
    labels = [f"{r['hand']}\n{r['solver']}" for r in rows]
    # only the split x kind columns that hold episodes
    cols = [(s, k) for s in SPLITS for k in KINDS if any(r[f"{s}_{k}"][2] for r in rows)]
    x = np.arange(len(rows))
    width = 0.8 / len(cols)
    fig, ax = plt.subplots(figsize=(max(6, 1.6 * len(rows)), 4))
    for i, (s, k) in enumerate(cols):
        vals = [100 * (r[f"{s}_{k}"][0] or 0.0) for r in rows]
        bounds = [wilson(*r[f"{s}_{k}"][1:]) if r[f"{s}_{k}"][2] else (0.0, 0.0) for r in rows]
        err = [[max(0.0, v - 100 * lo) for v, (lo, _) in zip(vals, bounds)],
               [max(0.0, 100 * hi - v) if hi else 0.0 for v, (_, hi) in zip(vals, bounds)]]
        ax.bar(x + (i - (len(cols) - 1) / 2) * width, vals, width, label=f"{s} {k}", yerr=err, capsize=2,
               error_kw={"elinewidth": 0.8})
    ax.set_xticks(x)
    ax.set_xticklabels(labels)
    ax.set_ylabel(f"success (%), open ratio > {int(threshold * 100)} %")
    ax.set_ylim(0, 105)
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return Path(path)
