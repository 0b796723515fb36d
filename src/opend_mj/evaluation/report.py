"""`opend report`: the current results page (`docs/results.md`) and the README's table, from results files.

Generated cabinets are scored from their records (`results/*.jsonl`, committed). Real PartNet-Mobility
cabinets are non-commercial data: their records stay under `build/`, and only per-hand aggregates
(`opend score --summary results/real/<name>.json`, counts and rates, no cabinet ids) are committed and
read here. So every figure in the page is computed from a file in the repository and cannot drift.

Two success criteria are reported side by side: the paper's (open ratio above 20 %: drawer travel /
drawer length, door angle / 180 degrees) and ManiSkill3's (the joint at 75 % of its range or more).
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path

#: The paper's grasp success with ground-truth handle boxes (its Table 2), per hand, percent.
PAPER_ORACLE = {"franka": 73.4, "allegro": 72.8, "shadow": 54.8, "skeleton": 50.8}
#: The paper's end-to-end test success range over its handle solvers (its Table 3), percent.
PAPER_END_TO_END = "14.6-30.3"
#: Success criteria: (key, title). ``open20``: open ratio > 0.2; ``range75``: joint >= 75 % of its range.
CRITERIA = (("open20", "open ratio > 20 %"), ("open50", "open ratio > 50 %"), ("range75", ">= 75 % of range"))
README_BEGIN = "<!-- results-table:begin (written by `opend report`) -->"
README_END = "<!-- results-table:end -->"


def report_hands() -> list[str]:
    """The hands the tables list, in their order: those of the hands folder, as the registry finds them
    (`opend_mj.sim.hands.builtin_hands`; a hand registered in this process alone is not the benchmark's)."""
    from opend_mj.sim.hands import builtin_hands

    return builtin_hands()


def hand_title(hand: str) -> str:
    """A hand's name in the tables: its ``spec.json`` ``title`` (the name itself for an unknown hand)."""
    from opend_mj.sim.hands import get_hand

    try:
        return get_hand(hand).title
    except KeyError:
        return hand


def hand_flags() -> str:
    """``--hand a --hand b ...`` for every hand of :func:`report_hands` (the commands the page names)."""
    return " ".join(f"--hand {h}" for h in report_hands())


def succeeded(record: dict, criterion: str) -> bool:
    """Whether one episode record succeeded under ``criterion`` (an error record never does)."""
    from opend_mj.evaluation.scoring import RANGE_THRESHOLD, _ok, _ok_range

    if criterion == "open20":
        return _ok(record, 0.2)
    if criterion == "open50":
        return _ok(record, 0.5)
    if criterion == "range75":
        return bool(_ok_range(record, RANGE_THRESHOLD))
    raise ValueError(f"unknown success criterion {criterion!r}; known: {[c for c, _ in CRITERIA]}")


def failure_ending(record: dict) -> str | None:
    """Where a failed episode (open ratio <= 20 %) ended: its ``ending`` (agents' runs,
    `grading.episode_ending`), ``excluded`` for a target the build excluded, else None."""
    if succeeded(record, "open20"):
        return None
    if record.get("failed_stage") == "excluded":
        return "excluded"
    return record.get("ending")


def summarize(records: list[dict]) -> dict:
    """Per (solver, hand): episodes and successes under every criterion, by target kind and overall,
    and, where the records carry it, how many failures ended where (``endings``: `failure_ending`).

    The result holds counts only (no cabinet ids), so it may be committed for real cabinets."""
    out: dict[str, dict] = {}
    for r in records:
        cell = out.setdefault(r["solver"], {}).setdefault(r["hand"], {})
        kinds = ["overall"] + ([r["target_type"]] if r.get("target_type") in ("drawer", "door") else [])
        ending = failure_ending(r)
        for kind in kinds:
            counts = cell.setdefault(kind, {"episodes": 0, **{c: 0 for c, _ in CRITERIA}})
            counts["episodes"] += 1
            for c, _ in CRITERIA:
                counts[c] += int(succeeded(r, c))
            if ending is not None:
                endings = counts.setdefault("endings", {})
                endings[ending] = endings.get(ending, 0) + 1
    return out


def excluded_as_failures(records: list[dict], manifest: Path) -> list[dict]:
    """One failed record per (solver, hand, seed) of ``records`` for every target the build excluded
    (``manifest.json``'s ``excluded_targets``: parts that cannot be opened in their room), so that a
    score over a source set counts them as failures instead of leaving them out."""
    manifest = Path(manifest)
    try:
        excluded = json.loads(manifest.read_text()).get("excluded_targets", [])
    except (OSError, ValueError) as exc:
        raise ValueError(f"{manifest}: cannot read the build's manifest ({exc})") from exc
    runs = sorted({(r["solver"], r["hand"], int(r.get("seed", 0))) for r in records})
    return [{"cabinet": t["id"], "joint": t["joint"], "target_type": t.get("type"), "solver": solver,
             "hand": hand, "seed": seed, "open_ratio": 0.0, "range_ratio": 0.0, "success": False,
             "failed_stage": "excluded", "excluded_reason": t.get("reason")}
            for t in excluded for solver, hand, seed in runs]


def write_summary(records: list[dict], path: Path, label: str = "", manifest: Path | None = None) -> Path:
    """Write :func:`summarize` of ``records`` as JSON (with how many cabinets and targets it covers).

    ``manifest``: the build's manifest; its excluded targets count as failed episodes."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    extra = excluded_as_failures(records, manifest) if manifest is not None else []
    records = list(records) + extra
    payload = {
        "label": label,
        "cabinets": len({r["cabinet"] for r in records}),
        "targets": len({(r["cabinet"], r["joint"]) for r in records}),
        "excluded_targets": len({(r["cabinet"], r["joint"]) for r in extra}),
        "seeds": sorted({int(r.get("seed", 0)) for r in records}),
        "scores": summarize(records),
    }
    path.write_text(json.dumps(payload, indent=1, sort_keys=True) + "\n")
    return path


@dataclass(frozen=True)
class ResultSet:
    """One column group of the results page: a solver on generated and on real cabinets."""

    solver: str
    title: str
    generated: str  # results/<name>.jsonl (records); a glob pattern reads every file it matches
    real: str  # results/real/<name>.json (aggregates); a glob pattern reads every file it matches
    #: how the generated records were made (``{hands}``: :func:`hand_flags`)
    command: str
    #: how the real records were made (``{hands}`` as in ``command``); default: `make eval-real SOLVER=<solver>`
    real_command: str = ""


RESULT_SETS = (
    ResultSet("oracle", "oracle boxes", "oracle_test.jsonl", "oracle_all.json",
              "opend run {hands} --solver oracle --split test"),
    ResultSet("cliport", "CLIPort", "cliport_test.jsonl", "cliport_all.json",
              "... --solver cliport"),
    ResultSet("fasterrcnn", "Faster R-CNN", "fasterrcnn_test.jsonl", "fasterrcnn_all.json",
              "... --solver fasterrcnn"),
    # the shipped behaviour-cloning checkpoints (checkpoints/bc_<hand>.pt), one file per hand on both
    # sides: each hand's policy is retrained on its own
    ResultSet("bc-fasterrcnn", "Behaviour cloning", "bc/*_shipped_test.jsonl", "bc_*_all.json",
              "opend run --policy bc --hand HAND --split test",
              "opend run --policy bc --hand HAND --split all --cabinets build/opend-train --workers 2 "
              "--out build/real-results/bc_HAND_real.jsonl` then `opend score build/real-results/bc_HAND_real.jsonl"),
)
#: Generated-split conditions reported below the main table: (file, what it varies).
CONDITIONS = (
    ("oracle_test_dt120.jsonl", "oracle, physics step 1/120 s"),
    ("oracle_test_light07.jsonl", "oracle, light x 0.7"),
    ("cliport_test_light07.jsonl", "CLIPort, light x 0.7"),
    ("fasterrcnn_test_light07.jsonl", "Faster R-CNN, light x 0.7"),
    ("cliport_test_corpus.jsonl", "CLIPort, hand-written rewordings"),
    ("fasterrcnn_test_corpus.jsonl", "Faster R-CNN, hand-written rewordings"),
)


def _rate(cell: dict | None, criterion: str) -> str:
    """``rate [lo-hi]``: percent and its 95 % Wilson interval (`evaluation.scoring.wilson`)."""
    from opend_mj.evaluation.scoring import interval_text

    if not cell or not cell.get("episodes"):
        return "-"
    return f"{100.0 * cell[criterion] / cell['episodes']:.1f} {interval_text(cell[criterion], cell['episodes'])}"


def _load_generated(path: Path) -> dict:
    """:func:`summarize` of one records file, or of every file a glob pattern in its name matches."""
    from opend_mj.evaluation.scoring import load_records

    paths = sorted(path.parent.glob(path.name)) if any(c in path.name for c in "*?[") else [path]
    paths = [p for p in paths if p.is_file()]
    return summarize(load_records(paths)) if paths else {}


def _load_real(path: Path) -> tuple[dict, dict]:
    """(scores, the first file's payload) of one real aggregate, or of every file a glob pattern in
    its name matches (their scores merged by solver and hand)."""
    paths = sorted(path.parent.glob(path.name)) if any(c in path.name for c in "*?[") else [path]
    paths = [p for p in paths if p.is_file()]
    if not paths:
        return {}, {}
    payloads = [json.loads(p.read_text()) for p in paths]
    scores: dict = {}
    for payload in payloads:
        for solver, hands in payload["scores"].items():
            scores.setdefault(solver, {}).update(hands)
    return scores, payloads[0]


def _pair(scores: dict, solver: str, hand: str) -> str:
    cell = scores.get(solver, {}).get(hand, {}).get("overall")
    return f"{_rate(cell, 'open20')} / {_rate(cell, 'range75')}"


def main_table(results_dir: Path) -> str:
    """The README's table: every hand x (solver x generated / real), cells "> 20 % / >= 75 % of range"."""
    results_dir = Path(results_dir)
    header = ["hand"]
    columns = []
    for rs in RESULT_SETS:
        generated = _load_generated(results_dir / rs.generated)
        real, _ = _load_real(results_dir / "real" / rs.real)
        columns.append((rs, generated, real))
        header += [f"{rs.title}, generated", f"{rs.title}, real"]
    header.append("the paper: oracle / end to end")
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for hand in report_hands():
        row = [hand_title(hand)]
        for rs, generated, real in columns:
            row += [_pair(generated, rs.solver, hand), _pair(real, rs.solver, hand)]
        row.append(f"{PAPER_ORACLE.get(hand, '-')} / {PAPER_END_TO_END}")
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines) + "\n"


def _detail_table(scores: dict, solver: str) -> list[str]:
    lines = ["| hand | drawers | doors | overall | episodes |", "|---|---|---|---|---|"]
    for hand in report_hands():
        cells = scores.get(solver, {}).get(hand)
        if not cells:
            continue
        parts = []
        for kind in ("drawer", "door", "overall"):
            c = cells.get(kind)
            parts.append(" / ".join(_rate(c, k) for k, _ in CRITERIA))
        lines.append(f"| {hand_title(hand)} | " + " | ".join(parts) + f" | {cells['overall']['episodes']} |")
    return lines


def results_markdown(results_dir: Path) -> str:
    """The whole results page."""
    results_dir = Path(results_dir)
    out = [
        "# Results",
        "",
        "Written by `opend report` from the files under `results/`; do not edit by hand. Generated = the",
        "procedural test split of the default build (`make quickstart`'s cabinets); real = all 133 OpenD",
        "training cabinets of `../shared/opend-train` (PartNet-Mobility; only per-hand aggregates are committed,",
        "under `results/real/`). Cells are success in percent: open ratio above 20 % (the paper's criterion) /",
        "the joint at 75 % of its range or more (ManiSkill3's), each with its 95 % Wilson interval in brackets",
        "(on 80 targets one episode moves a rate by 1.25 points). Episode seed 0, each cabinet in a room of its own.",
        "",
        main_table(results_dir),
    ]
    for rs in RESULT_SETS:
        generated = _load_generated(results_dir / rs.generated)
        real, meta = _load_real(results_dir / "real" / rs.real)
        out += [f"## {rs.title}", ""]
        out += ["Cells: open ratio > 20 % / > 50 % / joint >= 75 % of its range.", ""]
        if generated:
            command = rs.command.replace("{hands}", hand_flags())
            out += [f"Generated test split (`{command} --out results/{rs.generated.replace('*', 'HAND')}`):", ""]
            out += _detail_table(generated, rs.solver) + [""]
        if real:
            real_command = rs.real_command.replace("{hands}", hand_flags()) or (
                f"make eval-real SOLVER={rs.solver}` then `opend score build/real-results/{rs.solver}_real.jsonl")
            out += [f"Real cabinets ({meta.get('cabinets')} cabinets, {meta.get('targets')} targets, "
                    f"{meta.get('excluded_targets', 0)} of them excluded by the build's feasibility check and "
                    f"counted as failures; "
                    f"`{real_command} "
                    f"--summary results/real/{rs.real.replace('*', 'HAND')} --manifest build/opend-train/manifest.json`):",
                    ""]
            out += _detail_table(real, rs.solver) + [""]
    rows = []
    for name, title in CONDITIONS:
        scores = _load_generated(results_dir / name)
        for solver, hands in scores.items():
            cells = [_pair(scores, solver, h) if h in hands else "-" for h in report_hands()]
            rows.append(f"| {title} (`results/{name}`) | " + " | ".join(cells) + " |")
    if rows:
        out += ["## Conditions (generated test split)", "",
                "`make results` regenerates every file. Cells: > 20 % / >= 75 % of range.", "",
                "| condition | " + " | ".join(hand_title(h) for h in report_hands()) + " |",
                "|---" * (len(report_hands()) + 1) + "|"]
        out += rows + [""]
    out += endings_section(results_dir)
    out += robustness_sections(results_dir)
    out += expert_sections(results_dir)
    return "\n".join(out)


def endings_section(results_dir: Path) -> list[str]:
    """Where the shipped behaviour-cloning policies' failed episodes end, per hand and kind, on the
    generated test split (the records) and on real cabinets (the aggregates' ``endings``; a summary
    written before they were counted shows "-")."""
    from opend_mj.evaluation.grading import ENDINGS

    rs = next(r for r in RESULT_SETS if r.solver.startswith("bc"))
    generated = _load_generated(Path(results_dir) / rs.generated).get(rs.solver, {})
    real = _load_real(Path(results_dir) / "real" / rs.real)[0].get(rs.solver, {})
    columns = ENDINGS + ("excluded",)
    rows = []
    for hand in report_hands():
        for where, scores in (("generated", generated), ("real", real)):
            if hand not in scores:
                continue
            cells = [scores[hand].get(kind) or {"episodes": 0, "open20": 0} for kind in ("drawer", "door")]
            fails = [c["episodes"] - c["open20"] for c in cells]
            counts = [" / ".join(str((c.get("endings") or {}).get(e, 0)) if c.get("endings") is not None or not f
                                 else "-" for c, f in zip(cells, fails)) for e in columns]
            rows.append(f"| {hand_title(hand)} | {where} | {cells[0]['episodes']} / {cells[1]['episodes']} | "
                        f"{fails[0]} / {fails[1]} | " + " | ".join(counts) + " |")
    if not rows:
        return []
    return ["## Where the behaviour-cloning policies' failures end", "",
            "Failed episodes (open ratio <= 20 %) of the shipped policies above, drawers / doors, by where they "
            "ended (ground truth, for this table only; `grading.episode_ending`): never reached (the hand never "
            "came within 2 cm of the handle), never held (the part never opened 3 %), slipped (off the moved "
            "part for the last 0.5 s), stalled (on it to the end, short of 20 %), pushed back (had opened 5 % "
            "or more, ends below half of that), excluded (the build's feasibility check left the target out).", "",
            "| hand | cabinets | episodes | failures | " + " | ".join(e.replace("_", " ") for e in columns)
            + " |", "|" + "---|" * (4 + len(columns))] + rows + [""]


def expert_sections(results_dir: Path) -> list[str]:
    """The planner as an interactive expert (`opend expert-check`): episodes taken over mid-way, on
    generated cabinets (results/expert/*.json, the summaries beside the records) and real ones
    (results/real/expert_*.json, counts only)."""
    from opend_mj.evaluation.takeover import load_takeovers, takeover_markdown

    results_dir = Path(results_dir)
    paths = [p for pattern in EXPERT_RESULTS for p in sorted(results_dir.glob(pattern + ".json"))]
    if not paths:
        return []
    out = ["## The planner as an interactive expert", "",
           "A lead acts until the switch time, then a fresh expert (the planner with oracle boxes, started from the",
           "state the lead left) acts to the end; docs/demonstrations.md.", ""]
    for path in paths:
        where = "real cabinets" if path.parent.name == "real" else "generated test split"
        out += takeover_markdown(load_takeovers(path), f"{where} (`{path.relative_to(results_dir.parent).as_posix()}`)")
    return out


#: What `opend robustness` writes under results/ (`make robustness`, `make robustness-real`): its records,
#: tables and plots; the report reads the tables (``*.json``).
ROBUSTNESS_RESULTS = ("robustness/*", "real/robustness_*")
#: What `opend expert-check` writes under results/ (`make expert-check`; docs/demonstrations.md): its records
#: and their summaries on generated cabinets, the summaries only on real ones; the report reads the summaries.
EXPERT_RESULTS = ("expert/*", "real/expert_*")


def robustness_sections(results_dir: Path) -> list[str]:
    """The robustness tables (`opend robustness`): generated (results/robustness/*.json) and real
    (results/real/robustness_*.json, counts only), each summarised per solver and hand
    (`robustness.table_summary_markdown`) with the label of the run that made it; every cell is in
    the table beside the JSON (``.md`` for generated cabinets, ``.png`` for both)."""
    from opend_mj.evaluation.robustness import load_table, summary_legend, table_summary_markdown

    results_dir = Path(results_dir)
    out = []
    sets = [(title, {path: load_table(path) for path in paths}) for title, paths in (
        ("generated cabinets", sorted((results_dir / "robustness").glob("*.json"))),
        ("real cabinets", sorted((results_dir / "real").glob("robustness_*.json"))))]
    bands = next((t["bands"] for _, tables in sets for t in tables.values()), None)
    if bands is not None:  # what the columns hold, once for every table with these bands
        out += ["## Robustness", "", summary_legend(bands) + " docs/robustness.md.", ""]
    for title, tables in sets:
        for path, table in tables.items():
            full = [p.relative_to(results_dir.parent).as_posix() for p in (path.with_suffix(".md"),
                                                                           path.with_suffix(".png")) if p.is_file()]
            out += [table_summary_markdown(table, f"{title} (`{path.relative_to(results_dir.parent)}`)",
                                           heading="###", legend=table["bands"] != bands),
                    f"Made by: `{table.get('command') or 'opend robustness'}` ({table.get('label', '')}); "
                    f"every cell: {', '.join(f'`{p}`' for p in full) or 'the JSON'}.", ""]
            again = measured_again(path, tables)
            if again:
                out += ["Also in another run (with its own nominal): " + "; ".join(
                    f"{axes} of {entry} in `{other.relative_to(results_dir.parent).as_posix()}`"
                    for other, axes, entry in again) + ".", ""]
    return out


def _axis_cells(table: dict) -> dict[tuple[str, str, str], tuple]:
    """(solver, hand, axis) -> the counts (nominal, then each level of the axis) of every perturbed cell
    of a robustness table."""
    cells: dict[tuple[str, str, str], list] = {}
    for row in table.get("rows", []):
        conds = row.get("conditions", {})
        nominal = conds.get("nominal", {})
        for cond in sorted(conds):
            if cond != "nominal":
                cells.setdefault((row["solver"], row["hand"], cond.split("=")[0]),
                                 [(nominal.get("successes"), nominal.get("episodes"))]).append(
                    (cond, conds[cond].get("successes"), conds[cond].get("episodes")))
    return {k: tuple(v) for k, v in cells.items()}


def measured_again(path: Path, tables: dict[Path, dict]) -> list[tuple[Path, str, str]]:
    """Where another table of the same cabinets, split and seed (``label``) holds cells of ``path``'s
    table (the same solver, hand and axis) with other counts, i.e. from another run: (other table,
    axes, "solver (hand, hand)") per other table, so a reader of either finds both runs. Tables
    drawn from the same records hold the same counts and are not listed."""
    table = tables[path]
    mine = _axis_cells(table)
    found = []
    for other, t in tables.items():
        if other == path or t.get("label") != table.get("label"):
            continue
        theirs = _axis_cells(t)
        differ = sorted(k for k in mine.keys() & theirs.keys() if mine[k] != theirs[k])
        if not differ:
            continue
        by_solver: dict[str, list[str]] = {}
        for solver, hand, _ in differ:
            if hand not in by_solver.setdefault(solver, []):
                by_solver[solver].append(hand)
        axes = ", ".join(f"`{a}`" for a in sorted({a for _, _, a in differ}))
        found.append((other, axes, ", ".join(f"{s} ({', '.join(h)})" for s, h in by_solver.items())))
    return found


def update_readme(readme: Path, table: str) -> bool:
    """Replace the README's results table between its markers; False when the markers are missing."""
    text = Path(readme).read_text()
    pattern = re.compile(re.escape(README_BEGIN) + r".*?" + re.escape(README_END), re.S)
    if not pattern.search(text):
        return False
    new = pattern.sub(lambda _: f"{README_BEGIN}\n{table}{README_END}", text)
    Path(readme).write_text(new)
    return True


def write_report(results_dir: Path, out: Path, readme: Path | None = None) -> Path:
    """Write the results page to ``out`` and, where given, the README's table."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(results_markdown(results_dir))
    if readme is not None and not update_readme(readme, main_table(results_dir)):
        raise ValueError(f"{readme}: no results-table markers ({README_BEGIN!r} ... {README_END!r})")
    return out
