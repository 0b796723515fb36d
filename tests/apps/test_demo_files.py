"""Demonstration files of format version 2: float32 round trip, and the one-line errors of files that
cannot be used (an older format, truncated, another hand), without running the simulator."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from opend_mj.cli import main

T = 40


def _demo(hand: str = "allegro", index: int = 0):
    """A synthetic planner demonstration (random values, the keys training reads)."""
    from opend_mj.apps.demos import Demo, env_args
    from opend_mj.apps.planner_demos import TRAINING_KEYS
    from opend_mj.sim.task import TaskConfig

    rng = np.random.default_rng(index)
    obs = {k: rng.standard_normal((T, 4)) for k in TRAINING_KEYS}
    obs["rgb"] = rng.integers(0, 256, (T, 8, 8, 3), dtype=np.uint8)
    attrs = {"hand": hand, "success": True, "instruction": "open the top drawer", "cabinet": f"c{index}",
             "job_key": json.dumps([f"c{index}", "joint_0", hand, index])}
    demo = Demo(actions=rng.standard_normal((T, 23)), obs=obs, attrs=attrs,
                final={"hand_qpos": rng.standard_normal((1, 16))},
                extra={"actions_delta": rng.standard_normal((T, 22)), "phase": np.arange(T, dtype=np.int64)})
    demo.env_args = env_args(TaskConfig())
    return demo


def _write(path: Path, n: int = 2, hand: str = "allegro") -> tuple[Path, list]:
    from opend_mj.apps.demos import write_demos

    demos = [_demo(hand, i) for i in range(n)]
    return write_demos(path, demos, append=False), demos


@pytest.mark.parametrize("suffix", [".hdf5", ".npz"])
def test_v2_round_trip_keeps_float32_values_and_shapes(tmp_path, suffix):
    from opend_mj.apps.demos import FORMAT_VERSION, read_demos

    path, demos = _write(tmp_path / f"demos{suffix}")
    attrs, back = read_demos(path)
    assert attrs["format_version"] == FORMAT_VERSION == 2 and len(back) == 2
    for d, b in zip(demos, back):
        assert b.actions.dtype == np.float64 and np.array_equal(b.actions, d.actions)  # a replay steps these
        for k, v in d.obs.items():
            if k == "rgb":
                assert b.obs[k].dtype == np.uint8 and np.array_equal(b.obs[k], v)
            else:
                assert b.obs[k].dtype == np.float32 and b.obs[k].shape == v.shape
                assert np.array_equal(b.obs[k], v.astype(np.float32)), k
        assert b.extra["actions_delta"].dtype == np.float32 and b.extra["phase"].dtype == np.int64
        assert np.array_equal(b.extra["phase"], d.extra["phase"])
        assert b.final["hand_qpos"].shape == (1, 16) and b.attrs["job_key"] == d.attrs["job_key"]


def test_v2_hdf5_arrays_are_compressed(tmp_path):
    import h5py

    path, _ = _write(tmp_path / "demos.hdf5")
    with h5py.File(path) as f:
        d = f["data/demo_0"]
        assert d["actions"].compression == "gzip" and d["obs/rgb"].compression == "gzip"
        assert d["actions_delta"].chunks is not None and d["actions_delta"].compression == "gzip"


def _set_header(path: Path, **attrs) -> None:
    import h5py

    with h5py.File(path, "a") as f:
        for k, v in attrs.items():
            if v is None:
                del f["data"].attrs[k]
            else:
                f["data"].attrs[k] = v


@pytest.mark.parametrize("change, message", [
    ({"format_version": 1}, "format version 1"),
    ({"format_version": None}, "format version None"),
    ({"format": "robomimic"}, "not an opend-mj demonstrations file"),
])
def test_other_formats_get_one_line_errors_naming_the_file(tmp_path, change, message):
    from opend_mj.apps.demos import DemoFileError, append_demos, read_demos
    from opend_mj.apps.planner_demos import load_training_demos

    path, _ = _write(tmp_path / "old.hdf5")
    _set_header(path, **change)
    for read in (read_demos, load_training_demos, lambda p: append_demos(p, [_demo()])):
        with pytest.raises(DemoFileError) as err:
            read(path)
        text = str(err.value)
        assert str(path) in text and message in text and "\n" not in text
    if "format_version" in change:
        assert "re-record" in text


def test_older_npz_file_is_refused(tmp_path):
    from opend_mj.apps.demos import DemoFileError, read_demos

    path, _ = _write(tmp_path / "old.npz")
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    header = json.loads(str(arrays["data/.attrs"]))
    arrays["data/.attrs"] = np.array(json.dumps({**header, "format_version": 1}))
    np.savez(path, **arrays)
    with pytest.raises(DemoFileError, match="format version 1"):
        read_demos(path)


@pytest.mark.parametrize("suffix", [".hdf5", ".npz"])
def test_truncated_file_gets_one_line_error(tmp_path, suffix):
    from opend_mj.apps.demos import DemoFileError, read_demos
    from opend_mj.apps.planner_demos import load_training_demos

    path, _ = _write(tmp_path / f"cut{suffix}")
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])  # what a killed copy leaves
    for read in (read_demos, load_training_demos):
        with pytest.raises(DemoFileError) as err:
            read(path)
        assert str(path) in str(err.value) and "truncated" in str(err.value) and "\n" not in str(err.value)


def test_demos_of_another_hand_are_refused(tmp_path):
    from opend_mj.apps.demos import DemoFileError
    from opend_mj.apps.planner_demos import load_training_demos

    path, _ = _write(tmp_path / "allegro.hdf5")
    assert len(load_training_demos(path, hand="allegro")) == 2
    with pytest.raises(DemoFileError) as err:
        load_training_demos(path, hand="franka")
    assert str(path) in str(err.value) and "allegro hand" in str(err.value) and "franka" in str(err.value)


def test_cli_prints_the_errors_in_one_line(tmp_path):
    cut, _ = _write(tmp_path / "cut.hdf5")
    cut.write_bytes(cut.read_bytes()[:5000])
    old, _ = _write(tmp_path / "old.hdf5")
    _set_header(old, format_version=1)
    other, _ = _write(tmp_path / "franka.hdf5", hand="franka")
    runs = {
        "truncated": (["train-policy", "--demos", str(cut), "--out", str(tmp_path / "x.pt")], cut),
        "format version 1": (["train-policy", "--demos", str(old), "--out", str(tmp_path / "x.pt")], old),
        "franka hand": (["train-policy", "--demos", str(other), "--hand", "allegro", "--out", str(tmp_path / "x.pt")],
                        other),
        "re-record": (["replay", str(old)], old),
    }
    for message, (args, path) in runs.items():
        result = CliRunner().invoke(main, args)
        assert result.exit_code == 1, (message, result.output)
        assert result.exception is None or isinstance(result.exception, SystemExit), result.exception
        lines = result.output.strip().splitlines()
        assert len(lines) == 1 and str(path) in lines[0] and message in lines[0], result.output


def test_tried_keys_trust_the_file_for_kept_demos_and_drop_a_torn_log_line(tmp_path):
    """After a kill: a demo in the file is done (even without its log line), a kept episode the file
    lacks is not, a failed one the log has is, and a torn last log line is cut off."""
    from opend_mj.apps.demos import write_demos
    from opend_mj.apps.planner_demos import log_path, tried_keys

    out = tmp_path / "rec.hdf5"
    write_demos(out, [_demo(index=0)], append=False)
    log = log_path(out)
    lines = [{"key": ["c1", "joint_0", "allegro", 1], "kept": True},  # its demo never reached the file
             {"key": ["c2", "joint_0", "allegro", 2], "kept": False}]  # tried, failed
    log.write_text("".join(json.dumps(x) + "\n" for x in lines) + '{"key": ["c0", "joi')
    assert tried_keys(out) == {("c0", "joint_0", "allegro", 0), ("c2", "joint_0", "allegro", 2)}
    assert log.read_text().endswith("\n") and len(log.read_text().splitlines()) == 2


def test_demos_refuses_to_resume_into_an_older_file(tmp_path, small_dataset):
    old, _ = _write(tmp_path / "old.hdf5")
    _set_header(old, format_version=1)
    before = old.read_bytes()
    result = CliRunner().invoke(main, ["demos", "--cabinets", str(small_dataset), "--split", "all", "--limit", "1",
                                       "--out", str(old), "--no-progress"])
    assert result.exit_code == 1 and result.output.count("\n") == 1 and "format version 1" in result.output
    assert old.read_bytes() == before  # nothing recorded into it
