"""Perturbations (`sim.perturb`, `opend run --perturb`): each axis changes what it says, and only that;
draws are deterministic; nominal episodes are unchanged; bad ones are refused before any episode."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from opend_mj.sim.perturb import AXES, PerturbConfig, PerturbError, SceneShift, parse_perturb


def test_parse_canonical_and_refusals():
    assert parse_perturb(["light=strong", "camera_pose=mild"]) == "camera_pose=mild,light=strong"
    assert parse_perturb("physics=mild, depth_noise=strong") == "physics=mild,depth_noise=strong"
    assert parse_perturb([]) is None
    with pytest.raises(PerturbError, match="unknown axis 'fog'"):
        parse_perturb(["fog=mild"])
    with pytest.raises(PerturbError, match="unknown level 'hard'"):
        parse_perturb(["light=hard"])
    with pytest.raises(PerturbError, match="AXIS=LEVEL"):
        parse_perturb(["light"])
    with pytest.raises(PerturbError, match="given twice"):
        parse_perturb(["light=mild", "light=strong"])


def test_draw_deterministic_and_axes_independent():
    bounds = (np.array([-0.25, -0.4, 0.0]), np.array([0.25, 0.4, 0.9]))
    a = SceneShift.draw("camera_pose=strong", 7, bounds)
    assert a == SceneShift.draw("camera_pose=strong", 7, bounds)
    assert a["camera_pose"].offset != SceneShift.draw("camera_pose=strong", 8, bounds)["camera_pose"].offset
    both = SceneShift.draw("camera_pose=strong,light=mild", 7, bounds)
    assert both["camera_pose"] == a["camera_pose"] and both["camera_fov"] is None
    for seed in range(20):  # the levels' limits hold
        s = SceneShift.draw("camera_pose=mild,camera_fov=strong,physics=strong", seed, bounds)
        assert np.linalg.norm(s["camera_pose"].offset) <= 0.03 + 1e-12
        turn = np.degrees(np.arccos(np.clip((np.trace(np.array(s["camera_pose"].turn)) - 1) / 2, -1, 1)))
        assert turn <= 3.0 + 1e-9
        assert 0.85 - 1e-12 <= s["camera_fov"] <= 1.15 + 1e-12
        assert all(0.4 - 1e-12 <= f <= 3.0 + 1e-12 for f in s["physics"].values())


def test_check_refuses_camera_inside_and_distractor_in_path():
    bounds = (np.array([-0.25, -0.4, 0.0]), np.array([0.25, 0.4, 0.9]))
    shift = SceneShift.draw("distractors=strong", 3, bounds)
    start = np.array([-0.6, 0.8, 0.45])
    shift.check(bounds, np.array([-2.0, 0.0, 1.2]), start)  # as drawn: valid
    assert shift["distractors"] and all(d.box()[0][0] > bounds[0][0] for d in shift["distractors"])  # none in front
    with pytest.raises(PerturbError, match="camera inside the cabinet"):
        shift.check(bounds, np.array([0.0, 0.0, 0.5]), start, label="cab")
    from dataclasses import replace

    from opend_mj.sim.perturb import Distractor

    blocking = replace(shift, values={**shift.values,
                                      "distractors": (Distractor("mug", (-0.6, 0.75, 0.4), (0.05, 0.05, 0.05)),)})
    with pytest.raises(PerturbError, match=r"cab: perturbation distractors=strong puts a distractor \(mug"):
        blocking.check(bounds, np.array([-2.0, 0.0, 1.2]), start, label="cab")


def _env(cabinet_dir, perturb=None, joint=None):
    from opend_mj.evaluation.episode import EpisodeJob
    from opend_mj.evaluation.runner import make_episode_env
    from opend_mj.sim.cabinet import load_cabinet_info

    joint = joint or load_cabinet_info(cabinet_dir)["targets"][0]["joint"]
    job = EpisodeJob(cabinet="c", cabinet_dir=str(cabinet_dir), joint=joint, split="test", hand="franka",
                     solver="oracle", perturb=perturb)
    env = make_episode_env(job)
    env.reset()
    return env


def test_each_axis_changes_the_scene(proc_cabinets):
    """Camera pose and field of view move the real camera (and the intrinsics follow); light,
    textures and distractors change the MJCF; physics the compiled model's friction, damping and mass."""
    cab = proc_cabinets[0].dir
    nominal = _env(cab)
    m0 = nominal.physics.model
    cam = m0.name2id("front", "camera")

    env = _env(cab, "camera_pose=strong")
    moved = np.linalg.norm(env.physics.data.cam_xpos[cam] - nominal.physics.data.cam_xpos[cam])
    assert 0 < moved <= 0.10 + 1e-9
    assert not np.allclose(env.physics.data.cam_xmat[cam], nominal.physics.data.cam_xmat[cam])

    env = _env(cab, "camera_fov=strong")
    ratio = env.physics.model.cam_fovy[cam] / m0.cam_fovy[cam]
    assert ratio != 1.0 and abs(ratio - 1) <= 0.15 + 1e-9
    view = env.task.camera_view(env.physics)
    assert abs(view.intrinsics.fy - 128 / np.tan(np.radians(env.physics.model.cam_fovy[cam]) / 2)) < 1e-9

    env = _env(cab, "light=strong")
    assert not np.allclose(env.physics.model.light_diffuse, m0.light_diffuse)
    assert not np.allclose(env.physics.model.light_dir, m0.light_dir)

    env = _env(cab, "texture=strong")
    floor = m0.name2id("floor", "geom")
    assert env.physics.model.mat_texid[env.physics.model.geom_matid[floor]].tolist() != \
        m0.mat_texid[m0.geom_matid[floor]].tolist()
    handle = env.task.target.handle_geoms[0]
    hid = m0.name2id(f"cabinet/{handle}", "geom")
    assert env.physics.model.geom_matid[hid] == m0.geom_matid[hid]  # handles keep their look
    carcass = [i for i in range(m0.ngeom) if m0.geom(i).name.startswith("cabinet/")
               and m0.geom(i).name[len("cabinet/"):] not in env.task._handle_geoms]
    assert any(env.physics.model.geom_matid[i] != m0.geom_matid[i] for i in carcass)

    env = _env(cab, "distractors=strong")
    names = [env.physics.model.geom(i).name for i in range(env.physics.model.ngeom)]
    extra = [n for n in names if n.startswith("distractor")]
    assert extra and all(env.physics.model.geom_contype[names.index(n)] == 1 for n in extra)
    lo, _ = env.task.cabinet.bounds
    for n in extra:  # none in front of the cabinet
        assert env.physics.data.geom_xpos[names.index(n)][0] > lo[0]

    env = _env(cab, "physics=strong")
    m1, f = env.physics.model, env.task.shift["physics"]
    dof = int(env.physics.bind(env.task.cabinet.joint_element(env.task.target.joint)).dofadr)
    assert np.isclose(m1.dof_damping[dof], m0.dof_damping[dof] * f["joint_damping"])
    assert np.isclose(m1.dof_frictionloss[dof], m0.dof_frictionloss[dof] * f["joint_frictionloss"])
    assert np.isclose(m1.geom_friction[hid, 0], m0.geom_friction[hid, 0] * f["handle_friction"])
    body = m1.dof_bodyid[dof]
    assert np.isclose(m1.body_mass[body], m0.body_mass[body] * f["mass"])
    env.task.shift.apply_model(env.physics, env.task.cabinet, env.task._handle_geoms)  # again: no compounding
    assert np.isclose(m1.body_mass[body], m0.body_mass[body] * f["mass"])

    env = _env(cab, "hand_start=strong")  # the hand root starts back, out and up or down, still out of view
    moved = env.task.start_pose[0] - nominal.task.start_pose[0]
    back, out, up = env.task.shift["hand_start"]
    assert np.any(moved != 0) and np.isclose(moved[0], back) and -0.15 <= back <= 0
    assert moved[1] >= out - 1e-9 and abs(moved[2]) <= 0.25 + 1e-9
    assert np.allclose(env.physics.data.mocap_pos[0], env.task.start_pose[0])
    u, _ = env.task.camera_view(env.physics).project(env.task.start_pose[0][None])[0]
    assert u < 0  # beside the image, as the nominal start


def test_depth_noise_and_instruction(proc_cabinets):
    from opend_mj.evaluation.episode import EpisodeJob
    from opend_mj.evaluation.runner import instruction_for
    from opend_mj.language import canonical_instruction
    from opend_mj.sim.camera import RGBDCamera

    cab = proc_cabinets[0].dir
    env = _env(cab, "depth_noise=strong")
    with RGBDCamera(env.physics, "front", 64, 64) as cam:
        rgb, depth = cam.render()
    noisy = env.task.sense_depth(rgb, depth)
    assert noisy.shape == depth.shape and (noisy == 0).mean() > 0.01 and not np.array_equal(noisy, depth)
    ok = noisy > 0
    sigma = 3.0 * (0.0012 + 0.0019 * (depth[ok] - 0.4) ** 2)  # the strong level's noise model
    z = (noisy[ok] - depth[ok]) / sigma
    assert np.abs(z).max() < 6 and 0.8 < z.std() < 1.2  # noise growing with distance as modelled
    env.reset()
    assert np.array_equal(env.task.sense_depth(rgb, depth), noisy)  # each episode: the same draws
    assert _env(cab).task.sense_depth(rgb, depth) is depth  # nominal: the rendered depth itself
    assert _env(cab).task.sense_depth(rgb, depth, frames=8) is depth
    # eight frames of the still scene, fused: about a third of one frame's noise, fewer holes
    fused = _env(cab, "depth_noise=strong").task.sense_depth(rgb, depth, frames=8)
    seen = depth > 0
    both = seen & (noisy > 0) & (fused > 0)
    assert np.median(np.abs(fused - depth)[both]) < 0.5 * np.median(np.abs(noisy - depth)[both])
    assert (fused[seen] == 0).mean() < 0.5 * (noisy[seen] == 0).mean()

    from opend_mj.sim.cabinet import load_cabinet_info

    targets = load_cabinet_info(cab)["targets"]
    for level in ("mild", "strong"):  # the task rewords every target of the scene (`set_target` too)
        env = _env(cab, f"instruction={level}", joint=targets[0]["joint"])
        for target in targets:
            job = EpisodeJob(cabinet="c", cabinet_dir=str(cab), joint=target["joint"], split="test", hand="franka",
                             solver="oracle", perturb=f"instruction={level}")
            assert instruction_for(job) is None  # drawn with the scene's perturbation, applied by the task
            env.task.set_target(target["joint"], instruction_for(job))
            worded = env.task.instruction
            assert worded != target["instruction"]
            assert canonical_instruction(worded) == canonical_instruction(target["instruction"])


def test_nominal_records_keep_their_keys():
    """Records without a perturbation carry no ``perturb`` field, and old results files resume."""
    from opend_mj.evaluation.episode import EpisodeJob, episode_key, record_fields, video_name

    job = EpisodeJob(cabinet="c", cabinet_dir="d", joint="j", split="test", hand="allegro", solver="oracle")
    assert "perturb" not in record_fields(job)
    old = {"cabinet": "c", "joint": "j", "hand": "allegro", "solver": "oracle", "split": "test", "seed": 0,
           "light_scale": 1.0, "pull": "arc"}
    assert episode_key(old) == job.key()
    assert video_name(job) == "c_j_allegro_oracle_s0_l1_arc.mp4"
    perturbed = EpisodeJob(**{**job.__dict__, "perturb": "light=mild"})
    assert record_fields(perturbed)["perturb"] == "light=mild" and perturbed.key() != job.key()
    assert video_name(perturbed).endswith("_xlight-mild.mp4")


def test_run_refuses_before_any_episode(small_dataset, tmp_path, monkeypatch):
    from opend_mj.cli import main
    from opend_mj.sim import perturb

    out = tmp_path / "r.jsonl"
    base = ["run", "--cabinets", str(small_dataset), "--limit", "2", "--out", str(out)]
    for bad, word in ((["--perturb", "fog=mild"], "fog"), (["--perturb", "light=extreme"], "extreme")):
        res = CliRunner().invoke(main, base + bad)
        assert res.exit_code == 2 and word in res.output and len(res.output.strip().splitlines()) == 1
    monkeypatch.setattr(perturb, "DEFAULT_CONFIG", PerturbConfig(camera_clearance_m=50.0))
    res = CliRunner().invoke(main, base + ["--perturb", "camera_pose=mild"])
    assert res.exit_code == 2 and "camera inside the cabinet" in res.output
    assert len(res.output.strip().splitlines()) == 1 and not out.exists()
    monkeypatch.setattr(perturb, "DEFAULT_CONFIG", PerturbConfig(hand_clearance_m=50.0))
    res = CliRunner().invoke(main, base + ["--perturb", "distractors=mild"])
    assert res.exit_code == 2 and "in the hand's path" in res.output and not out.exists()


def test_run_and_robustness_table(small_dataset, tmp_path):
    """`opend run --perturb` puts the perturbation into every record; `opend robustness` tabulates
    nominal against each condition with intervals, as Markdown, JSON and a plot."""
    from opend_mj.cli import main

    rec = tmp_path / "rec"
    res = CliRunner().invoke(main, ["robustness", "--solver", "oracle", "--hand", "franka", "--cabinets",
                                    str(small_dataset), "--limit", "1", "--axis", "physics",
                                    "--records", str(rec), "--out", str(tmp_path / "rob")])
    assert res.exit_code == 0, res.output
    records = [json.loads(line) for line in (rec / "oracle_test.jsonl").read_text().splitlines()]
    assert sorted(r.get("perturb") or "-" for r in records) == ["-", "physics=mild", "physics=strong"]
    table = json.loads((tmp_path / "rob.json").read_text())
    row = table["rows"][0]
    assert set(row["conditions"]) == {"nominal", "physics=mild", "physics=strong"}
    cell = row["conditions"]["physics=strong"]
    assert cell["episodes"] == 1 and "delta" in cell and len(cell["ci95"]) == 2
    assert "| oracle | franka |" in (tmp_path / "rob.md").read_text()
    assert (tmp_path / "rob.png").stat().st_size > 1000
    # another axis into the same records: its table holds nominal and that axis only
    res = CliRunner().invoke(main, ["robustness", "--solver", "oracle", "--hand", "franka", "--cabinets",
                                    str(small_dataset), "--limit", "1", "--axis", "light",
                                    "--records", str(rec), "--out", str(tmp_path / "light")])
    assert res.exit_code == 0, res.output
    light = json.loads((tmp_path / "light.json").read_text())["rows"][0]["conditions"]
    assert set(light) == {"nominal", "light=mild", "light=strong"}
    from opend_mj.evaluation.report import results_markdown

    (tmp_path / "results" / "robustness").mkdir(parents=True)
    (tmp_path / "results" / "robustness" / "generated.json").write_text((tmp_path / "rob.json").read_text())
    page = results_markdown(tmp_path / "results")
    assert "## Robustness" in page and "### generated cabinets" in page and "| oracle | franka |" in page
    assert "opend robustness --solver oracle" in page
    res = CliRunner().invoke(main, ["robustness", "--solver", "oracle", "--axis", "fog", "--cabinets",
                                    str(small_dataset)])
    assert res.exit_code == 2 and "fog" in res.output


def test_axes_documented():
    from pathlib import Path

    doc = (Path(__file__).parents[2] / "docs" / "robustness.md").read_text()
    for axis in AXES:
        assert f"`{axis}`" in doc


def test_sensor_depth_is_a_seeded_draw_and_fusing_frames_fills_holes():
    """`sensor_depth`: the depth_noise sensor's image of a render, for training solvers on it; the
    same seed gives the same image; fusing frames leaves fewer holes and less noise."""
    from opend_mj.sim.depth_sensor import sensor_depth

    depth = np.full((64, 64), 2.0, np.float32)
    depth[20:40, 20:40] = 1.95  # a raised square: edges that drop out
    rgb = np.full((64, 64, 3), 128, np.uint8)
    one = sensor_depth(rgb, depth, "strong", 3)
    assert np.array_equal(one, sensor_depth(rgb, depth, "strong", 3))
    assert not np.array_equal(one, sensor_depth(rgb, depth, "strong", 4))
    eight = sensor_depth(rgb, depth, "strong", 3, frames=8)
    assert (eight == 0).sum() < (one == 0).sum()
    flat = (slice(45, 60), slice(5, 60))
    assert np.std(eight[flat][eight[flat] > 0]) < np.std(one[flat][one[flat] > 0])


def test_robustness_summary_gives_each_entry_its_worst_drops():
    """docs/results.md's robustness rows: per solver and hand, the largest drop at each level and where,
    and the conditions beyond their band."""
    from opend_mj.evaluation.robustness import table_summary_markdown

    def cell(rate, delta, ok=True):
        return {"rate": rate, "ci95": [rate - 5, rate + 5], "successes": int(rate), "episodes": 100,
                "delta": delta, "within_band": ok}

    table = {"bands": {"mild": 5.0, "strong": 15.0}, "rows": [{"solver": "fasterrcnn", "hand": "allegro",
             "conditions": {"nominal": {"rate": 90.0, "ci95": [85.0, 95.0], "successes": 90, "episodes": 100},
                            "light=mild": cell(89.0, -1.0), "light=strong": cell(84.0, -6.0),
                            "depth_noise=mild": cell(88.0, -2.0), "depth_noise=strong": cell(70.0, -20.0, False)}}]}
    row = next(line for line in table_summary_markdown(table).splitlines() if line.startswith("| fasterrcnn"))
    assert row.split(" | ")[2:] == ["2", "90.0 [85.0-95.0] (90/100)", "-2.0 (`depth_noise`)",
                                    "-20.0 (`depth_noise`)", "`depth_noise=strong` |"]
