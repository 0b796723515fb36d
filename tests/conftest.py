"""Shared fixtures: the real PartNet cabinet and a few procedural cabinets, compiled once per session.

The compile cache (CoACD results) lives in a session tmp dir, so the real cabinet's decomposition runs
once per test session and never touches the user's `cabinets/`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import pytest

REAL_ID = "45780"
REAL_SOURCE = Path(__file__).resolve().parents[1].parent / "shared" / "partnet-sample" / REAL_ID
#: How many valid procedural cabinets the compiler tests look at, out of how many sources.
N_PROC_SOURCES = 40
N_PROC_CABINETS = 6


@dataclass
class Compiled:
    """A compiled cabinet: its folder, cabinet.json and the CompileResult that made it."""

    id: str
    source: Path
    dir: Path
    info: dict
    result: object

    @property
    def xml(self) -> Path:
        return self.dir / "cabinet.xml"

    def model(self):
        from opend_mj.assets.checks import load_cabinet

        return load_cabinet(self.dir)


@pytest.fixture(scope="session")
def compile_cache(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("compile_cache")


@pytest.fixture(scope="session")
def real_source() -> Path:
    if not (REAL_SOURCE / "mobility.urdf").is_file():
        pytest.skip(f"real PartNet-Mobility sample not found at {REAL_SOURCE}")
    return REAL_SOURCE


@pytest.fixture(scope="session")
def real_cabinet(real_source, tmp_path_factory, compile_cache) -> Compiled:
    from opend_mj.assets.compiler import compile_cabinet

    out = tmp_path_factory.mktemp("real_cabinets")
    result = compile_cabinet(real_source, out, cache_dir=compile_cache)
    assert result.status == "built", f"{REAL_ID} was not built: {result.reason}: {result.message}"
    return Compiled(REAL_ID, real_source, out / REAL_ID, result.info, result)


@pytest.fixture(scope="session")
def proc_sources(tmp_path_factory) -> list[Path]:
    from opend_mj.assets.procedural import generate_sources

    return generate_sources(N_PROC_SOURCES, 0, tmp_path_factory.mktemp("proc_sources"), progress=False)


@pytest.fixture(scope="session")
def proc_cabinets(proc_sources, tmp_path_factory, compile_cache) -> list[Compiled]:
    """The first few procedural sources that compile, covering drawers and double doors."""
    from opend_mj.assets.compiler import compile_cabinet

    out = tmp_path_factory.mktemp("proc_cabinets")
    chosen: list[Compiled] = []
    for source in proc_sources:
        meta = json.loads((source / "meta.json").read_text())["procedural"]
        if not meta["describable"]:
            continue
        result = compile_cabinet(source, out, cache_dir=compile_cache)
        assert result.status == "built", f"{source.name} ({meta['layout']}): {result.reason}: {result.message}"
        chosen.append(Compiled(source.name, source, out / source.name, result.info, result))
        kinds = [t["type"] for c in chosen for t in c.info["targets"]]
        doubles = [c for c in chosen if [t["type"] for t in c.info["targets"]].count("door") >= 2]
        if len(chosen) >= N_PROC_CABINETS and "drawer" in kinds and doubles:
            break
    assert len(chosen) >= N_PROC_CABINETS, "too few describable procedural cabinets"
    return chosen


@pytest.fixture(params=["real"] + [f"proc{i}" for i in range(N_PROC_CABINETS)])
def any_cabinet(request) -> Compiled:
    """Each compiled cabinet in turn: the real one (skipped if absent), then the procedural ones."""
    if request.param == "real":
        return request.getfixturevalue("real_cabinet")
    return request.getfixturevalue("proc_cabinets")[int(request.param[4:])]


@pytest.fixture(scope="session")
def small_dataset(proc_sources, tmp_path_factory) -> Path:
    """A compiled dataset (manifest + cabinets) of the first dozen procedural sources."""
    from opend_mj.assets.dataset import build_dataset

    out = tmp_path_factory.mktemp("small_dataset")
    build_dataset(proc_sources[:12], out, workers=2, progress=False, log=lambda *a: None)
    return out
