"""`opend report` / `opend score --summary`: the results page comes from the results files, counts only."""

from __future__ import annotations

import json
import re

import pytest

from opend_mj.evaluation.report import (
    README_BEGIN,
    README_END,
    main_table,
    succeeded,
    summarize,
    update_readme,
    write_report,
    write_summary,
)


def _record(cabinet, joint, hand, kind, open_ratio, range_ratio, solver="oracle", **extra):
    return {"cabinet": cabinet, "joint": joint, "hand": hand, "solver": solver, "split": "test", "seed": 0,
            "target_type": kind, "open_ratio": open_ratio, "range_ratio": range_ratio, **extra}


RECORDS = [
    _record("c1", "joint_0", "allegro", "drawer", 0.9, 0.95),    # succeeds under every criterion
    _record("c1", "joint_1", "allegro", "door", 0.3, 0.6),       # > 20 % only
    _record("c2", "joint_0", "allegro", "door", 0.1, 0.2),       # fails
    _record("c2", "joint_1", "allegro", "drawer", 0.8, 0.9, error="boom"),  # an error never succeeds
]


def test_criteria():
    assert [succeeded(RECORDS[0], c) for c in ("open20", "open50", "range75")] == [True, True, True]
    assert [succeeded(RECORDS[1], c) for c in ("open20", "open50", "range75")] == [True, False, False]
    assert not any(succeeded(RECORDS[3], c) for c in ("open20", "open50", "range75"))
    with pytest.raises(ValueError, match="unknown success criterion"):
        succeeded(RECORDS[0], "open99")


def test_summary_counts_by_kind():
    cell = summarize(RECORDS)["oracle"]["allegro"]
    assert cell["overall"] == {"episodes": 4, "open20": 2, "open50": 1, "range75": 1}
    assert cell["door"] == {"episodes": 2, "open20": 1, "open50": 0, "range75": 0}
    assert cell["drawer"]["episodes"] == 2


def test_summary_file_holds_no_cabinet_ids(tmp_path):
    path = write_summary(RECORDS, tmp_path / "real" / "oracle_all.json", label="x")
    text = path.read_text()
    assert "c1" not in text and "c2" not in text
    payload = json.loads(text)
    assert payload["cabinets"] == 2 and payload["targets"] == 4


def test_report_and_readme_table(tmp_path):
    results = tmp_path / "results"
    (results / "real").mkdir(parents=True)
    with open(results / "oracle_test.jsonl", "w") as f:
        for r in RECORDS:
            f.write(json.dumps(r) + "\n")
    write_summary(RECORDS[:2], results / "real" / "oracle_all.json")
    table = main_table(results)
    allegro = next(line for line in table.splitlines() if line.startswith("| Allegro"))
    cells = [c.strip() for c in allegro.strip("|").split("|")]
    # generated: 2 of 4 > 20 %, 1 of 4 at 75 % of range, each with its 95 % Wilson interval
    assert cells[1] == "50.0 [15.0-85.0] / 25.0 [4.6-69.9]"
    assert cells[2] == "100.0 [34.2-100.0] / 50.0 [9.5-90.5]"     # real aggregates: 2 of 2, 1 of 2
    readme = tmp_path / "README.md"
    readme.write_text(f"intro\n{README_BEGIN}\nold table\n{README_END}\nrest\n")
    out = write_report(results, tmp_path / "docs" / "results.md", readme)
    assert "50.0 [15.0-85.0] / 25.0 [4.6-69.9]" in readme.read_text() and "old table" not in readme.read_text()
    assert readme.read_text().endswith("rest\n")
    assert "# Results" in out.read_text()
    plain = tmp_path / "PLAIN.md"
    plain.write_text("no markers\n")
    assert update_readme(plain, table) is False
    with pytest.raises(ValueError, match="no results-table markers"):
        write_report(results, tmp_path / "docs" / "results.md", plain)


def test_excluded_targets_count_as_failures(tmp_path):
    manifest = tmp_path / "manifest.json"
    manifest.write_text(json.dumps({"excluded_targets": [
        {"id": "c3", "joint": "joint_0", "type": "drawer", "reason": "jammed", "message": "m"}]}))
    path = write_summary(RECORDS, tmp_path / "s.json", manifest=manifest)
    payload = json.loads(path.read_text())
    assert payload["targets"] == 5 and payload["excluded_targets"] == 1
    assert payload["scores"]["oracle"]["allegro"]["overall"] == {"episodes": 5, "open20": 2, "open50": 1,
                                                                  "range75": 1, "endings": {"excluded": 1}}
    manifest.write_text("{not json")
    with pytest.raises(ValueError, match="manifest.json"):
        write_summary(RECORDS, tmp_path / "s.json", manifest=manifest)


def _plain(text: str) -> str:
    """A cell without its 95 % intervals (the tests of counts read the rates alone)."""
    return re.sub(r" \[[0-9.]+-[0-9.]+\]", "", text)


def test_report_reads_every_hands_bc_records(tmp_path):
    """The behaviour-cloning columns read one records file per hand (results/bc/<hand>_shipped_test.jsonl)
    and one real aggregate per hand, results/real/bc_<hand>_all.json."""
    results = tmp_path / "results"
    (results / "bc").mkdir(parents=True)
    (results / "real").mkdir()
    bc = [dict(r, solver="bc-fasterrcnn") for r in RECORDS]
    shadow = [dict(r, hand="shadow") for r in bc[:2]]
    for name, records in (("allegro_shipped_test.jsonl", bc), ("shadow_shipped_test.jsonl", shadow),
                          ("allegro_n50_test.jsonl", bc[:1])):   # not a shipped checkpoint's: not read
        (results / "bc" / name).write_text("".join(json.dumps(r) + "\n" for r in records))
    write_summary(bc[1:3], results / "real" / "bc_allegro_all.json")
    write_summary(shadow[1:], results / "real" / "bc_shadow_all.json")
    rows = {line.split("|")[1].strip(): [c.strip() for c in line.strip("|").split("|")]
            for line in main_table(results).splitlines()[2:]}
    assert [_plain(c) for c in rows["Allegro"][7:9]] == ["50.0 / 25.0", "50.0 / 0.0"]
    assert [_plain(c) for c in rows["Shadow"][7:9]] == ["100.0 / 50.0", "100.0 / 0.0"]
    assert rows["Franka gripper"][7] == "- / -"
    page = write_report(results, tmp_path / "results.md").read_text()
    assert "## Behaviour cloning" in page and "results/bc/HAND_shipped_test.jsonl" in page


def test_report_points_between_two_runs_of_one_robustness_cell(tmp_path):
    """A real-cabinet table and a later run of one of its axes (`opend robustness --axis`) on the same
    cabinets: each table's section names the other, so a reader finds both; tables drawn from the
    same records (the same counts) are not cross-referenced."""
    from opend_mj.evaluation.report import robustness_sections

    def table(label, strong, axes=("depth_noise", "light"), hand="allegro"):
        conds = {"nominal": {"successes": 250, "episodes": 266, "rate": 94.0, "ci95": [90.5, 96.3]}}
        for axis in axes:
            for level, k in (("mild", 240), ("strong", strong)):
                conds[f"{axis}={level}"] = {"successes": k, "episodes": 266, "rate": 100.0 * k / 266,
                                            "ci95": [0.0, 100.0], "delta": 100.0 * (k - 250) / 266,
                                            "within_band": True}
        return {"label": label, "command": "opend robustness", "bands": {"mild": 5.0, "strong": 15.0},
                "rows": [{"solver": "cliport", "hand": hand, "conditions": conds}]}

    real = tmp_path / "results" / "real"
    real.mkdir(parents=True)
    (real / "robustness_all_cliport.json").write_text(json.dumps(table("opend-train", 200)))
    (real / "robustness_all_depth_noise_cliport.json").write_text(
        json.dumps(table("opend-train", 220, axes=("depth_noise",))))
    (real / "robustness_all_copy.json").write_text(json.dumps(table("opend-train", 200, axes=("light",))))
    (real / "robustness_other.json").write_text(json.dumps(table("elsewhere", 100)))
    text = "\n".join(robustness_sections(tmp_path / "results"))
    again = [line for line in text.splitlines() if line.startswith("Also in another run")]
    assert again == [
        "Also in another run (with its own nominal): `depth_noise` of cliport (allegro) in "
        "`results/real/robustness_all_depth_noise_cliport.json`.",
        "Also in another run (with its own nominal): `depth_noise` of cliport (allegro) in "
        "`results/real/robustness_all_cliport.json`."]


def test_a_fifth_hand_is_one_folder(tmp_path, monkeypatch):
    """Adding a hand is adding its folder: a copy of the shipped hands plus one more under another
    name (its title and order in its spec.json), named by $OPEND_HANDS_DIR, is in the registry, in
    `opend hands` and in the report's rows, titles and orderings; nothing else lists it."""
    import shutil

    from click.testing import CliRunner

    from opend_mj.cli import main
    from opend_mj.evaluation.report import results_markdown
    from opend_mj.sim import hands

    folder = tmp_path / "hands"
    for name in hands.builtin_hands():
        shutil.copytree(hands.HANDS_DIR / name, folder / name)
    shutil.copytree(hands.HANDS_DIR / "allegro", folder / "lefty")
    spec = json.loads((folder / "lefty" / "spec.json").read_text())
    spec.update(name="lefty", title="Lefty hand", order=3)  # between allegro (2) and shadow (3): by name
    (folder / "lefty" / "spec.json").write_text(json.dumps(spec))
    monkeypatch.setenv(hands.HANDS_DIR_ENV, str(folder))
    try:
        assert hands.builtin_hands() == ["franka", "allegro", "lefty", "shadow", "skeleton"]
        assert hands.list_hands()[:5] == hands.builtin_hands()
        lefty = hands.get_hand("lefty")
        assert lefty.title == "Lefty hand" and lefty.spec.dof == 16 and lefty.folder == (folder / "lefty").resolve()
        listed = CliRunner().invoke(main, ["hands", "--names"])
        assert listed.exit_code == 0 and listed.output.split()[:5] == hands.builtin_hands()
        results = tmp_path / "results"
        results.mkdir()
        (results / "oracle_test.jsonl").write_text("".join(json.dumps(r) + "\n" for r in [
            _record("c1", "joint_0", "lefty", "drawer", 0.9, 0.95), _record("c1", "joint_0", "shadow", "door", 0.1, 0.1),
            _record("c1", "joint_0", "allegro", "door", 0.3, 0.9)]))
        rows = [line.split(" | ")[0].lstrip("| ") for line in main_table(results).splitlines()[2:]]
        assert rows == ["Franka gripper", "Allegro", "Lefty hand", "Shadow", "Skeleton"]
        page = results_markdown(results)
        detail = [line.split(" | ")[0].lstrip("| ") for line in page.split("## oracle boxes")[1].splitlines()
                  if line.startswith("| ") and not line.startswith("| hand")]
        assert detail[:3] == ["Allegro", "Lefty hand", "Shadow"]
        assert "--hand allegro --hand lefty --hand shadow" in page
    finally:
        monkeypatch.delenv(hands.HANDS_DIR_ENV)
        assert "lefty" not in hands.builtin_hands()  # back to the shipped hands
    assert "lefty" not in hands.list_hands()


def test_report_says_where_each_hands_bc_failures_end(tmp_path):
    """The shipped policies' failures, per hand and kind, by ending: counted from the generated records
    and carried by the real aggregate (counts only), the build's excluded targets among them; an
    aggregate written before endings were counted shows "-" rather than zeros."""
    from opend_mj.evaluation.report import endings_section

    results = tmp_path / "results"
    (results / "bc").mkdir(parents=True)
    (results / "real").mkdir()
    bc = [_record("c1", "joint_0", "allegro", "drawer", 0.9, 0.95, solver="bc-fasterrcnn"),
          _record("c1", "joint_1", "allegro", "door", 0.05, 0.1, solver="bc-fasterrcnn", ending="slipped"),
          _record("c2", "joint_0", "allegro", "door", 0.0, 0.0, solver="bc-fasterrcnn", ending="never_reached"),
          _record("c2", "joint_1", "allegro", "door", 0.01, 0.0, solver="bc-fasterrcnn", ending="slipped")]
    (results / "bc" / "allegro_shipped_test.jsonl").write_text("".join(json.dumps(r) + "\n" for r in bc))
    manifest = tmp_path / "manifest.json"
    manifest.write_text(json.dumps({"excluded_targets": [{"id": "c3", "joint": "joint_0", "type": "door"}]}))
    summary = write_summary(bc, results / "real" / "bc_allegro_all.json", manifest=manifest)
    door = json.loads(summary.read_text())["scores"]["bc-fasterrcnn"]["allegro"]["door"]
    assert door["endings"] == {"slipped": 2, "never_reached": 1, "excluded": 1}
    old = [dict(r, hand="shadow") for r in bc]
    write_summary([{k: v for k, v in r.items() if k != "ending"} for r in old],
                  results / "real" / "bc_shadow_all.json")
    rows = [[c.strip() for c in line.strip("|").split("|")] for line in endings_section(results)
            if line.startswith("| ") and not line.startswith("| hand")]
    by = {tuple(r[:2]): r[2:] for r in rows}
    # drawers / doors: episodes, failures, never reached, never held, slipped, stalled, pushed back, excluded
    assert by[("Allegro", "generated")] == ["1 / 3", "0 / 3", "0 / 1", "0 / 0", "0 / 2", "0 / 0", "0 / 0", "0 / 0"]
    assert by[("Allegro", "real")] == ["1 / 4", "0 / 4", "0 / 1", "0 / 0", "0 / 2", "0 / 0", "0 / 0", "0 / 1"]
    assert by[("Shadow", "real")] == ["1 / 3", "0 / 3"] + ["0 / -"] * 6
    assert "## Where the behaviour-cloning policies' failures end" in write_report(
        results, tmp_path / "results.md").read_text()
