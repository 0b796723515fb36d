"""Fixtures of the planner's tests: the synthetic depth scenes of ``test_grasp_choice.py``."""

from __future__ import annotations

from importlib import util
from pathlib import Path

import pytest


@pytest.fixture(scope="session")
def grasp_scenes():
    """``test_grasp_choice.py`` as a module: bars and knobs in front of a panel, rendered in depth
    (``_bar``, ``_knob``, ``_view``, ``_render``, ``_box_of``, ``PANEL_X``), and ``_choose``, the
    grasp a planner chooses in such a scene."""
    spec = util.spec_from_file_location("grasp_choice", Path(__file__).with_name("test_grasp_choice.py"))
    module = util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
