"""tools/success_by_part.py: records tallied by the geometry of the part they opened."""

from __future__ import annotations

import json

import pytest


def _door(joint, axis, anchor, handle):
    return {"joint": joint, "type": "door", "axis": axis, "anchor": anchor, "handle": {"center": handle}}


def test_parts_are_classed_by_hinge_axis_and_handle_to_hinge_distance(tmp_path, capsys, load_tool):
    """Drawers, flaps (horizontal hinge axis), doors, and wide doors (handle 0.5 m or more from the
    hinge line, measured across the floor); each records file's row counts successes per class."""
    tool = load_tool("success_by_part")
    targets = [{"joint": "joint_0", "type": "drawer"},
               _door("joint_1", [0, 1, 0], [-0.2, 0.0, 0.1], [-0.2, 0.3, 0.4]),  # a flap
               _door("joint_2", [0, 0, 1], [-0.2, 0.5, 0.0], [-0.22, 0.1, 0.4]),  # 0.4 m: a door
               _door("joint_3", [0, 0, -1], [-0.2, 0.6, 0.9], [-0.2, -0.5, 0.05])]  # 1.1 m: a wide door
    assert [tool.part_class(t, 0.5) for t in targets] == ["drawer", "flap", "door", "wide door"]
    assert tool.part_class(targets[2], 0.3) == "wide door"
    cab = tmp_path / "cabs" / "c1"
    cab.mkdir(parents=True)
    (cab / "cabinet.json").write_text(json.dumps({"targets": targets}))
    records = tmp_path / "r.jsonl"
    records.write_text("".join(json.dumps({"cabinet": "c1", "joint": f"joint_{i}", "hand": "skeleton",
                                           "solver": "bc-fasterrcnn", "success": ok}) + "\n"
                               for i, ok in [(0, True), (1, False), (2, True), (3, False), (3, True)]))
    assert tool.tally(records, tmp_path / "cabs", 0.5) == {"drawer": [1, 1], "flap": [0, 1], "door": [1, 1],
                                                            "wide door": [1, 2]}
    assert tool.main([f"{records}@{tmp_path / 'cabs'}"]) == 0
    assert "| 1/1 | 0/1 | 1/1 | 1/2 | 3/5 |" in capsys.readouterr().out
    with pytest.raises(SystemExit, match="no such records file"):  # a typo is not a row of zeros
        tool.main([f"{tmp_path / 'nope.jsonl'}@{tmp_path / 'cabs'}"])
