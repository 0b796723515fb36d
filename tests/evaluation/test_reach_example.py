"""examples/reach_agent.py runs under `opend run --policy` and gets its hand onto the handle."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from opend_mj.cli import main
from opend_mj.evaluation.results import load_results

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "reach_agent.py"


@pytest.mark.slow
def test_the_reach_example_touches_the_handle(small_dataset, tmp_path):
    out = tmp_path / "reach.jsonl"
    result = CliRunner().invoke(main, ["run", "--cabinets", str(small_dataset), "--split", "all", "--hand", "allegro",
                                       "--kind", "drawer", "--limit", "2", "--out", str(out), "--policy", str(EXAMPLE)])
    assert result.exit_code == 0, result.output
    records = load_results(out)
    assert len(records) == 2 and all("error" not in r and r["agent_stopped"] for r in records)
    assert all(r["solver"] == "reach" and not r["others_moved"] for r in records)
    # the hand's gripping surfaces reached the handle (MuJoCo distance <= 0: in contact)
    assert sum(r["hand_to_handle"] <= 0.0 for r in records) >= 1
