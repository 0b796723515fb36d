"""`opend run --policy`: any agent on the benchmark's episodes; one run per results file."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from opend_mj.cli import main
from opend_mj.evaluation.episode import episode_key
from opend_mj.evaluation.results import load_results

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "random_agent.py"


def _run_args(dataset, out, *extra):
    return ["run", "--cabinets", str(dataset), "--split", "all", "--hand", "franka", "--limit", "3",
            "--out", str(out), *extra]


def test_planner_as_an_agent_gives_the_planners_record(small_dataset):
    """The planner behind the agent interface (observations in, one action per step out) does what
    `opend run` does with the same handle box, to the bit."""
    from opend_mj.evaluation.agents import run_agent_episode
    from opend_mj.evaluation.jobs import make_jobs
    from opend_mj.evaluation.runner import make_episode_env, run_episode
    from opend_mj.policy.agents import PlannerAgent
    from opend_mj.policy.solvers import OracleSolver

    job = next(j for j in make_jobs(small_dataset, ["franka"], "oracle", split="all") if j.target_type == "drawer")
    reference = run_episode(job)
    env = make_episode_env(job)
    try:
        agent = PlannerAgent(solver=OracleSolver(lambda: env.task.handle_boxes(env.physics)[env.task.target.joint]))
        record = run_agent_episode(job, env, agent)
    finally:
        env.close()
    assert reference["success"]
    for key in ("success", "open_ratio", "joint_value", "others_moved", "sim_seconds", "max_penetration_mm", "box",
                "pulled"):
        assert record[key] == reference[key], key
    assert record["agent_stopped"] and record["failed_stage"] is None


def test_planner_agent_refuses_ground_truth_solvers():
    from opend_mj.policy.agents import PlannerAgent

    with pytest.raises(ValueError, match="ground truth"):
        PlannerAgent(solver="oracle")


def test_opend_run_policy_with_the_example_agent(small_dataset, tmp_path):
    out = tmp_path / "random.jsonl"
    args = _run_args(small_dataset, out, "--policy", str(EXAMPLE), "--policy-arg", "seconds=0.5")
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    records = load_results(out)
    assert len(records) == 3 and len({episode_key(r) for r in records}) == 3
    for r in records:
        assert r["solver"] == "random" and "error" not in r, r.get("error_reason")
        assert r["steps"] == 30 and r["agent_stopped"] and r["sim_seconds"] == pytest.approx(0.5)
        assert r["success"] is False and r["failed_stage"] in ("approach", "grasp", "pull")
        for field in ("cabinet", "joint", "target_type", "instruction", "hand", "split", "seed", "open_ratio",
                      "others_moved", "room", "policy", "wall_seconds"):
            assert field in r, field
    # scoreable, ranked with the others
    score = CliRunner().invoke(main, ["score", str(out)])
    assert score.exit_code == 0 and "| 1 | random | franka |" in score.output
    # resumable: a second run does nothing
    again = CliRunner().invoke(main, args)
    assert again.exit_code == 0 and "0 episodes run, 3 already done" in again.output


def test_bad_policies_are_usage_errors(small_dataset, tmp_path):
    out = tmp_path / "r.jsonl"
    cases = [(["--policy", "no_such_module:Agent"], "cannot import"),
             (["--policy", str(tmp_path / "missing.py")], "not found"),
             (["--policy", f"{EXAMPLE}:NoSuchClass"], "has no 'NoSuchClass'"),
             (["--policy", str(EXAMPLE), "--solver", "cliport"], "exclude each other"),
             (["--policy-arg", "x=1"], "--policy-arg needs --policy"),
             (["--policy", str(EXAMPLE), "--policy-arg", "oops"], "key=value")]
    for extra, message in cases:
        result = CliRunner().invoke(main, _run_args(small_dataset, out, *extra))
        assert result.exit_code == 2, (extra, result.output)
        assert message in result.output, (extra, result.output)
    assert not out.exists()


def test_a_second_run_on_the_same_file_is_refused(small_dataset, tmp_path):
    from opend_mj.evaluation.lock import ResultsLock, ResultsLocked

    out = tmp_path / "r.jsonl"
    with ResultsLock(out):
        result = CliRunner().invoke(main, _run_args(small_dataset, out, "--policy", str(EXAMPLE),
                                                    "--policy-arg", "seconds=0.2"))
        assert result.exit_code == 2
        assert "being written by another run" in result.output and f"pid {os.getpid()}" in result.output
        with pytest.raises(ResultsLocked):
            ResultsLock(out).acquire()
    assert not out.exists()
    with ResultsLock(out):  # released: it can be taken again
        pass


def _spawn(dataset, out, *extra) -> subprocess.Popen:
    env = {**os.environ, "MUJOCO_GL": "egl", "PYTHONPATH": str(ROOT / "src")}
    return subprocess.Popen([sys.executable, "-m", "opend_mj.cli", *_run_args(dataset, out, *extra)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


@pytest.mark.slow
def test_concurrent_runs_write_each_episode_once(small_dataset, tmp_path):
    """Two `opend run` on one file at the same time: the second is refused (or, with --wait, waits
    and then finds every episode done); the file holds each episode once."""
    from opend_mj.evaluation.lock import ResultsLock, ResultsLocked, lock_path

    out = tmp_path / "r.jsonl"
    agent = ["--policy", str(EXAMPLE)]  # the whole 15 s time limit per episode
    first = _spawn(small_dataset, out, *agent)
    deadline = time.time() + 300
    while time.time() < deadline and first.poll() is None:  # until the first run holds the file
        if lock_path(out).exists() and f'"pid": {first.pid}' in lock_path(out).read_text():
            break
        time.sleep(0.05)
    assert first.poll() is None, first.communicate()[0]
    with pytest.raises(ResultsLocked, match=f"pid {first.pid}"):
        ResultsLock(out).acquire()
    second = _spawn(small_dataset, out, *agent)
    waiting = _spawn(small_dataset, out, *agent, "--wait")
    outputs = [p.communicate(timeout=600)[0] for p in (first, second, waiting)]
    assert first.returncode == 0, outputs[0]
    assert second.returncode in (0, 2), outputs[1]  # 2: refused; 0: it started after the first ended
    if second.returncode == 2:
        assert "being written by another run" in outputs[1]
    assert waiting.returncode == 0, outputs[2]
    assert "3 episodes run" in outputs[0]
    records = load_results(out)
    keys = [episode_key(r) for r in records]
    assert len(keys) == len(set(keys)) == 3
    assert len(out.read_text().splitlines()) == 3


def test_the_final_sort_never_drops_a_line_written_meanwhile(tmp_path, monkeypatch):
    from opend_mj.evaluation import results
    from opend_mj.evaluation.episode import EpisodeJob

    jobs = [EpisodeJob(cabinet="c", cabinet_dir="d", joint=f"j{i}", split="test", hand="h", solver="s")
            for i in range(3)]
    out = tmp_path / "r.jsonl"
    with results.ResultsWriter(out) as w:
        for job in reversed(jobs):
            w.write({**job.record_fields(), "success": True})
    foreign = json.dumps({"cabinet": "x", "joint": "k", "hand": "h", "solver": "other", "seed": 0}) + "\n"
    stamp, calls = results._stamp, []

    def stamp_with_a_write_meanwhile(path):
        calls.append(path)
        if len(calls) == 2:  # after the sorted copy is written, before it replaces the file
            with open(path, "a") as f:
                f.write(foreign)
        return stamp(path)

    monkeypatch.setattr(results, "_stamp", stamp_with_a_write_meanwhile)
    assert results.sort_results(out, jobs)
    lines = out.read_text().splitlines()
    assert foreign.strip() in lines and len(lines) == 4
    assert [json.loads(ln)["joint"] for ln in lines] == ["k", "j0", "j1", "j2"]


class _FirstLook:
    """An agent that keeps the depth of its first observation and stops."""

    name = "first-look"

    def reset(self, episode):
        self.depth = None

    def act(self, obs):
        self.depth = obs["depth"]
        return None


def test_an_agents_first_depth_under_a_sensor_fuses_the_still_frames(small_dataset):
    """Under depth_noise the first observation, of the still scene, is the planner's fused image:
    fewer holes and less noise than one sensor frame of the same render, and nominal is exact."""
    from dataclasses import replace

    from opend_mj.evaluation.agents import run_agent_episode
    from opend_mj.evaluation.jobs import make_jobs
    from opend_mj.evaluation.runner import make_episode_env
    from opend_mj.sim.envs import SceneReader

    job = make_jobs(small_dataset, ["franka"], "oracle", split="all")[0]
    looks = {}
    for perturb in (None, "depth_noise=strong"):
        noisy_job = replace(job, perturb=perturb)
        env = make_episode_env(noisy_job)
        try:
            agent = _FirstLook()
            run_agent_episode(noisy_job, env, agent)
            env.reset()
            reader = SceneReader(env, env.task.config.image_size)
            try:
                single = reader.render()[1]
            finally:
                reader.close()
        finally:
            env.close()
        looks[perturb] = (agent.depth, single)
    exact, single_exact = looks[None]
    assert np.array_equal(exact, single_exact)
    fused, single = looks["depth_noise=strong"]
    seen = exact > 0
    assert (fused[seen] == 0).mean() < 0.5 * (single[seen] == 0).mean()
    both = seen & (fused > 0) & (single > 0)
    assert np.median(np.abs(fused - exact)[both]) < 0.6 * np.median(np.abs(single - exact)[both])
