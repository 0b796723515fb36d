"""Agents that misbehave are contained: one whose `act` never returns is ended by the per-episode
wall-clock limit (`--episode-timeout`), one that ends its process costs that episode only (in its own
process, the default, and in the worker's with --agent-in-process); the run goes on and records each
with its reason. Bad input to any command is answered in one line."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest
from click.testing import CliRunner

from opend_mj.cli import main
from opend_mj.evaluation.results import load_results

#: stops at once (a normal, empty episode), except on the target whose instruction it is told to misbehave on
AGENT = textwrap.dedent('''
    import os
    import time


    class Agent:
        name = "misbehaving"
        control = "delta"
        images = "first"

        def __init__(self, on: str = "", how: str = "hang"):
            self.on, self.how = on, how

        def reset(self, episode) -> None:
            self.bad = episode.instruction == self.on

        def act(self, obs):
            if self.bad and self.how == "hang":
                while True:
                    try:
                        time.sleep(3600)
                    except Exception:  # an agent that swallows errors does not swallow the limit
                        pass
            if self.bad and self.how == "crash":
                os._exit(3)
            return None
''')


def _run(small_dataset, out: Path, agent: Path, on: str, how: str, *extra: str):
    args = ["run", "--cabinets", str(small_dataset), "--split", "all", "--hand", "franka", "--limit", "3",
            "--out", str(out), "--policy", str(agent), "--policy-arg", f"on={on}", "--policy-arg", f"how={how}", *extra]
    return CliRunner().invoke(main, args)


@pytest.fixture(scope="module")
def agent(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("agent") / "misbehaving.py"
    path.write_text(AGENT)
    return path


@pytest.fixture(scope="module")
def instructions(small_dataset, agent, tmp_path_factory) -> list[str]:
    """The instructions of the run's three episodes (a run in which the agent behaves)."""
    out = tmp_path_factory.mktemp("probe") / "probe.jsonl"
    result = _run(small_dataset, out, agent, "", "hang")
    assert result.exit_code == 0, result.output
    records = load_results(out)
    assert len(records) == 3 and all("error" not in r for r in records)
    return [r["instruction"] for r in records]


@pytest.mark.slow
def test_an_agent_that_hangs_is_ended_by_the_episode_timeout(small_dataset, agent, instructions, tmp_path):
    out = tmp_path / "hang.jsonl"
    result = _run(small_dataset, out, agent, instructions[1], "hang", "--episode-timeout", "3")
    assert result.exit_code == 0, result.output
    records = load_results(out)
    assert len(records) == 3
    hung = [r for r in records if r["instruction"] == instructions[1]]
    assert len(hung) == 1 and hung[0]["error_kind"] == "timeout", hung
    assert "wall-clock limit of 3 s" in hung[0]["error_reason"] and hung[0]["success"] is False
    others = [r for r in records if r["instruction"] != instructions[1]]
    assert all("error" not in r and r["agent_stopped"] for r in others), others


@pytest.mark.slow
@pytest.mark.parametrize("isolation, kind, words", [
    ("process", "agent_died", "the agent process died (exit status 3)"),
    ("in-process", "worker_died", "died"),
])
def test_an_agent_that_ends_its_process_costs_that_episode_only(small_dataset, agent, instructions, tmp_path,
                                                                 isolation, kind, words):
    out = tmp_path / "crash.jsonl"
    extra = ("--agent-in-process",) if isolation == "in-process" else ()
    result = _run(small_dataset, out, agent, instructions[0], "crash", *extra)
    assert result.exit_code == 0, result.output
    records = load_results(out)
    assert len(records) == 3
    crashed = [r for r in records if r.get("error")]
    assert len(crashed) == 1 and crashed[0]["instruction"] == instructions[0], crashed
    assert crashed[0]["error_kind"] == kind and words in crashed[0]["error_reason"], crashed[0]["error_reason"]
    assert all(r["agent_isolation"] == isolation for r in records)
    assert all("error" not in r and r["agent_stopped"] for r in records if r is not crashed[0])


def test_the_timeout_option_is_checked(small_dataset, tmp_path):
    result = CliRunner().invoke(main, ["run", "--cabinets", str(small_dataset), "--episode-timeout", "-1",
                                       "--out", str(tmp_path / "r.jsonl")])
    assert result.exit_code == 2 and "--episode-timeout" in result.output


def test_episode_deadline_raises_in_python_code_and_is_off_without_a_limit():
    import time

    from opend_mj.evaluation.deadline import EpisodeTimeout, episode_deadline

    start = time.perf_counter()
    with pytest.raises(EpisodeTimeout, match="limit of 0.2 s"):
        with episode_deadline(0.2, hard_exit=False):
            while True:
                try:
                    time.sleep(10)
                except Exception:  # noqa: BLE001 (the limit is no Exception: not swallowed here)
                    pass
    assert time.perf_counter() - start < 5
    with episode_deadline(None):
        time.sleep(0.01)
    with episode_deadline(5, hard_exit=False):
        time.sleep(0.01)  # ends in time: nothing raised, the timer is disarmed
    time.sleep(0.05)


def _corrupt_middle(path: Path) -> Path:
    lines = (Path(__file__).resolve().parents[2] / "results" / "oracle_test.jsonl").read_text().splitlines()[:5]
    lines[2] = lines[2][: len(lines[2]) // 2]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_score_on_a_corrupt_middle_line_answers_in_one_line(tmp_path):
    """Not a 40-line traceback: one line naming the file and the line, exit 1."""
    path = _corrupt_middle(tmp_path / "r.jsonl")
    result = CliRunner().invoke(main, ["score", str(path)])
    assert result.exit_code == 1
    assert result.output.strip().splitlines() == [f"Error: {path}: corrupt line 3 in the middle of the file at byte "
                                                  f"{len(chr(10).join(path.read_text().splitlines()[:3])) + 1}"]
    assert "Traceback" not in result.output


@pytest.mark.parametrize("line, words", [
    ("[1, 2]", "line 2 is not an episode record (a JSON list)"),
    ('{"cabinet": "a"}', "line 2 is not an episode record (no joint, hand, solver)"),
    ('{"cabinet": "a", "joint": "j", "hand": "h", "solver": "s", "seed": "x"}', "line 2: seed 'x' is not valid"),
])
def test_score_on_lines_that_are_no_records(tmp_path, line, words):
    lines = (Path(__file__).resolve().parents[2] / "results" / "oracle_test.jsonl").read_text().splitlines()[:3]
    path = tmp_path / "r.jsonl"
    path.write_text("\n".join([lines[0], line, lines[1]]) + "\n")
    result = CliRunner().invoke(main, ["score", str(path)])
    assert result.exit_code == 1 and result.output.strip() == f"Error: {path}: {words}", result.output


def test_an_unexpected_error_is_one_line_and_debug_shows_the_traceback(tmp_path, monkeypatch):
    """Whatever a command does not catch: one line and exit 1; `opend --debug` re-raises it."""
    from opend_mj.evaluation import scoring

    def broken(records):
        raise RuntimeError("the table\nbroke")

    monkeypatch.setattr(scoring, "ranking", broken)  # what report_markdown calls first
    lines = (Path(__file__).resolve().parents[2] / "results" / "oracle_test.jsonl").read_text().splitlines()[:3]
    path = tmp_path / "r.jsonl"
    path.write_text("\n".join(lines) + "\n")
    result = CliRunner().invoke(main, ["score", str(path)])
    assert result.exit_code == 1
    assert result.output.strip() == "Error: RuntimeError: the table broke (opend --debug shows the traceback)"
    result = CliRunner().invoke(main, ["--debug", "score", str(path)])
    assert isinstance(result.exception, RuntimeError)
