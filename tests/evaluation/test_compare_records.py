"""tools/compare_records.py: two results files compared episode by episode, wall clock aside."""

from __future__ import annotations

import json
from pathlib import Path


def _write(path: Path, records: list[dict]) -> Path:
    path.write_text("".join(json.dumps(r) + "\n" for r in records))
    return path


def _record(**kw) -> dict:
    rec = {"cabinet": "proc_0001", "joint": "joint_0", "hand": "allegro", "solver": "oracle", "split": "test",
           "seed": 0, "light_scale": 1.0, "pull": "arc", "instruction": "drawer", "success": True,
           "open_ratio": 0.71, "verify": [{"held": True, "touch": {"thumb": 3.2}}], "wall_seconds": 0.4}
    rec.update(kw)
    return rec


def test_identical_but_for_wall_clock(tmp_path, load_tool):
    tool = load_tool("compare_records")
    a = _write(tmp_path / "a.jsonl", [_record(), _record(joint="joint_1")])
    b = _write(tmp_path / "b.jsonl", [_record(joint="joint_1", wall_seconds=9.0), _record(wall_seconds=2.0)])
    bad, lines = tool.compare(a, b)
    assert bad == 0 and "2 identical" in lines[-1]
    assert tool.main([str(a), str(b)]) == 0


def test_a_changed_field_deep_in_a_record_is_reported(tmp_path, load_tool):
    tool = load_tool("compare_records")
    a = _write(tmp_path / "a.jsonl", [_record(), _record(joint="joint_1")])
    b = _write(tmp_path / "b.jsonl", [_record(verify=[{"held": True, "touch": {"thumb": 3.3}}])])
    bad, lines = tool.compare(a, b)
    assert bad == 2  # one differs, one is missing
    assert any("verify.0.touch.thumb: 3.2 != 3.3" in line for line in lines)
    assert any("only in" in line for line in lines)
    assert tool.compare(a, b, hands={"shadow"})[0] == 0  # no shadow episodes on either side
    c = _write(tmp_path / "c.jsonl", [_record(cabinet_dir="/elsewhere/proc_0001"), _record(joint="joint_1")])
    assert tool.compare(a, c)[0] == 1 and tool.compare(a, c, ignore=("cabinet_dir",))[0] == 0
    assert tool.main([str(a), str(b)]) == 1
