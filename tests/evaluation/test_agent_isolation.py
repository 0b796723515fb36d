"""Agents as an attacker would write them: one that searches its process for the simulator to write
the cabinet's joints, reads its parent's memory through /proc, or allocates without end. In a
process of its own (the default) it finds no simulator, reads nothing, and is held to its memory
limit while the run goes on; `--agent-in-process` (debugging) is marked in records and score tables."""

from __future__ import annotations

import hashlib
import textwrap
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from opend_mj.cli import main
from opend_mj.evaluation.results import load_results

ATTACKER = textwrap.dedent('''
    import gc
    import os

    import numpy as np

    #: types whose instances would give the agent the scene
    SIMULATOR_TYPES = ("Physics", "MjData", "MjModel", "OpenDEnvironment", "Environment", "OpenDTask")


    def find_simulator():
        """Simulator objects reachable in this process: gc-tracked ones and what they refer to
        (MjData and MjModel are not tracked themselves)."""
        found = {}
        for obj in gc.get_objects():
            for x in (obj, *gc.get_referents(obj)):
                if type(x).__name__ in SIMULATOR_TYPES:
                    found.setdefault(type(x).__name__, x)
        return found


    def read_parent_memory():
        """What reading 8 bytes of the parent's first readable mapping gives: 'read' or the error."""
        ppid = os.getppid()
        try:
            with open(f"/proc/{ppid}/maps") as f:
                start = next(int(ln.split("-")[0], 16) for ln in f if ln.split()[1].startswith("r"))
            with open(f"/proc/{ppid}/mem", "rb") as f:
                f.seek(start)
                return "read" if len(f.read(8)) == 8 else "empty"
        except Exception as exc:
            return type(exc).__name__


    class Agent:
        name = "attacker"
        control = "delta"
        images = "first"

        def __init__(self, hog_marker: str = ""):
            self.hog_marker = hog_marker

        def reset(self, episode):
            self.found = find_simulator()
            self.parent_memory = read_parent_memory()
            physics = self.found.get("Physics")
            if physics is not None:  # every cabinet joint to the end of its range
                model = physics.model
                for j in range(model.njnt):
                    if model.id2name(j, "joint").startswith("cabinet/") and model.jnt_limited[j]:
                        physics.data.qpos[model.jnt_qposadr[j]] = model.jnt_range[j][1]
                physics.forward()

        def act(self, obs):
            if self.hog_marker and not os.path.exists(self.hog_marker):
                open(self.hog_marker, "w").close()
                hog = []
                while True:  # 64 MiB at a time until the address space runs out
                    hog.append(np.empty(64 << 20, np.uint8))
            return None

        def episode_info(self):
            return {"simulator_found": sorted(self.found), "parent_memory": self.parent_memory,
                    "success": True, "agent_isolation": "process"}  # fields it may not set
''')


@pytest.fixture(scope="module")
def attacker(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("attacker") / "attacker.py"
    path.write_text(ATTACKER)
    return path


def _run(small_dataset, out: Path, agent: Path, limit: int, *extra: str):
    args = ["run", "--cabinets", str(small_dataset), "--split", "all", "--hand", "franka", "--limit", str(limit),
            "--out", str(out), "--policy", str(agent), *extra]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    return load_results(out)


@pytest.mark.slow
def test_an_agent_apart_finds_no_simulator_reads_no_parent_memory_and_opens_nothing(small_dataset, attacker,
                                                                                     tmp_path):
    records = _run(small_dataset, tmp_path / "apart.jsonl", attacker, 2)
    digest = hashlib.sha256(attacker.read_bytes()).hexdigest()
    assert len(records) == 2
    for r in records:
        assert "error" not in r, r.get("error_reason")
        assert r["simulator_found"] == [], r["simulator_found"]
        assert r["parent_memory"] == "PermissionError", r["parent_memory"]
        assert r["success"] is False and r["open_ratio"] == 0.0 and r["agent_stopped"]
        assert r["agent_isolation"] == "process" and r["agent_sha256"] == digest and r["opend_version"]
        assert r["agent_memory"] > 0  # the default: a share of the machine

    # the control: the same agent beside the simulator reaches it and writes the joints
    inside = _run(small_dataset, tmp_path / "inside.jsonl", attacker, 1, "--agent-in-process")
    assert len(inside) == 1
    assert "Physics" in inside[0]["simulator_found"] and inside[0]["open_ratio"] > 0.2
    assert inside[0]["agent_isolation"] == "in-process"
    score = CliRunner().invoke(main, ["score", str(tmp_path / "apart.jsonl"), str(tmp_path / "inside.jsonl")])
    assert score.exit_code == 0, score.output
    assert "| attacker (agent in-process) | franka |" in score.output
    assert "| attacker | franka |" in score.output
    assert "## How agents were run" in score.output and "| franka | attacker (agent in-process) | 1 | in-process |" \
        in score.output


@pytest.mark.slow
def test_an_agent_past_its_memory_limit_is_recorded_and_the_run_goes_on(small_dataset, attacker, tmp_path):
    marker = tmp_path / "hogged"
    records = _run(small_dataset, tmp_path / "hog.jsonl", attacker, 2, "--agent-memory", "1G",
                   "--policy-arg", f"hog_marker={marker}")
    assert marker.exists() and len(records) == 2
    hogs = [r for r in records if "error" in r]
    assert len(hogs) == 1, [r.get("error_reason") for r in records]
    assert hogs[0]["error_kind"] == "agent_memory" and "memory limit of 1 GiB" in hogs[0]["error_reason"]
    assert hogs[0]["agent_memory"] == 1 << 30
    other = next(r for r in records if r is not hogs[0])
    assert other["agent_stopped"] and other["simulator_found"] == []


def test_the_agent_memory_option_is_checked(small_dataset, tmp_path):
    base = ["run", "--cabinets", str(small_dataset), "--out", str(tmp_path / "r.jsonl")]
    result = CliRunner().invoke(main, [*base, "--policy", "bc", "--agent-memory", "lots"])
    assert result.exit_code == 2 and "--agent-memory" in result.output and "no memory size" in result.output
    result = CliRunner().invoke(main, [*base, "--agent-in-process"])
    assert result.exit_code == 2 and "need --policy" in result.output
    assert not (tmp_path / "r.jsonl").exists()


def test_observations_and_actions_cross_as_raw_bytes():
    """The channel's codec: arrays arrive equal and writable, each step in fresh memory; an action
    is float64 of the shape sent; a malformed action message is refused, not parsed."""
    from opend_mj.evaluation.agent_channel import (
        AgentFailure,
        ObservationDecoder,
        ObservationEncoder,
        decode_action,
        encode_action,
    )

    enc, dec = ObservationEncoder(), ObservationDecoder()
    obs = {"hand_qpos": np.arange(4.0), "rgb": np.full((2, 3, 3), 7, np.uint8), "instruction": "top drawer"}
    first = dec.decode(enc.encode(obs))
    assert first["instruction"] == "top drawer" and first["rgb"].dtype == np.uint8
    assert np.array_equal(first["rgb"], obs["rgb"]) and np.array_equal(first["hand_qpos"], obs["hand_qpos"])
    step = {"hand_qpos": np.arange(4.0) + 1, "instruction": "top drawer"}
    message = enc.encode(step)
    second, third = dec.decode(message), dec.decode(enc.encode(step))
    assert message[:1] == b"O" and "rgb" not in second  # a new layout goes in full
    assert enc.encode(step)[:1] == b"o"  # the same layout: array bytes only
    third["hand_qpos"][0] = -1.0
    assert second["hand_qpos"][0] == 1.0
    with pytest.raises(TypeError, match="not an array"):
        enc.encode({"physics": object()})
    action = decode_action(encode_action([[1, 2], [3, 4]]))
    assert action.dtype == np.float64 and action.shape == (2, 2)
    with pytest.raises(AgentFailure, match="malformed"):
        decode_action(encode_action([1.0, 2.0])[:-3])
