"""The Ray backend gives the same results as the local process pool (on a local Ray instance).

One local Ray instance (2 CPUs, no dashboard) is started for the module; `run_jobs`, `build_dataset`
and the CLI find it initialised and use it without starting or stopping another. Skipped, with the
reason, where Ray is not installed or cannot start here.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from opend_mj.cli import main
from opend_mj.evaluation.episode import episode_key, strip_wall_clock
from opend_mj.evaluation.jobs import make_jobs

HAND = "franka"


@pytest.fixture(scope="module")
def ray_instance():
    from opend_mj.backends import BackendError, RayBackend

    try:
        backend = RayBackend(workers=2)
    except BackendError as exc:
        pytest.skip(f"Ray cannot start here: {exc}")
    yield backend
    backend.close()


@pytest.fixture(scope="module")
def sources(tmp_path_factory) -> list[Path]:
    """Three generated cabinets (seed 0): one drawer, a stack of three drawers, one side-hinged door."""
    from opend_mj.assets.procedural import find_cabinets, write_source

    def first(where):
        return find_cabinets(where)[0]

    root = tmp_path_factory.mktemp("ray_sources")
    return [write_source(c, root) for c in (
        first(lambda c: len(c.targets) == 1 and c.targets[0].kind == "drawer"),
        first(lambda c: len(c.targets) == 3 and all(t.kind == "drawer" for t in c.targets)),
        first(lambda c: len(c.targets) == 1 and c.targets[0].hinge in ("left", "right")))]


@pytest.fixture(scope="module")
def dataset(sources, tmp_path_factory) -> Path:
    from opend_mj.assets.dataset import build_dataset

    out = tmp_path_factory.mktemp("ray_cabinets")
    build_dataset(sources[:2], out, workers=1, progress=False, log=lambda *a: None)
    return out


def _records(path: Path) -> list[dict]:
    recs = [json.loads(line) for line in path.read_text().splitlines()]
    return sorted((strip_wall_clock(r) for r in recs), key=episode_key)


@pytest.mark.slow
def test_ray_run_matches_the_process_pool(ray_instance, dataset, tmp_path):
    common = ["run", "--hand", HAND, "--split", "all", "--limit", "3", "--seed", "1", "--cabinets", str(dataset)]
    pool, ray_out = tmp_path / "pool.jsonl", tmp_path / "ray.jsonl"
    r1 = CliRunner().invoke(main, [*common, "--workers", "2", "--out", str(pool)])
    assert r1.exit_code == 0, r1.output
    r2 = CliRunner().invoke(main, [*common, "--backend", "ray", "--out", str(ray_out)])
    assert r2.exit_code == 0, r2.output
    assert "3 episodes run, 0 already done, 0 errors" in r2.output
    a, b = _records(pool), _records(ray_out)
    assert len(a) == 3 and a == b
    # same file order too (job order), and a rerun on Ray resumes: nothing to do
    jobs = make_jobs(dataset, [HAND], "oracle", split="all", limit=3, seed=1)
    assert [episode_key(json.loads(line)) for line in ray_out.read_text().splitlines()] == [j.key() for j in jobs]
    r3 = CliRunner().invoke(main, [*common, "--backend", "ray", "--out", str(ray_out)])
    assert r3.exit_code == 0 and "0 episodes run, 3 already done" in r3.output


def test_ray_workers_get_egl(ray_instance):
    import os

    def gl(_):
        return os.environ.get("MUJOCO_GL")

    assert [r for _, r, e in ray_instance.imap_unordered(gl, [0, 1])] == ["egl", "egl"]


def test_ray_errors_are_records(ray_instance, tmp_path):
    from opend_mj.evaluation.episode import EpisodeJob
    from opend_mj.evaluation.pool import run_jobs
    from opend_mj.evaluation.results import load_results

    bad = [EpisodeJob(cabinet="missing", cabinet_dir=str(tmp_path / "missing"), joint="joint_0", split="test",
                      hand=HAND, solver="oracle")]
    counts = run_jobs(bad, tmp_path / "r.jsonl", backend="ray", progress=False)
    assert counts["errors"] == 1
    (rec,) = load_results(tmp_path / "r.jsonl")
    assert "cabinet.json" in rec["error_reason"]


@pytest.mark.slow
def test_build_dataset_on_ray_matches_local(ray_instance, sources, tmp_path):
    from opend_mj.assets.dataset import build_dataset

    local = build_dataset(sources, tmp_path / "local", workers=1, progress=False, log=lambda *a: None)
    on_ray = build_dataset(sources, tmp_path / "ray", backend="ray", progress=False, log=lambda *a: None)
    assert on_ray.cabinets == local.cabinets and on_ray.rejected == local.rejected
    assert on_ray.info["built"] + len(on_ray.rejected) == len(sources) and on_ray.info["cached"] == 0
    for c in on_ray.cabinets:
        assert (tmp_path / "ray" / c["id"] / "cabinet.xml").read_bytes() == \
               (tmp_path / "local" / c["id"] / "cabinet.xml").read_bytes()
