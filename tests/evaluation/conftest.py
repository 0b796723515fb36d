"""Fixtures of the evaluation tests: one small generated drawer cabinet, compiled."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture(scope="module")
def drawer_cabinet(tmp_path_factory) -> Path:
    """Generated cabinet proc_0004 (a drawer stack, seed 0), compiled into a temporary folder."""
    from opend_mj.assets.compiler import compile_cabinet
    from opend_mj.assets.procedural import generate_source

    root = tmp_path_factory.mktemp("eval_cabinets")
    src = generate_source(4, 0, root / "src")
    compile_cabinet(src, root / "built", cache_dir=root / "cache")
    return root / "built" / "proc_0004"
