"""The commands that open one scene (render, gallery, view, teleop) answer an unknown hand as a bad
argument: exit status 2 and the known hands named, before any scene is built."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

from opend_mj.cli import main


@pytest.mark.parametrize("command", [["render", "--cabinet", "any"], ["gallery"], ["view", "--cabinet", "any"],
                                     ["teleop", "--cabinet", "any"]])
def test_an_unknown_hand_is_a_usage_error(command, tmp_path):
    result = CliRunner().invoke(main, [*command, "--cabinets", str(tmp_path), "--hand", "shadoww"])
    assert result.exit_code == 2, result.output
    assert "unknown hand 'shadoww'; known: franka, allegro, shadow, skeleton" in result.output
