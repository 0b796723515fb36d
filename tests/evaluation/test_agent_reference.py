"""docs/evaluation.md's agent reference against what an agent really gets from `opend run --policy`:
every observation key with its shape, dtype and when it arrives, every `EpisodeInfo` field with its
type, and both action layouts, none missing and none extra."""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from opend_mj.cli import main

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "evaluation.md"


class Recorder:
    """An agent that writes what it is given (two observations, the EpisodeInfo) to ``out`` as JSON."""

    name = "recorder"

    def __init__(self, out: str, control: str = "absolute", images: str = "first"):
        self.out, self.control, self.images = out, control, images

    def reset(self, episode) -> None:
        from opend_mj.sim.hands import touch_parts

        self.info = {"fields": {f.name: type(getattr(episode, f.name)).__name__ for f in dataclasses.fields(episode)},
                     "bounds": {k: [list(getattr(episode, k).shape), str(getattr(episode, k).dtype)]
                                for k in ("action_low", "action_high")},
                     "action_names": list(episode.action_names),
                     "actuators": list(episode.hand_spec.actuator_names),
                     "n": len(episode.hand_spec.joint_names), "t": len(touch_parts(episode.hand_spec))}
        self.open_pose = np.asarray(episode.hand_spec.open_pose, float)
        self.observations = []

    def act(self, obs):
        self.observations.append({k: [list(np.shape(v)), type(v).__name__ if isinstance(v, str) else str(v.dtype)]
                                  for k, v in obs.items()})
        if len(self.observations) < 2:  # hold still: the commanded pose, fingers open (or a zero delta)
            if self.control == "delta":
                return np.zeros(len(self.info["action_names"]))
            return np.concatenate([obs["mocap_pos"], obs["mocap_quat"], self.open_pose])
        Path(self.out).write_text(json.dumps({**self.info, "observations": self.observations}))
        return None


def _table(after: str) -> list[list[str]]:
    """The body cells of the Markdown table whose header line starts with ``after``."""
    lines = PAGE.read_text().splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(after))
    rows = []
    for line in lines[start:]:
        if not line.startswith("|"):
            if rows:
                break
            continue
        rows.append([c.strip() for c in line.strip("|").split("|")])
    return rows[2:]  # past the header and its rule


def _names(cell: str) -> list[str]:
    return re.findall(r"`([^`]+)`", cell)


def _shape(cell: str, sizes: dict) -> list[int]:
    """``(n,)``, ``(H, W, 3)``, ``-`` -> the shape with the sizes filled in."""
    inner = cell.strip("()")
    return [] if cell == "-" else [int(sizes.get(p.strip(), p.strip())) for p in inner.split(",") if p.strip()]


@pytest.fixture(scope="module")
def recorded(small_dataset, tmp_path_factory):
    """What the recorder was given, for the absolute and the delta layout (Franka, one episode each)."""
    out = {}
    for control, images in (("absolute", "first"), ("delta", "every_step")):
        path = tmp_path_factory.mktemp(control) / "seen.json"
        result = CliRunner().invoke(main, [
            "run", "--cabinets", str(small_dataset), "--split", "all", "--hand", "franka", "--limit", "1",
            "--out", str(path.with_name("results.jsonl")), "--policy", f"{__file__}:Recorder",
            "--policy-arg", f"out={path}", "--policy-arg", f"control={control}", "--policy-arg", f"images={images}"])
        assert result.exit_code == 0, result.output
        out[control] = json.loads(path.read_text())
    return out


def test_every_observation_key_is_documented_with_its_shape_dtype_and_timing(recorded):
    seen = recorded["absolute"]
    sizes = {"n": seen["n"], "t": seen["t"], "H": 256, "W": 256}
    rows = {_names(r[0])[0]: r for r in _table("| key | shape | dtype |")}
    first, second = seen["observations"]
    assert set(rows) == set(first)  # every key documented, none documented that is not there
    for key, (shape, dtype) in first.items():
        assert _shape(rows[key][1], sizes) == shape, key
        assert rows[key][2] == dtype, key
    # "first step": present in the first observation only, unless the agent asks for every step
    later = {k for k, r in rows.items() if r[4] == "first step"}
    assert later == {"rgb", "depth"}
    assert set(second) == set(first) - later
    assert [set(o) for o in recorded["delta"]["observations"]] == [set(first)] * 2


def test_every_episode_info_field_is_documented_with_its_type(recorded):
    seen = recorded["absolute"]
    documented = {name: row[1] for row in _table("| field | type |") for name in _names(row[0])}
    assert documented == seen["fields"]
    for bound in seen["bounds"].values():
        assert bound == [[len(seen["action_names"])], "float64"]


def test_both_action_layouts_are_documented_from_action_names(recorded):
    rows = {_names(r[0])[0].strip('"'): r for r in _table("| `control` | length |")}
    assert set(rows) == {"absolute", "delta"}
    for control, seen in recorded.items():
        names = _names(rows[control][2])
        n = len(seen["actuators"])
        assert seen["action_names"] == names + seen["actuators"], control
        assert rows[control][1] == f"{len(names)} + n" and len(seen["action_names"]) == len(names) + n
