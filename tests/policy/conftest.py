"""Fixtures of the planner's tests: the synthetic depth scenes of ``test_grasp_choice.py``, and one
oracle episode on a real cabinet of ``../shared/opend-train``."""

from __future__ import annotations

from importlib import util
from pathlib import Path

import pytest

#: the real OpenD training cabinets (PartNet-Mobility), beside the repository; absent in a user's clone
SHARED_TRAIN = Path(__file__).resolve().parents[2].parent / "shared" / "opend-train"


@pytest.fixture(scope="session")
def grasp_scenes():
    """``test_grasp_choice.py`` as a module: bars and knobs in front of a panel, rendered in depth
    (``_bar``, ``_knob``, ``_view``, ``_render``, ``_box_of``, ``PANEL_X``), and ``_choose``, the
    grasp a planner chooses in such a scene."""
    spec = util.spec_from_file_location("grasp_choice", Path(__file__).with_name("test_grasp_choice.py"))
    module = util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture
def real_episode(tmp_path):
    """``run(cabinet_id, joint, hand, overrides=())``: compile that cabinet of
    ``../shared/opend-train`` into a temporary folder (once) and run one oracle episode on it, with
    ``overrides`` (``(dotted name, value)`` pairs) of the planner's configuration; its record (one
    without an error). Skips where the cabinet is not there."""
    def run(cid: str, joint: str, hand: str, overrides: tuple = ()) -> dict:
        from opend_mj.assets.compiler import compile_cabinet
        from opend_mj.evaluation.episode import EpisodeJob
        from opend_mj.evaluation.runner import run_episode

        if not (SHARED_TRAIN / cid / "mobility.urdf").is_file():
            pytest.skip(f"real data missing: no {cid} in ../shared/opend-train")
        if not (tmp_path / "built" / cid).is_dir():
            compile_cabinet(SHARED_TRAIN / cid, tmp_path / "built", cache_dir=tmp_path / "cache")
        rec = run_episode(EpisodeJob(cabinet=cid, cabinet_dir=str(tmp_path / "built" / cid), joint=joint,
                                     split="all", hand=hand, solver="oracle", planner_overrides=tuple(overrides)))
        assert "error" not in rec, rec.get("error")
        return rec

    return run
