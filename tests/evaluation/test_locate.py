"""`opend evaluate-solver`: a solver's locate rate graded against every target's handle box."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from opend_mj.evaluation.locate import evaluate_locate, format_summary, grade, summarise


def test_grade_tells_located_wrong_handle_and_missed():
    boxes = {"top": (100, 40, 160, 50), "bottom": (100, 140, 160, 150), "hidden": None}
    assert grade((110, 42, 150, 48), "top", boxes) == "located"
    assert grade((110, 142, 150, 148), "top", boxes) == "wrong_handle"
    assert grade((0, 0, 20, 20), "top", boxes) == "missed"
    assert grade(None, "top", boxes) == "missed"
    assert grade((110, 42, 150, 48), "hidden", boxes) == "wrong_handle"


@pytest.fixture(scope="module")
def small_dataset(tmp_path_factory):
    from opend_mj.assets.dataset import build_dataset
    from opend_mj.assets.procedural import generate_sources

    root = tmp_path_factory.mktemp("locate")
    sources = generate_sources(8, 0, root / "src", progress=False)
    build_dataset(sources, root / "cabinets", workers=1, progress=False, log=lambda *a: None)
    return root / "cabinets"


def test_oracle_locates_every_target_and_records_are_written(small_dataset, tmp_path):
    out = tmp_path / "locate.jsonl"
    records = evaluate_locate(small_dataset, "oracle", split="all", limit=4, progress=False, out=out)
    assert len(records) == 4
    assert all(r.verdict == "located" and r.verdict_refined == "located" for r in records)
    lines = [json.loads(line) for line in out.read_text().splitlines()]
    assert [(r["cabinet"], r["joint"]) for r in lines] == [(r.cabinet, r.joint) for r in records]
    rows = summarise(records)
    overall = next(r for r in rows if r["kind"] == "overall")
    assert overall["targets"] == 4 and overall["located"] == 100.0 and overall["wrong_handle"] == 0.0
    assert "| oracle | overall | 4 | 100.0 |" in format_summary(rows)


def test_several_seeds_are_pooled_with_each_seeds_rate(small_dataset, tmp_path):
    """`opend evaluate-solver --seed 0 --seed 1`: the same targets in two scene draws, pooled, with
    one file per seed and each seed's rate in the table."""
    from click.testing import CliRunner

    from opend_mj.cli import main

    out = tmp_path / "loc.jsonl"
    result = CliRunner().invoke(main, ["evaluate-solver", "--solver", "oracle", "--cabinets", str(small_dataset),
                                       "--split", "all", "--limit", "2", "--seed", "0", "--seed", "1",
                                       "--no-progress", "--out", str(out)])
    assert result.exit_code == 0, result.output
    per_seed = [[json.loads(line) for line in (tmp_path / f"loc_s{k}.jsonl").read_text().splitlines()] for k in (0, 1)]
    assert [len(p) for p in per_seed] == [2, 2] and {r["seed"] for r in per_seed[1]} == {1}
    assert "| oracle | overall | 4 | 100.0 |" in result.output and "100 / 100 |" in result.output


def test_perturbed_scenes_reach_the_solver_and_the_records(small_dataset, tmp_path):
    """`opend evaluate-solver --perturb depth_noise=strong`: the solver reads the sensor's depth (holes,
    noise), as an episode's planner does; each record names the perturbation; an unknown axis is
    refused before anything is rendered."""
    import numpy as np
    from click.testing import CliRunner

    from opend_mj.cli import main
    from opend_mj.evaluation.locate import locate_frames, locate_jobs

    clean = [d for _, _, _, d, _, _ in locate_frames(locate_jobs(small_dataset, "all", limit=1))][0]
    noisy = [d for _, _, _, d, _, _ in locate_frames(locate_jobs(small_dataset, "all", limit=1,
                                                                 perturb="depth_noise=strong"))][0]
    assert (clean > 0).all() and (noisy == 0).any() and not np.allclose(clean[noisy > 0], noisy[noisy > 0])

    out = tmp_path / "loc.jsonl"
    result = CliRunner().invoke(main, ["evaluate-solver", "--solver", "oracle", "--cabinets", str(small_dataset),
                                       "--split", "all", "--limit", "2", "--perturb", "depth_noise=strong",
                                       "--no-progress", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert {json.loads(line)["perturb"] for line in out.read_text().splitlines()} == {"depth_noise=strong"}
    bad = CliRunner().invoke(main, ["evaluate-solver", "--solver", "oracle", "--cabinets", str(small_dataset),
                                    "--perturb", "depth_nois=strong", "--no-progress"])
    assert bad.exit_code == 2 and "depth_nois" in bad.output


def test_the_sensor_trained_detector_locates_handles_in_a_real_sensors_depth(small_dataset):
    """`--solver fasterrcnn-sensor` (checkpoints/fasterrcnn_sensor.pt, trained on the depth_noise
    sensor's depth too) reads holes as holes and finds the named handles of generated cabinets
    whose depth comes from the strong sensor."""
    from opend_mj.policy.learned.detector import SensorFasterRCNNSolver

    assert SensorFasterRCNNSolver().config.relief_holes
    records = evaluate_locate(small_dataset, "fasterrcnn-sensor", split="all", limit=8, progress=False,
                              perturb="depth_noise=strong")
    assert sum(r.verdict == "located" for r in records) >= 6, [(r.cabinet, r.joint, r.verdict) for r in records]


def test_the_box_is_graded_as_the_planner_acts_on_it(monkeypatch):
    """A solver's box over a pair of pulls is graded as the planner acts on it (`settle_box`): narrowed
    to the nearer pull, which is the other target's handle here, so it is the wrong handle, though
    the raw box's centre lies within the named one's margin."""
    from types import SimpleNamespace

    import numpy as np

    import opend_mj.evaluation.locate as locate
    import opend_mj.policy.factory as factory
    from opend_mj.policy.handle_box import HandleBox

    depth = np.full((64, 128), 1.0, np.float32)
    depth[30:34, 42:61] = 0.965  # the left pull, 3.5 cm proud, the nearer to the box's centre (u = 63)
    depth[30:34, 67:86] = 0.965  # the right pull, the named one
    boxes = {"left": (42, 30, 61, 34), "right": (66, 30, 86, 34)}
    job = SimpleNamespace(cabinet="c", joint="right", split="test", seed=0, light_scale=1.0, paraphrase=0,
                          perturb=None)
    task = SimpleNamespace(instruction="right drawer", target=SimpleNamespace(kind="drawer"))
    monkeypatch.setattr(locate, "locate_jobs", lambda *a, **k: [job])
    monkeypatch.setattr(locate, "locate_frames", lambda jobs: iter([(job, task, None, depth, None, boxes)]))

    class Pair:
        def solve(self, rgb, depth, instruction, view):
            return HandleBox(40, 30, 86, 34, orientation="horizontal", from_depth=True)

    monkeypatch.setattr(factory, "build_solver", lambda name, ground_truth=None: Pair())
    (record,) = locate.evaluate_locate(Path("unused"), "pair", progress=False)
    assert record.verdict == "located" and record.verdict_refined == "wrong_handle"
