"""The results file is resumable: torn last lines are dropped, reruns neither lose nor repeat episodes."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from opend_mj.evaluation.episode import episode_key, EpisodeJob
from opend_mj.evaluation.pool import run_jobs
from opend_mj.evaluation.results import load_results, ResultsWriter


def _jobs(cab: Path, joints, seed=0, **kw):
    return [EpisodeJob(cabinet=cab.name, cabinet_dir=str(cab), joint=j, split="train", hand="franka",
                       solver="oracle", seed=seed, use_grasp_file=False, **kw) for j in joints]


def test_torn_last_line_is_dropped_and_truncated(tmp_path):
    path = tmp_path / "r.jsonl"
    with ResultsWriter(path) as w:
        w.write({"cabinet": "a", "joint": "j", "hand": "h", "solver": "s", "seed": 0, "success": True})
        w.write({"cabinet": "b", "joint": "j", "hand": "h", "solver": "s", "seed": 0, "success": False})
    good = path.read_bytes()
    with open(path, "ab") as f:
        f.write(b'{"cabinet": "c", "joint": "j", "ha')  # killed mid-write
    recs = load_results(path)
    assert [r["cabinet"] for r in recs] == ["a", "b"]
    assert path.read_bytes() == good  # truncated back to the last full line


def test_resume_after_interruption(tmp_path, drawer_cabinet):
    out = tmp_path / "results.jsonl"
    first = _jobs(drawer_cabinet, ["joint_0"])
    counts = run_jobs(first, out, workers=1, progress=False)
    assert counts["ran"] == 1
    # simulate a kill -9 while the parent was writing the next line
    with open(out, "ab") as f:
        f.write(f'{{"cabinet": "{drawer_cabinet.name}", "joint": "joint_1", "hand": "franka", "solv'.encode())
    everything = _jobs(drawer_cabinet, ["joint_0", "joint_1"])
    counts = run_jobs(everything, out, workers=1, progress=False)
    assert counts == {"total": 2, "skipped": 1, "ran": 1, "errors": 0, "success": counts["success"]}
    recs = load_results(out)
    keys = [episode_key(r) for r in recs]
    assert len(keys) == len(set(keys)) == 2
    assert {r["joint"] for r in recs} == {"joint_0", "joint_1"}
    for line in out.read_text().splitlines():
        json.loads(line)
    r = recs[0]
    for field in ("cabinet", "joint", "target_type", "instruction", "hand", "solver", "split", "seed", "success",
                  "open_ratio", "joint_value", "range_ratio", "others_moved", "failed_stage", "sim_seconds",
                  "wall_seconds", "room", "light_scale", "pull"):
        assert field in r, field
    # a third run does nothing
    assert run_jobs(everything, out, workers=1, progress=False)["ran"] == 0


def test_errors_are_recorded_and_the_pool_goes_on(tmp_path, drawer_cabinet):
    """Two spawn workers; episodes on a missing cabinet become error lines, the rest still run."""
    out = tmp_path / "results.jsonl"
    bad = [EpisodeJob(cabinet="missing", cabinet_dir=str(tmp_path / "missing"), joint=f"joint_{i}", split="test",
                      hand="franka", solver="oracle") for i in range(3)]
    counts = run_jobs(bad, out, workers=2, progress=False)
    assert counts["ran"] == 3 and counts["errors"] == 3
    recs = load_results(out)
    assert all("Traceback" in r["error"] and r["success"] is False for r in recs)
    assert len({episode_key(r) for r in recs}) == 3


def test_episodes_sharing_a_scene_give_the_records_of_separate_scenes(drawer_cabinet):
    """`opend run` builds one scene per cabinet and hand; each episode's record must not change."""
    from opend_mj.evaluation.episode import strip_wall_clock
    from opend_mj.evaluation.jobs import group_jobs
    from opend_mj.evaluation.runner import run_episode, run_episode_group

    joints = [t["joint"] for t in json.loads((drawer_cabinet / "cabinet.json").read_text())["targets"]][:2]
    jobs = _jobs(drawer_cabinet, joints)
    groups = group_jobs(jobs)
    assert [len(g) for g in groups] == [len(jobs)]
    shared = run_episode_group(groups[0])
    separate = [run_episode(j) for j in jobs]
    assert [strip_wall_clock(r) for r in shared] == [strip_wall_clock(r) for r in separate]
    assert any(r["success"] for r in shared)


def test_a_coarser_physics_timestep_is_recorded_and_keyed_apart(drawer_cabinet, tmp_path):
    """`--physics-timestep 1/120`: the episode runs (4x fewer substeps), says so, and resumes apart."""
    from opend_mj.evaluation.runner import run_episode

    joint = json.loads((drawer_cabinet / "cabinet.json").read_text())["targets"][0]["joint"]
    default, coarse = _jobs(drawer_cabinet, [joint]) + _jobs(drawer_cabinet, [joint], physics_timestep=1 / 120)
    rec = run_episode(coarse)
    assert rec["physics_timestep"] == pytest.approx(1 / 120)
    assert rec["success"] and not rec["physics_warnings"]
    assert episode_key(rec) == coarse.key() != default.key()


def test_a_runs_cabinets_stand_in_rooms_the_seed_and_cabinet_draw(tmp_path):
    """Each cabinet of a run gets its own scene from (seed, cabinet): the run covers several rooms,
    a cabinet's targets and hands share one, and the same seed gives the same rooms again."""
    from opend_mj.evaluation.episode import scene_seed
    from opend_mj.sim.task import EpisodeSpec

    def room(cabinet, joint="joint_0", hand="franka", seed=0):
        job = EpisodeJob(cabinet=cabinet, cabinet_dir=str(tmp_path / cabinet), joint=joint, split="test",
                         hand=hand, solver="oracle", seed=seed)
        return EpisodeSpec(Path(job.cabinet_dir), joint, hand, seed=scene_seed(job)).room_index()

    cabinets = [f"proc_{i:04d}" for i in range(40)]
    rooms = [room(c) for c in cabinets]
    assert len(set(rooms)) >= 6  # of nine: one seed no longer means one room
    assert rooms == [room(c) for c in cabinets]
    assert all(room(c, "joint_3", "shadow") == r for c, r in zip(cabinets, rooms))
    assert [room(c, seed=1) for c in cabinets] != rooms


def test_opend_run_with_several_seeds_runs_each_episode_in_each_draw(small_dataset, tmp_path):
    """`opend run --seed 0 --seed 1`: every episode once per seed (its own record and key), and a
    second call resumes with nothing left to run."""
    from click.testing import CliRunner

    from opend_mj.cli import main

    out = tmp_path / "r.jsonl"
    args = ["run", "--cabinets", str(small_dataset), "--split", "all", "--hand", "franka", "--limit", "1",
            "--seed", "0", "--seed", "1", "--workers", "1", "--out", str(out)]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    records = load_results(out)
    assert sorted(r["seed"] for r in records) == [0, 1]
    assert len({episode_key(r) for r in records}) == 2 and all("room" in r for r in records)
    again = CliRunner().invoke(main, args)
    assert again.exit_code == 0, again.output
    assert len(load_results(out)) == 2


def test_make_jobs_keeps_the_named_targets_or_kind_and_refuses_an_unknown_one(small_dataset):
    """`opend run --target ID[:JOINT]` reruns chosen cabinets or single targets (e.g. an earlier
    run's failures); a target the split does not hold is a clear error, not an empty run."""
    from opend_mj.assets.layout import load_manifest
    from opend_mj.evaluation.jobs import make_jobs

    pairs = load_manifest(small_dataset).targets("all")
    (c0, t0), (c1, _) = pairs[0], next(p for p in pairs if p[0]["id"] != pairs[0][0]["id"])
    jobs = make_jobs(small_dataset, ["franka"], "oracle", split="all",
                     targets=[f"{c0['id']}:{t0['joint']}", c1["id"]])
    n1 = sum(c["id"] == c1["id"] for c, _ in pairs)
    assert [(j.cabinet, j.joint) for j in jobs][0] == (c0["id"], t0["joint"])
    assert len(jobs) == 1 + n1 and {j.cabinet for j in jobs} == {c0["id"], c1["id"]}
    with pytest.raises(ValueError, match="no target nope:joint_9"):
        make_jobs(small_dataset, ["franka"], "oracle", split="all", targets=["nope:joint_9"])
    # --kind: only drawers (or doors), in manifest order, before --limit
    for kind in ("drawer", "door"):
        of_kind = [(c["id"], t["joint"]) for c, t in pairs if t["type"] == kind]
        assert of_kind and [(j.cabinet, j.joint) for j in make_jobs(small_dataset, ["franka"], "oracle", split="all",
                                                                    kind=kind)] == of_kind
        limited = make_jobs(small_dataset, ["franka"], "oracle", split="all", kind=kind, limit=1)
        assert [(j.cabinet, j.joint, j.target_type) for j in limited] == [(*of_kind[0], kind)]
