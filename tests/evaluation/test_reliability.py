"""Reliability of `opend run`: kill -9 and resume, corrupt cabinets, faulty actions, unstable physics,
bad arguments, and determinism across worker counts.

Results file order: records are appended in completion order while a run goes on; once every job
of the run is in the file, `run_jobs` rewrites it atomically in job order. So the same command and
seed give the same file, line for line, whatever `--workers`, apart from `wall_seconds`.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from opend_mj.cli import main
from opend_mj.evaluation.episode import episode_key, EpisodeJob, strip_wall_clock, WALL_CLOCK_FIELDS
from opend_mj.evaluation.jobs import make_jobs
from opend_mj.evaluation.pool import run_jobs
from opend_mj.evaluation.results import load_results

HAND = "franka"  # the quickest hand


def _first(where):
    from opend_mj.assets.procedural import find_cabinets

    return find_cabinets(where)[0]


#: three generated cabinets (seed 0): four side-hinged doors, one drawer, a stack of three drawers
DOORS = _first(lambda c: len(c.targets) == 4 and all(t.kind == "door" and t.hinge in ("left", "right")
                                                      for t in c.targets))
DRAWER = _first(lambda c: len(c.targets) == 1 and c.targets[0].kind == "drawer")
STACK = _first(lambda c: len(c.targets) == 3 and all(t.kind == "drawer" for t in c.targets))


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    """Three procedural cabinets (4 doors, 4 drawers) with a manifest, built once for this module."""
    from opend_mj.assets.dataset import build_dataset
    from opend_mj.assets.procedural import write_source

    root = tmp_path_factory.mktemp("reliability")
    cabinets = sorted((DOORS, DRAWER, STACK), key=lambda c: c.index)
    sources = [write_source(c, root / "src") for c in cabinets]
    manifest = build_dataset(sources, root / "cabinets", workers=1, progress=False, log=lambda *a: None)
    assert [c["id"] for c in manifest.cabinets] == [c.id for c in cabinets]
    return root / "cabinets"


def _subset(dataset: Path, dest: Path, ids: list[str]) -> Path:
    """A copy of the dataset with only some cabinets."""
    dest.mkdir(parents=True)
    data = json.loads((dataset / "manifest.json").read_text())
    data["cabinets"] = [c for c in data["cabinets"] if c["id"] in ids]
    for c in data["cabinets"]:
        shutil.copytree(dataset / c["id"], dest / c["id"])
    (dest / "manifest.json").write_text(json.dumps(data))
    return dest


def _lines(path: Path) -> list[dict]:
    raw = path.read_bytes()
    assert raw.endswith(b"\n")
    return [json.loads(line) for line in raw.decode().splitlines()]  # every line parses


def _opend(*args) -> list[str]:
    return [sys.executable, "-m", "opend_mj.cli", *map(str, args)]


# --------------------------------------------------------------------------------------------------
# kill -9 and resume
# --------------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_kill_9_then_resume(dataset, tmp_path):
    out = tmp_path / "results.jsonl"
    cmd = _opend("run", "--hand", HAND, "--split", "all", "--cabinets", dataset, "--limit", 6, "--workers", 1,
                 "--out", out)
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(cmd, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            if out.exists() and out.read_bytes().count(b"\n") >= 1:
                break
            time.sleep(0.05)
        assert proc.poll() is None, f"run ended before it could be killed: {proc.stderr.read().decode()[-2000:]}"
        os.killpg(proc.pid, signal.SIGKILL)  # the whole group: parent and any pool workers
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
        proc.stderr.close()
    assert proc.returncode == -signal.SIGKILL
    before = load_results(out)  # repairs a torn last line if the kill hit a write
    assert 1 <= len(before) < 6
    # and a torn line written by hand (as if killed in the middle of a write) is repaired too
    with open(out, "ab") as f:
        f.write(f'{{"cabinet": "{STACK.id}", "joint": "joint_0", "hand": "fr'.encode())
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert f"{6 - len(before)} episodes run, {len(before)} already done" in done.stdout
    recs = _lines(out)
    keys = [episode_key(r) for r in recs]
    assert len(keys) == len(set(keys)) == 6  # none lost, none repeated
    expected = [j.key() for j in make_jobs(dataset, [HAND], "oracle", split="all", limit=6)]
    assert keys == expected  # the finished file is in job order
    assert all("error" not in r for r in recs), [r.get("error_reason") for r in recs]


def test_torn_line_repaired_on_resume(dataset, tmp_path):
    """A torn last line (no newline, half a JSON object) is cut away before new lines are appended."""
    out = tmp_path / "results.jsonl"
    out.write_bytes(f'{{"cabinet": "{DRAWER.id}", "joint": "joint_0", "ha'.encode())
    assert load_results(out, repair=False) == []
    jobs = make_jobs(dataset, [HAND], "oracle", split="all", cabinet_ids=[DRAWER.id])
    assert run_jobs(jobs, out, progress=False)["ran"] == 1
    recs = _lines(out)
    assert len(recs) == 1 and recs[0]["cabinet"] == DRAWER.id


# --------------------------------------------------------------------------------------------------
# corrupt cabinets
# --------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("broken_file", ["cabinet.xml", "cabinet.json", "meshes"])
def test_corrupt_cabinet_is_reported_and_skipped(dataset, tmp_path, broken_file):
    data = _subset(dataset, tmp_path / "cabinets", [DRAWER.id, STACK.id])
    bad = data / STACK.id
    if broken_file == "meshes":  # well-formed XML naming missing files: found by the worker
        shutil.rmtree(bad / "meshes")
    else:  # truncated: found by the parent's check
        path = bad / broken_file
        path.write_bytes(path.read_bytes()[: len(path.read_bytes()) // 2])
    out = tmp_path / "results.jsonl"
    result = CliRunner().invoke(main, ["run", "--hand", HAND, "--split", "all", "--cabinets", str(data),
                                       "--out", str(out), "--workers", "1"])
    assert result.exit_code == 0, result.output
    assert "4 episodes run, 0 already done, 3 errors, 1 successes" in result.output
    recs = _lines(out)
    errors = [r for r in recs if "error" in r]
    assert {r["cabinet"] for r in errors} == {STACK.id} and len(errors) == 3
    file_named = "cabinet.xml" if broken_file == "meshes" else broken_file
    for r in errors:
        assert r["success"] is False and r["error_kind"] == "cabinet"
        assert "CabinetError" in r["error_reason"] and f"{STACK.id}/{file_named}" in r["error_reason"]
    good = [r for r in recs if "error" not in r]
    assert [r["cabinet"] for r in good] == [DRAWER.id] and good[0]["success"]


def test_every_episode_an_error_exits_1(dataset, tmp_path):
    data = _subset(dataset, tmp_path / "cabinets", [DRAWER.id])
    (data / DRAWER.id / "cabinet.json").write_text("{")
    out = tmp_path / "results.jsonl"
    result = CliRunner().invoke(main, ["run", "--hand", HAND, "--split", "all", "--cabinets", str(data),
                                       "--out", str(out)])
    assert result.exit_code == 1, result.output
    assert "every episode failed" in result.output
    assert f"{DRAWER.id}/cabinet.json" in _lines(out)[0]["error_reason"]


# --------------------------------------------------------------------------------------------------
# faulty actions, unstable physics
# --------------------------------------------------------------------------------------------------
def _env(cabinet_dir: Path, joint="joint_0"):
    from opend_mj.sim.task import EpisodeSpec, TaskConfig, make_environment

    env = make_environment(EpisodeSpec(cabinet_dir=cabinet_dir, target_joint=joint, hand=HAND, seed=0),
                           TaskConfig(enable_rgbd=False, time_limit=1e6))
    env.reset()
    task = env.task
    pos, quat = task.start_pose
    return env, task.make_action(pos, quat, task.hand.spec.open_pose)


def test_non_finite_action_raises_at_the_task_level(dataset):
    """Out-of-range actions are clipped (root to the workspace, fingers to ctrlrange); NaN/inf raise."""
    env, action = _env(dataset / STACK.id)
    for bad in (np.nan, np.inf):
        faulty = action.copy()
        faulty[0] = bad
        with pytest.raises(ValueError, match="non-finite"):
            env.step(faulty)
    with pytest.raises(ValueError, match="shape"):
        env.step(action[:-1])
    far = action.copy()
    far[:3] += 1e6  # far outside the workspace: clipped, the episode goes on
    far[7:] = 1e6
    ts = env.step(far)
    assert not ts.last() and env.task.physics_warnings == []
    assert np.all(np.isfinite(env.physics.data.qpos))


def test_non_finite_action_is_an_error_record_and_the_run_goes_on(dataset, tmp_path, monkeypatch):
    """A planner that sends NaN (injected here) ends its episode as an error; the next one runs."""
    from opend_mj.sim.task import OpenCabinetTask

    make_action = OpenCabinetTask.make_action

    def faulty(self, root_pos, root_quat, fingers):
        action = make_action(self, root_pos, root_quat, fingers)
        if self.target.joint == "joint_0":
            action[7:] = np.nan
        return action

    monkeypatch.setattr(OpenCabinetTask, "make_action", faulty)
    jobs = make_jobs(dataset, [HAND], "oracle", split="all", cabinet_ids=[STACK.id])[:2]
    out = tmp_path / "results.jsonl"
    counts = run_jobs(jobs, out, workers=1, progress=False)
    assert counts["ran"] == 2 and counts["errors"] == 1
    first, second = _lines(out)
    assert first["joint"] == "joint_0" and first["success"] is False
    assert "non-finite" in first["error_reason"] and first["error_kind"] == "action"
    assert second["joint"] == "joint_1" and "error" not in second and second["success"]


def test_physics_instability_is_recorded(dataset, tmp_path, monkeypatch):
    """Task level: a huge joint velocity raises BADQVEL, recorded in task.physics_warnings, episode over.
    Evaluation level: the episode's line has failed_stage "physics" and the warnings."""
    env, action = _env(dataset / STACK.id)
    physics = env.physics
    dof = physics.model.jnt_dofadr[physics.model.name2id("cabinet/joint_0", "joint")]
    physics.data.qvel[dof] = 1e12
    ts = env.step(action)
    assert ts.last()
    assert env.task.physics_warnings and "mjWARN_BADQVEL" in env.task.physics_warnings[0]["warnings"]

    from opend_mj.sim.task import OpenCabinetTask

    before_step = OpenCabinetTask.before_step
    calls = {"n": 0}

    def kick(self, physics, action, random_state):
        before_step(self, physics, action, random_state)
        calls["n"] += 1
        if calls["n"] == 10:
            physics.data.qvel[:] = 1e12

    monkeypatch.setattr(OpenCabinetTask, "before_step", kick)
    out = tmp_path / "results.jsonl"
    jobs = make_jobs(dataset, [HAND], "oracle", split="all", cabinet_ids=[STACK.id])[:1]
    assert run_jobs(jobs, out, workers=1, progress=False)["errors"] == 0
    (rec,) = _lines(out)
    assert rec["success"] is False and rec["failed_stage"] == "physics"
    assert rec["physics_warnings"] and rec["physics_warnings"][0]["warnings"]
    assert "physics instability" in rec["failure_reason"]


# --------------------------------------------------------------------------------------------------
# bad arguments: a clear message and exit status 2
# --------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("args, message", [
    (["run", "--hand", "nosuchhand"], "unknown hand 'nosuchhand'"),
    (["run", "--solver", "nosuchsolver"], "unknown handle solver"),
    (["run", "--split", "nosplit"], "nosplit"),
    (["run", "--workers", "0"], "--workers"),
    (["run", "--light-scale", "-1"], "--light-scale"),
    (["run", "--limit", "0"], "--limit"),
    (["run", "--cabinets", "/nonexistent"], "/nonexistent"),
    (["run", "--cabinets", "{tmp}"], "no manifest.json"),
    (["run", "--backend", "spark"], "spark"),
    (["run", "--address", "auto"], "--address needs --backend ray"),
    (["run", "--physics-timestep", "1/100"], "whole number of substeps"),
    (["run", "--physics-timestep", "zero"], "--physics-timestep"),
    (["build-assets", "--scale", "0"], "--scale"),
    (["build-assets", "--workers", "0"], "--workers"),
    (["build-assets", "--address", "auto", "--out", "{tmp}"], "--address needs --backend ray"),
    (["score", "missing.jsonl"], "missing.jsonl"),
])
def test_bad_arguments_exit_2(args, message, dataset, tmp_path):
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    if args[0] == "run" and "--cabinets" not in args:
        args += ["--cabinets", str(dataset), "--out", str(tmp_path / "r.jsonl")]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 2, result.output
    assert message in result.output, result.output
    assert not (tmp_path / "r.jsonl").exists()


# --------------------------------------------------------------------------------------------------
# determinism
# --------------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_same_seed_same_file_whatever_the_workers(dataset, tmp_path):
    """Two episodes, twice with one worker and once with two: the same lines in the same (job) order,
    apart from the wall-clock fields."""
    jobs = make_jobs(dataset, [HAND], "oracle", split="all", cabinet_ids=[DRAWER.id, STACK.id], seed=3)[:2]
    files = []
    for k, workers in enumerate((1, 1, 2)):
        out = tmp_path / f"r{k}.jsonl"
        assert run_jobs(jobs, out, workers=workers, progress=False)["ran"] == 2
        files.append(_lines(out))
    stripped = [[json.dumps(strip_wall_clock(r)) for r in recs] for recs in files]
    assert stripped[0] == stripped[1] == stripped[2]
    assert [episode_key(r) for r in files[2]] == [j.key() for j in jobs]
    assert all(f in r for recs in files for r in recs for f in WALL_CLOCK_FIELDS)
    assert all(r["seed"] == 3 and "error" not in r for r in files[0])


def test_sort_keeps_other_runs_first(tmp_path):
    """Records of another run sharing the file keep their place; this run's lines go in job order."""
    from opend_mj.evaluation.results import ResultsWriter, sort_results

    jobs = [EpisodeJob(cabinet="c", cabinet_dir="/x", joint=f"joint_{i}", split="test", hand="h", solver="s")
            for i in range(3)]
    other = {"cabinet": "z", "joint": "j", "hand": "h", "solver": "s", "seed": 0}
    out = tmp_path / "r.jsonl"
    with ResultsWriter(out) as w:
        for rec in (dict(other), *({"cabinet": "c", "joint": f"joint_{i}", "hand": "h", "solver": "s", "seed": 0}
                                   for i in (2, 0))):
            w.write(rec)
    assert not sort_results(out, jobs)  # joint_1 missing: an incomplete run is left alone
    with ResultsWriter(out) as w:
        w.write({"cabinet": "c", "joint": "joint_1", "hand": "h", "solver": "s", "seed": 0})
    assert sort_results(out, jobs)
    assert [r["joint"] for r in _lines(out)] == ["j", "joint_0", "joint_1", "joint_2"]
    assert not sort_results(out, jobs)  # already in order: not rewritten
    assert not list(tmp_path.glob(".*sorting"))


# --------------------------------------------------------------------------------------------------
# a pool worker that dies
# --------------------------------------------------------------------------------------------------
def _die_on_2(x: int) -> int:
    if x == 2:
        os._exit(9)  # as if killed (OOM killer, segfault)
    return x * 10


def test_a_dead_pool_worker_is_an_error_and_the_others_go_on():
    from opend_mj.backends import ProcessPoolBackend

    with ProcessPoolBackend(2, initializer=None) as ex:
        got = {item: (result, error) for item, result, error in ex.imap_unordered(_die_on_2, range(5))}
    assert sorted(got) == [0, 1, 2, 3, 4]
    assert all(got[i] == (10 * i, None) for i in (0, 1, 3, 4))
    assert got[2][0] is None and "died" in got[2][1]
    assert ex.restarts >= 2
