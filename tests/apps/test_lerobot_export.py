"""tools/demos_to_lerobot.py: `opend demos` files as LeRobotDatasets, read back by LeRobot's own loader.

LeRobot pins an older torch than this project, so the tool runs in an environment of its own
(`make install-lerobot`: build/lerobot-venv, or the Python named by $OPEND_LEROBOT_PYTHON); the
round trip skips without one. The clear errors are checked everywhere.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from opend_mj.cli import main

ROOT = Path(__file__).resolve().parents[2]
TOOL = ROOT / "tools" / "demos_to_lerobot.py"


def lerobot_python() -> str | None:
    """A Python that imports lerobot: $OPEND_LEROBOT_PYTHON, else build/lerobot-venv's, else none."""
    for candidate in (os.environ.get("OPEND_LEROBOT_PYTHON"), str(ROOT / "build" / "lerobot-venv" / "bin" / "python")):
        if candidate and Path(candidate).is_file():
            return candidate
    return None


def run_tool(python: str, *args, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([python, str(TOOL), *map(str, args)], capture_output=True, text=True, cwd=cwd, timeout=600)


@pytest.fixture(scope="module")
def demos_with_images(small_dataset, tmp_path_factory):
    """Two franka demos of the small dataset with 32 x 32 RGB-D at every step."""
    out = tmp_path_factory.mktemp("lerobot") / "franka.hdf5"
    result = CliRunner().invoke(main, ["demos", "--cabinets", str(small_dataset), "--split", "all", "--hand", "franka",
                                       "--limit", "2", "--image-size", "32", "--out", str(out), "--no-progress"])
    assert result.exit_code == 0, result.output
    return out


def test_bad_input_is_a_clear_error_and_writes_nothing(tmp_path):
    not_demos = tmp_path / "notes.hdf5"
    not_demos.write_text("not hdf5")
    result = run_tool(sys.executable, not_demos, "--out", tmp_path / "out", cwd=tmp_path)
    assert result.returncode == 2 and "notes.hdf5" in result.stderr and "not an HDF5 file" in result.stderr
    missing = run_tool(sys.executable, tmp_path / "nope.hdf5", "--out", tmp_path / "out", cwd=tmp_path)
    assert missing.returncode == 2 and "nope.hdf5: no such file" in missing.stderr
    assert not (tmp_path / "out").exists()


def test_without_lerobot_the_tool_says_how_to_get_it(demos_with_images, tmp_path):
    has = subprocess.run([sys.executable, "-c", "import lerobot"], capture_output=True).returncode == 0
    if has:
        pytest.skip("lerobot is importable in this environment")
    result = run_tool(sys.executable, demos_with_images, "--out", tmp_path / "out", cwd=tmp_path)
    assert result.returncode == 2 and "make install-lerobot" in result.stderr
    assert not (tmp_path / "out").exists()


def test_demos_round_trip_through_lerobots_loader(demos_with_images, tmp_path):
    """Every frame's state, environment state and action come back exactly from LeRobot's loader,
    each episode's task is its instruction, and the camera comes back as a video feature."""
    python = lerobot_python()
    if python is None:
        pytest.skip("the optional extra LeRobot environment is not installed (make install-lerobot, or set "
                    "OPEND_LEROBOT_PYTHON to a Python with lerobot)")
    out = tmp_path / "ds"
    result = run_tool(python, demos_with_images, "--out", out, "--repo-id", "opend-mj/test", "--verify", cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-2000:]
    assert "2 episodes" in result.stdout and "verified with LeRobot's loader: 2 episodes" in result.stdout
    info = json.loads((out / "meta" / "info.json").read_text())
    assert info["fps"] == 60 and info["total_episodes"] == 2 and info["robot_type"] == "franka"
    features = info["features"]
    assert features["observation.images.front"]["dtype"] == "video"
    assert features["observation.images.front"]["shape"] == [32, 32, 3]
    assert features["observation.environment_state"]["shape"] == [14 + 4 + 25]
    assert "hand_qpos.0" in features["observation.state"]["names"]
    # a second conversion into the same folder is refused, not merged
    again = run_tool(python, demos_with_images, "--out", out, cwd=tmp_path)
    assert again.returncode == 2 and "already exists" in again.stderr
