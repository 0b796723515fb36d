"""Checkpoints cannot run code: every reader loads plain data only (`checkpoint_io.read_checkpoint`),
and a file whose pickle calls a function is refused in one line naming it, the function never
called. The attack files here call ``os.mkdir`` on a marker path when unpickled without restriction."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner

from opend_mj.cli import main
from opend_mj.policy.learned.checkpoint_io import CheckpointError, plain_data, read_checkpoint, write_checkpoint

CHECKPOINTS = Path(__file__).resolve().parents[2] / "checkpoints"


class _MakesMarker:
    """Unpickled without restriction, becomes ``os.mkdir(marker)``: the marker appears."""

    def __init__(self, marker: Path):
        self.marker = str(marker)

    def __reduce__(self):
        return os.mkdir, (self.marker,)


def _attack(tmp_path: Path, name: str = "evil.pt") -> tuple[Path, Path]:
    """(a checkpoint-shaped file whose pickle makes a marker folder, the marker's path)."""
    marker = tmp_path / f"{name}.ran"
    path = tmp_path / name
    torch.save({"model": {"w": torch.zeros(3)}, "config": {}, "dims": {"ctx": 1, "step": 1, "act": 1},
                "hand": "franka", "payload": _MakesMarker(marker)}, path)
    return path, marker


def test_the_attack_file_runs_its_code_when_unpickled_without_restriction(tmp_path):
    """The attack is real: torch.load(weights_only=False), what every reader used before, calls it."""
    path, marker = _attack(tmp_path)
    torch.load(path, weights_only=False)
    assert marker.is_dir()


def _one_line_naming(text: str, path: Path) -> str:
    lines = text.strip().splitlines()
    assert len(lines) == 1 and str(path) in lines[0] and "Traceback" not in text, text
    return lines[0]


@pytest.mark.parametrize("arg", ["checkpoint", "drawer"])
def test_run_refuses_a_bc_checkpoint_that_runs_code(tmp_path, arg):
    """Refused when the agent is made, before the cabinets' manifest is read (an empty one here)."""
    path, marker = _attack(tmp_path)
    (tmp_path / "manifest.json").write_text("{}")
    result = CliRunner().invoke(main, ["run", "--policy", "bc", "--policy-arg", f"{arg}={path}", "--hand", "franka",
                                       "--cabinets", str(tmp_path),
                                       "--out", str(tmp_path / "r.jsonl")])
    assert result.exit_code == 1
    line = _one_line_naming(result.output, path)
    assert "posix.mkdir" in line or "os.mkdir" in line
    assert not marker.exists() and not (tmp_path / "r.jsonl").exists()


def test_bundle_policy_refuses_a_checkpoint_that_runs_code(tmp_path):
    path, marker = _attack(tmp_path)
    result = CliRunner().invoke(main, ["bundle-policy", str(path), "--out", str(tmp_path / "bundle.pt")])
    assert result.exit_code == 1
    _one_line_naming(result.output, path)
    assert not marker.exists() and not (tmp_path / "bundle.pt").exists()


@pytest.mark.parametrize("solver", ["cliport", "fasterrcnn"])
def test_train_evaluate_refuses_a_solver_checkpoint_that_runs_code(tmp_path, solver):
    """`opend train --evaluate` loads the solver checkpoint --out (as `opend run --solver` does)."""
    path, marker = _attack(tmp_path)
    result = CliRunner().invoke(main, ["train", "--solver", solver, "--evaluate", "val", "--out", str(path),
                                       "--data", str(tmp_path)])
    assert result.exit_code == 1
    _one_line_naming(result.output, path)
    assert not marker.exists()


def _library_loaders():
    """name -> a call of one reader on a file: every place a checkpoint enters the project."""
    from opend_mj.policy.learned import checkpoint_tensors
    from opend_mj.policy.learned.affordance import load_affordance
    from opend_mj.policy.learned.bc_model import bundle_policies, load_policies, load_policy
    from opend_mj.policy.learned.bc_train import _warm_start
    from opend_mj.policy.learned.detector import load_detector
    from opend_mj.policy.learned.loop import TrainingLoop, load_pretrained

    return {
        "bc policy": lambda p: load_policy(p),
        "bc policies": lambda p: load_policies([p]),
        "bundle-policy input": lambda p: bundle_policies([p], p.with_name("bundle.pt")),
        "train-policy --init": lambda p: _warm_start(p, None, "franka", None),
        "CLIPort checkpoint": lambda p: load_affordance(p, "cpu"),
        "detector checkpoint": lambda p: load_detector(p, "cpu"),
        "train --init": lambda p: checkpoint_tensors(p),
        "train --resume state": lambda p: TrainingLoop("cliport", p.with_name("out.pt"), p, 1, None, False,
                                                lambda s: None).resume(None, None, None),
        "train --pretrained": lambda p: load_pretrained(None, p, "cliport"),
    }


@pytest.mark.parametrize("name", list(_library_loaders()))
def test_every_reader_refuses_a_checkpoint_that_runs_code(tmp_path, name):
    path, marker = _attack(tmp_path)
    with pytest.raises(CheckpointError) as info:
        _library_loaders()[name](path)
    _one_line_naming(str(info.value), path)
    assert not marker.exists()


def test_a_bare_pickle_and_a_damaged_file_are_refused_in_one_line(tmp_path):
    import pickle

    marker = tmp_path / "bare.ran"
    bare = tmp_path / "bare.pt"
    bare.write_bytes(pickle.dumps({"model": _MakesMarker(marker)}, protocol=4))
    with pytest.raises(CheckpointError, match="posix.mkdir|os.mkdir") as info:
        read_checkpoint(bare)
    _one_line_naming(str(info.value), bare)
    assert not marker.exists()
    good = tmp_path / "good.pt"
    write_checkpoint({"model": {"w": torch.ones(4)}}, good)
    damaged = tmp_path / "damaged.pt"
    damaged.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    with pytest.raises(CheckpointError, match="damaged") as info:
        read_checkpoint(damaged)
    _one_line_naming(str(info.value), damaged)


@dataclass
class _Config:
    width: int = 3
    lags: tuple = (0, 4)


def test_written_checkpoints_are_plain_data(tmp_path):
    """numpy arrays become tensors, numpy scalars numbers, dataclasses dicts, paths strings; the file
    loads with torch.load(weights_only=True); an object of any other class is refused when writing."""
    path = tmp_path / "c.pt"
    state = torch.nn.Linear(2, 2).state_dict()
    write_checkpoint({"model": state, "config": _Config(), "low": np.array([0.5, 1.5], np.float32),
                      "best": np.float64(0.25), "n": np.int64(7), "data": tmp_path, "history": [{"loss": np.float32(1.0)}]},
                     path)
    ckpt = torch.load(path, weights_only=True)
    assert ckpt["config"] == {"width": 3, "lags": (0, 4)}
    assert torch.equal(ckpt["low"], torch.tensor([0.5, 1.5])) and ckpt["low"].dtype == torch.float32
    assert type(ckpt["best"]) is float and ckpt["best"] == 0.25 and type(ckpt["n"]) is int
    assert ckpt["data"] == str(tmp_path) and type(ckpt["history"][0]["loss"]) is float
    assert all(torch.equal(state[k], ckpt["model"][k]) for k in state)
    assert ckpt["model"]._metadata == state._metadata  # module versions, read by load_state_dict
    with pytest.raises(TypeError, match=r"\['config'\]"):
        plain_data({"config": {1, 2}})


@pytest.mark.parametrize("name", sorted(p.name for p in CHECKPOINTS.glob("*.pt")))
def test_every_shipped_checkpoint_loads_as_plain_data(name):
    """With torch.load(weights_only=True); the handle solvers' weights stay float16 (the files' size), and
    a behaviour-cloning policy's are float16 where the DAgger recipe shipped it (`apps.dagger.save_half`),
    float32 in the older ones; a bundle of several (`opend bundle-policy`) holds such policies."""
    ckpt = torch.load(CHECKPOINTS / name, map_location="cpu", weights_only=True)
    models = ckpt["members"] if name.startswith("bc_") and "members" in ckpt else [ckpt]
    for model in models:
        assert isinstance(model["model"], dict) and all(isinstance(v, torch.Tensor) for v in model["model"].values())
        floats = {v.dtype for v in model["model"].values() if v.is_floating_point()}
        assert floats in ({torch.float16}, {torch.float32}) if name.startswith("bc_") else floats == {torch.float16}
        assert isinstance(model["config"], dict)


def test_the_shipped_checkpoints_are_found():
    assert {p.name for p in CHECKPOINTS.glob("*.pt")} >= {"bc_allegro.pt", "bc_franka.pt", "bc_shadow.pt",
                                                           "bc_skeleton.pt", "cliport.pt", "fasterrcnn.pt",
                                                           "fasterrcnn_sensor.pt"}
