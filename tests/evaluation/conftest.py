"""Fixtures of the evaluation tests: one small generated drawer cabinet, compiled."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture(scope="module")
def drawer_cabinet(tmp_path_factory) -> Path:
    """The first generated stack of three drawers (seed 0), compiled into a temporary folder."""
    from opend_mj.assets.compiler import compile_cabinet
    from opend_mj.assets.procedural import find_cabinets, write_source

    (cabinet,) = find_cabinets(lambda c: len(c.targets) == 3 and all(t.kind == "drawer" for t in c.targets))
    root = tmp_path_factory.mktemp("eval_cabinets")
    src = write_source(cabinet, root / "src")
    compile_cabinet(src, root / "built", cache_dir=root / "cache")
    return root / "built" / cabinet.id


@pytest.fixture
def drawer_job(drawer_cabinet):
    """An oracle episode of ``drawer_cabinet``'s first drawer for a hand: ``drawer_job(hand)``."""
    import json

    from opend_mj.evaluation.episode import EpisodeJob

    joint = json.loads((drawer_cabinet / "cabinet.json").read_text())["targets"][0]["joint"]

    def job(hand: str) -> EpisodeJob:
        return EpisodeJob(cabinet=drawer_cabinet.name, cabinet_dir=str(drawer_cabinet), joint=joint, split="train",
                          hand=hand, solver="oracle", use_grasp_file=False)

    return job
