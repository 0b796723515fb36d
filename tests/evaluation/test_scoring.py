"""`opend score` on a fixed results file: exact numbers."""

from __future__ import annotations

import csv
from pathlib import Path

from click.testing import CliRunner

DATA = Path(__file__).parent / "data" / "results_small.jsonl"


def test_score_tables_exact():
    from opend_mj.evaluation.scoring import load_records, report_markdown

    md = _plain_md(load_records([DATA]))
    assert "# Results (9 episodes)" in md
    # 20 %: allegro train 0/1 drawers, 1/1 doors; test 2/2 drawers, 1/2 doors
    assert ("| allegro | oracle | 0.0 (0/1) | 100.0 (1/1) | 50.0 (1/2) | 100.0 (2/2) | 50.0 (1/2) | 75.0 (3/4) |"
            in md)
    # the error line counts as a failed drawer episode (error lines carry the target type from the manifest)
    assert "| franka | oracle | - | - | - | 0.0 (0/2) | 100.0 (1/1) | 33.3 (1/3) |" in md
    # 50 % and 90 % recomputed from open_ratio
    assert "| allegro | oracle | 0.0 (0/1) | 0.0 (0/1) | 0.0 (0/2) | 100.0 (2/2) | 0.0 (0/2) | 50.0 (2/4) |" in md
    assert "| allegro | oracle | 0.0 (0/1) | 0.0 (0/1) | 0.0 (0/2) | 50.0 (1/2) | 0.0 (0/2) | 25.0 (1/4) |" in md
    # failure stages and wrong targets
    assert "| allegro | oracle | train | 1 | 0 | 0 | 0 | 1 | 0 | 0 |" in md
    assert "| franka | oracle | test | 2 | 0 | 0 | 1 | 0 | 0 | 0 | 1 |" in md
    assert "| allegro | oracle | test | 4 | 1 | 0 |" in md
    assert "| franka | oracle | test | 3 | 1 | 1 |" in md
    assert "| allegro | oracle | 6 | 8.50 | 2.25 |" in md


def test_refused_instructions_are_a_stage_of_their_own():
    """Episodes whose instruction the parser refused count under "language" (first stage column),
    and their kind comes from the manifest's target type, not from the refused words."""
    from opend_mj.evaluation.scoring import STAGE_ORDER, report_markdown

    base = {"cabinet": "c", "hand": "allegro", "solver": "oracle", "split": "test", "seed": 0, "light_scale": 1.0,
            "pull": "arc", "target_type": "drawer", "open_ratio": 0.0, "success": False}
    records = [{**base, "joint": "a", "instruction": "open the third drawer from the top", "failed_stage": "language"},
               {**base, "joint": "b", "instruction": "open the one on the left", "target_type": "door",
                "failed_stage": "language"},
               {**base, "joint": "c", "instruction": "top drawer", "failed_stage": "grasp"}]
    md = _plain_md(records)
    assert STAGE_ORDER[0] == "language"
    assert "| allegro | oracle | test | 3 | 2 | 0 | 0 | 1 | 0 | 0 | 0 |" in md
    assert "| allegro | oracle | - | - | - | 0.0 (0/2) | 0.0 (0/1) | 0.0 (0/3) |" in md


def test_score_command_csv_and_plot(tmp_path):
    from opend_mj.cli import main

    res = CliRunner().invoke(main, ["score", str(DATA), "--csv", str(tmp_path / "t.csv"),
                                    "--plot", str(tmp_path / "t.png")])
    assert res.exit_code == 0, res.output
    assert "## Failure stages" in res.output
    rows = list(csv.DictReader(open(tmp_path / "t.csv")))
    assert len(rows) == (3 + 1) * 2 * 2 * 3  # (open-ratio thresholds + range) x hands x splits x kinds
    assert {r["measure"] for r in rows} == {"open_ratio", "range"}
    row = [r for r in rows if r["hand"] == "allegro" and r["threshold"] == "0.2" and r["split"] == "test"
           and r["kind"] == "overall"][0]
    assert (row["successes"], row["episodes"], row["success_rate"]) == ("3", "4", "0.7500")
    assert (tmp_path / "t.png").stat().st_size > 1000


def test_duplicate_keys_last_file_wins(tmp_path):
    from opend_mj.evaluation.scoring import load_records

    lines = DATA.read_text().splitlines()
    other = tmp_path / "more.jsonl"
    other.write_text(lines[0].replace('"open_ratio": 0.55', '"open_ratio": 0.05') + "\n")
    recs = load_records([DATA, other])
    assert len(recs) == 9
    assert [r["open_ratio"] for r in recs if r["cabinet"] == "proc_0000"] == [0.05]


def test_record_without_type_counts_in_overall_only():
    from opend_mj.evaluation.scoring import success_table

    recs = [{"cabinet": "c", "joint": "j", "hand": "h", "solver": "s", "split": "test", "seed": 0,
             "light_scale": 1.0, "pull": "arc", "error": "boom"},
            {"cabinet": "c", "joint": "k", "hand": "h", "solver": "s", "split": "test", "seed": 0,
             "light_scale": 1.0, "pull": "arc", "target_type": "door", "open_ratio": 0.5, "success": True}]
    row = success_table(recs)[0]
    assert row["test_overall"][1:] == (1, 2)
    assert row["test_door"][1:] == (1, 1) and row["test_drawer"][2] == 0


def test_handles_given_up_by_their_kind_are_counted():
    from opend_mj.evaluation.scoring import report_markdown

    base = dict(hand="shadow", solver="cliport", split="test", target_type="drawer", seed=0, open_ratio=0.5,
                success=True, cabinet="c", instruction="top drawer")
    records = [dict(base, joint="joint_0", wrong_kind=[{"box": [0, 0, 1, 1], "kind": "door"}]),
               dict(base, joint="joint_1", wrong_kind=[{"box": [0, 0, 1, 1], "kind": "door"}], success=False,
                    open_ratio=0.0),
               dict(base, joint="joint_2", wrong_kind=[])]
    md = _plain_md(records)
    assert "| shadow | cliport | test | 3 | 2 | 1 |" in md
    assert "given up" not in _plain_md([records[2]])


def _rec(joint, **kw):
    return dict(cabinet="c", joint=joint, hand="h", solver="s", split="test", seed=0, light_scale=1.0, pull="arc",
                target_type="door", **kw)


def test_range_column_from_range_ratio_or_raw_joint_value():
    """ManiSkill3's criterion (>= 75 % of the joint range) beside the paper's 20 %: read from range_ratio,
    else computed from the raw joint value and range (a door closed at its upper limit opens downward)."""
    from opend_mj.evaluation.scoring import range_fraction, ranking, report_markdown, success_table

    recs = [_rec("a", open_ratio=0.45, range_ratio=0.9, success=True),
            _rec("b", open_ratio=0.30, range_ratio=0.6, success=True),
            _rec("c", open_ratio=0.40, joint_value=-1.2, joint_range=[-1.5, 0.0], success=True),
            _rec("d", open_ratio=None, range_ratio=None, joint_value=None, success=False, failed_stage="physics")]
    assert abs(range_fraction(recs[2]) - 0.8) < 1e-9
    assert range_fraction(recs[3]) == 0.0
    row = success_table(recs, 0.75, "range")[0]
    assert row["test_overall"] == (0.5, 2, 4)
    assert success_table(recs)[0]["test_overall"][1:] == (3, 4)
    top = ranking(recs)[0]
    assert top["test_overall_range"] == (0.5, 2, 4)
    md = _plain_md(recs)
    assert "joint at >= 75 % of its range (ManiSkill3)" in md
    assert "| 1 | s | h | 75.0 (3/4) | 50.0 (2/4) |" in md


def test_range_column_is_na_for_records_without_the_range():
    """A record written before the range was recorded: n/a, not a guess."""
    from opend_mj.evaluation.scoring import range_fraction, report_markdown

    old = [_rec("a", open_ratio=0.45, success=True), _rec("b", open_ratio=0.1, success=False)]
    assert range_fraction(old[0]) is None
    assert "| 1 | s | h | 50.0 (1/2) | n/a |" in _plain_md(old)


def _plain_md(records) -> str:
    """`report_markdown` without its 95 % intervals (these tests check the counts and rates)."""
    import re

    from opend_mj.evaluation.scoring import report_markdown

    return re.sub(r" \[[0-9.]+-[0-9.]+\]", "", report_markdown(records))


def test_wilson_interval_reference_values():
    """95 % Wilson intervals against textbook values (Brown, Cai & DasGupta 2001): inside [0, 1], not
    empty at 0 or n successes, narrower with more episodes."""
    from opend_mj.evaluation.scoring import interval_text, wilson

    lo, hi = wilson(0, 10)
    assert lo == 0.0 and abs(hi - 0.2775) < 1e-4
    lo, hi = wilson(5, 10)
    assert abs(lo - 0.2366) < 1e-4 and abs(hi - 0.7634) < 1e-4
    assert abs(wilson(84, 84)[1] - 1.0) < 1e-12 and wilson(84, 84)[0] < 0.96
    assert wilson(0, 0) == (0.0, 1.0)
    assert wilson(42, 84)[1] - wilson(42, 84)[0] < wilson(5, 10)[1] - wilson(5, 10)[0]
    assert interval_text(81, 84) == "[90.0-98.8]"


def test_score_gives_intervals_and_ranking_overlaps():
    """Every rate of `opend score` carries its interval; the ranking says which entries' intervals
    overlap (81/84 and 80/84 do; 81/84 and 30/84 do not), and perturbed runs are their own entries."""
    from opend_mj.evaluation.scoring import ranking, report_markdown

    def runs(solver, k, n, **extra):
        return [{"cabinet": f"c{i}", "joint": "j", "hand": "allegro", "solver": solver, "split": "test",
                 "target_type": "drawer", "open_ratio": 0.5 if i < k else 0.0, **extra} for i in range(n)]

    records = runs("a", 81, 84) + runs("b", 80, 84) + runs("a", 30, 84, perturb="light=strong")
    rows = {r["solver"]: r for r in ranking(records)}
    assert set(rows) == {"a", "b", "a [light=strong]"}
    assert rows["a"]["overlaps"] == [rows["b"]["rank"]]
    assert rows["a [light=strong]"]["overlaps"] == []
    md = report_markdown(records)
    assert "| 1 | a | allegro | 96.4 (81/84) [90.0-98.8] |" in md
    assert "overlaps #2" in md and "clear of all others" in md


def test_robustness_table_pairs_episodes_and_marks_bands():
    """A condition is compared with nominal on the same episodes; drops beyond 5 points (mild) or 15
    (strong) are marked, smaller ones are not."""
    from opend_mj.evaluation.robustness import robustness_table, table_markdown

    def runs(perturb, oks):
        return [{"cabinet": f"c{i}", "joint": "j", "hand": "allegro", "solver": "s", "split": "test",
                 "open_ratio": 0.5 if ok else 0.0, **({"perturb": perturb} if perturb else {})}
                for i, ok in enumerate(oks)]

    nominal = [True] * 15 + [False] * 5                        # 75 % over 20
    records = (runs(None, nominal) + runs("light=mild", [True] * 14 + [False] * 6)      # -5: inside
               + runs("light=strong", [True] * 11 + [False] * 9)                        # -20: outside
               + runs("physics=mild", [True] * 5 + [False] * 5))  # first 10 only: nominal 100 % there
    row = robustness_table(records)["rows"][0]["conditions"]
    assert row["nominal"]["rate"] == 75.0 and row["nominal"]["ci95"] == [53.13, 88.81]
    assert row["light=mild"]["delta"] == -5.0 and row["light=mild"]["within_band"]
    assert row["light=strong"]["delta"] == -20.0 and not row["light=strong"]["within_band"]
    assert row["physics=mild"]["paired_episodes"] == 10 and row["physics=mild"]["delta"] == -50.0
    md = table_markdown(robustness_table(records))
    assert "| s | allegro | `light` | 75.0 [53.1-88.8] (15/20) | 70.0 [48.1-85.5] (14/20) -5.0 | " \
           "55.0 [34.2-74.2] (11/20) -20.0 ! |" in md
    assert "Outside the bands: s / allegro under light=strong (-20.0); s / allegro under physics=mild (-50.0)." in md


def test_failed_episodes_are_told_apart_by_where_they_ended():
    """A failure is classified from the ground-truth hold probe: never reached, never held,
    slipped, stalled part-way, pushed back; `opend score` counts them per kind for agents' runs."""
    from opend_mj.evaluation.grading import episode_ending
    from opend_mj.evaluation.scoring import report_markdown

    far = {"first_held": None, "last_held": None, "steps": 600, "peak_ratio": 0.0}
    assert episode_ending(True, 0.4, 0.0, far) is None
    assert episode_ending(False, 0.0, 0.08, far) == "never_reached"
    assert episode_ending(False, 0.0, 0.01, far) == "never_held"  # got to the handle, touched nothing
    touched = {"first_held": 100, "last_held": 599, "steps": 600, "peak_ratio": 0.01}
    assert episode_ending(False, 0.01, 0.0, touched) == "never_held"  # on it, never moved it
    held = {"first_held": 100, "last_held": 599, "steps": 600, "peak_ratio": 0.12}
    assert episode_ending(False, 0.12, 0.0, held) == "stalled"
    assert episode_ending(False, 0.12, 0.0, {**held, "last_held": 300}) == "slipped"
    assert episode_ending(False, 0.02, 0.0, {**held, "last_held": 300}) == "pushed_back"
    records = [{"hand": "allegro", "solver": "bc", "split": "test", "target_type": "door", "success": False,
                "open_ratio": 0.02, "ending": "pushed_back"},
               {"hand": "allegro", "solver": "bc", "split": "test", "target_type": "door", "success": False,
                "open_ratio": 0.0, "ending": "never_held"},
               {"hand": "allegro", "solver": "bc", "split": "test", "target_type": "drawer", "success": True,
                "open_ratio": 0.5, "ending": None}]
    table = report_markdown(records)
    assert "| allegro | bc | test | door | 2 | 2 | 0 | 1 | 0 | 0 | 1 |" in table
    assert "| allegro | bc | test | drawer | 1 | 0 | 0 | 0 | 0 | 0 | 0 |" in table
    planner = [{k: v for k, v in r.items() if k != "ending"} for r in records]
    assert "Where failed episodes ended" not in report_markdown(planner)
