"""Shared fixtures: the real PartNet cabinet, a few procedural cabinets and a small dataset, compiled
once per test run.

They are built in session tmp dirs (never the user's `cabinets/`) that every pytest-xdist process of
the run shares: the first process to need one builds it under a file lock, the others wait for it and
reuse it (`make test` runs the suite in 2 processes with ``--dist loadfile``).

Skips: every skip says why. Under CI (the environment variable ``CI`` set), a skip is a failure
unless its reason says that real data (``../shared``) or an optional extra is missing: a test that
needs only what the repository generates must run there.
"""

from __future__ import annotations

import json
import os
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")  # before any test module imports mujoco's renderer
# One math-library thread per test process (torch, BLAS), set before anything imports them: the suite
# runs in several processes (pytest-xdist), and idle OpenMP threads spinning beside another process
# cost about three times the CPU of the work itself (the three torch training and detector tests:
# 35 CPU s with the default threads, 11 CPU s with one, on the 2-core development machine).
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

pytest_plugins = ("pytester",)  # tests/test_ci_skips.py runs a small suite under this conftest

#: Words a skip's reason must contain to stay a skip under CI: real data or an optional extra is missing.
CI_ALLOWED_SKIPS = ("../shared", "optional extra")


def skip_allowed_in_ci(reason: str) -> bool:
    """Whether a skip with this reason may stay a skip under CI (see the module docstring)."""
    return any(words in reason for words in CI_ALLOWED_SKIPS)


def _fail_unexplained_skip(report) -> None:
    """Under CI, turn a skip (of a test or of a whole module) into a failure unless its reason is allowed."""
    if not (report.skipped and os.environ.get("CI")) or hasattr(report, "wasxfail"):
        return
    reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else str(report.longrepr)
    if not skip_allowed_in_ci(reason):
        report.outcome = "failed"
        report.longrepr = (f"skipped under CI ({reason}); only a missing ../shared (real data) or a missing "
                           "optional extra may skip there: make the test build what it needs, or fail")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    _fail_unexplained_skip(outcome.get_result())


@pytest.hookimpl(hookwrapper=True)
def pytest_make_collect_report(collector):
    outcome = yield
    _fail_unexplained_skip(outcome.get_result())

REAL_ID = "45780"
REAL_SOURCE = Path(__file__).resolve().parents[1].parent / "shared" / "partnet-sample" / REAL_ID
#: How many valid procedural cabinets the compiler tests look at, out of how many sources.
N_PROC_SOURCES = 40
N_PROC_CABINETS = 6


@dataclass
class Compiled:
    """A compiled cabinet: its folder and cabinet.json."""

    id: str
    source: Path
    dir: Path
    info: dict

    @property
    def xml(self) -> Path:
        return self.dir / "cabinet.xml"

    def model(self):
        from opend_mj.assets.checks import load_cabinet

        return load_cabinet(self.dir)


@contextmanager
def shared_dir(tmp_path_factory, name: str):
    """A tmp dir that every xdist process of this run shares, held under a file lock while in use."""
    from filelock import FileLock

    base = tmp_path_factory.getbasetemp()
    root = base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base  # xdist: <run>/popen-gwN
    path = root / f"shared-{name}"
    with FileLock(str(path) + ".lock"):
        path.mkdir(exist_ok=True)
        yield path


@pytest.fixture(scope="session")
def load_tool():
    """``load_tool(name)``: the module of the script ``tools/<name>.py`` (tools/ is not a package)."""
    from importlib import util

    tools = Path(__file__).resolve().parents[1] / "tools"

    def load(name: str):
        spec = util.spec_from_file_location(name, tools / f"{name}.py")
        module = util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module

    return load


@pytest.fixture(scope="session")
def compile_cache(tmp_path_factory) -> Path:
    """The compiler's decomposition cache (its files are written atomically, so processes share it)."""
    with shared_dir(tmp_path_factory, "compile_cache") as path:
        return path


@pytest.fixture(scope="session")
def real_source() -> Path:
    if not (REAL_SOURCE / "mobility.urdf").is_file():
        pytest.skip(f"real data missing: no PartNet-Mobility sample at {REAL_SOURCE} (../shared/partnet-sample)")
    return REAL_SOURCE


@pytest.fixture(scope="session")
def real_cabinet(real_source, tmp_path_factory, compile_cache) -> Compiled:
    from opend_mj.assets.compiler import compile_cabinet

    with shared_dir(tmp_path_factory, "real_cabinets") as out:  # "cached": another process built it
        result = compile_cabinet(real_source, out, cache_dir=compile_cache)
    assert result.status in ("built", "cached"), f"{REAL_ID} was not built: {result.reason}: {result.message}"
    return Compiled(REAL_ID, real_source, out / REAL_ID, result.info)


@pytest.fixture(scope="session")
def proc_sources(tmp_path_factory) -> list[Path]:
    from opend_mj.assets.procedural import generate_sources

    return generate_sources(N_PROC_SOURCES, 0, tmp_path_factory.mktemp("proc_sources"), progress=False)


@pytest.fixture(scope="session")
def proc_cabinets(proc_sources, tmp_path_factory, compile_cache) -> list[Compiled]:
    """The first few procedural sources that compile, covering drawers and double doors."""
    from opend_mj.assets.compiler import compile_cabinet

    chosen: list[Compiled] = []
    with shared_dir(tmp_path_factory, "proc_cabinets") as out:  # "cached": another process built them
        for source in proc_sources:
            meta = json.loads((source / "meta.json").read_text())["procedural"]
            if not meta["describable"]:
                continue
            result = compile_cabinet(source, out, cache_dir=compile_cache)
            assert result.status in ("built", "cached"), \
                f"{source.name} ({meta['layout']}): {result.reason}: {result.message}"
            chosen.append(Compiled(source.name, source, out / source.name, result.info))
            kinds = [t["type"] for c in chosen for t in c.info["targets"]]
            doubles = [c for c in chosen if [t["type"] for t in c.info["targets"]].count("door") >= 2]
            if len(chosen) >= N_PROC_CABINETS and "drawer" in kinds and doubles:
                break
    kinds = [t["type"] for c in chosen for t in c.info["targets"]]
    doubles = [c for c in chosen if [t["type"] for t in c.info["targets"]].count("door") >= 2]
    assert len(chosen) >= N_PROC_CABINETS, "too few describable procedural cabinets"
    assert "drawer" in kinds and doubles, (f"the first {N_PROC_SOURCES} procedural sources hold no drawer or no "
                                          "double door among the describable ones: raise N_PROC_SOURCES")
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

    from opend_mj.assets.layout import MANIFEST

    with shared_dir(tmp_path_factory, "small_dataset") as out:  # built by the first process to need it
        if not (out / MANIFEST).is_file():
            build_dataset(proc_sources[:12], out, workers=1, progress=False, log=lambda *a: None)
    return out


# Synthetic views for perception and solver tests (no rendering): a camera and depth images of a
# cabinet front seen by it.


@pytest.fixture
def front_view():
    """A camera at x = -2 looking along +x (right = -y, up = +z, backward = -x), 256 x 256, 45 degrees."""
    import numpy as np

    from opend_mj.sim.camera import CameraIntrinsics, CameraView

    rot = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    return CameraView(CameraIntrinsics.from_fovy(45, 256, 256), pos=np.array([-2.0, 0.0, 1.0]), rot=rot)


@pytest.fixture
def cabinet_depth():
    """A wall 1 m behind a cabinet front (2 m away, image columns 40-216, rows 40-216) with two bars
    3 cm proud of it: a horizontal one at the top left, a vertical one at the bottom right."""
    import numpy as np

    depth = np.full((256, 256), 3.0, np.float32)
    depth[40:216, 40:216] = 2.0
    depth[70:74, 60:110] = 1.97
    depth[150:190, 180:184] = 1.97
    return depth


@pytest.fixture
def thin_pulls_depth():
    """A cabinet front 2 m away with three drawer pulls in a column: the top one 3 cm proud, the
    middle and bottom ones 5 mm proud (thin pulls, like real 7 mm bars 4.5 mm off a front), and a
    rail 5 mm proud along the whole top of the front (0.8 m; no pull)."""
    import numpy as np

    depth = np.full((256, 256), 3.0, np.float32)
    depth[40:216, 40:216] = 2.0
    depth[70:73, 100:150] = 1.97
    depth[120:122, 100:150] = 1.995
    depth[170:172, 100:150] = 1.995
    depth[46:48, 44:212] = 1.995
    return depth
