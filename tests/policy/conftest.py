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
def door_plane():
    """``plane(lo, hi)``: (view, depth) of a 256 px camera (fovy 45 degrees) at the origin looking
    along +x, and a door's front plane 1 m ahead from y = ``lo`` to ``hi`` and 0.3 m above and below
    its centre, the room 2.5 m away around it."""
    import numpy as np

    from opend_mj.sim.camera import CameraIntrinsics, CameraView

    def plane(lo: float, hi: float):
        rot = np.column_stack([(0, -1, 0), (0, 0, 1), (-1, 0, 0)]).astype(float)
        view = CameraView(CameraIntrinsics.from_fovy(45, 256, 256), np.zeros(3), rot)
        cols, rows = np.meshgrid(np.arange(256) + 0.5, np.arange(256) + 0.5)
        on_plane = view.backproject(cols.ravel(), rows.ravel(), np.ones(cols.size))
        inside = (on_plane[:, 1] > lo) & (on_plane[:, 1] < hi) & (np.abs(on_plane[:, 2]) < 0.3)
        return view, np.where(inside, 1.0, 2.5).reshape(256, 256)

    return plane


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
