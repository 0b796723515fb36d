"""A compiled generated scene with a hand in MJX (JAX on CPU): accepted whole, and stepped in a batch."""

from __future__ import annotations

import os

import numpy as np
import pytest

pytest.importorskip("jax", reason="JAX not installed (pip install -e '.[mjx]')")
pytest.importorskip("mujoco.mjx", reason="mujoco-mjx not installed (pip install -e '.[mjx]')")
os.environ.setdefault("JAX_PLATFORMS", "cpu")

import mujoco  # noqa: E402

from opend_mj.assets.layout import load_manifest  # noqa: E402
from opend_mj.sim.batched import batched_steps, mjx_report, scene_model  # noqa: E402


@pytest.fixture(scope="module")
def allegro_scene(small_dataset):
    cab, tgt = load_manifest(small_dataset).targets("all")[0]
    return scene_model(small_dataset / cab["path"], tgt["joint"], hand="allegro")


def test_mjx_accepts_a_whole_benchmark_scene(allegro_scene):
    model, _ = allegro_scene
    report = mjx_report(model)
    assert report.accepted, report.error
    assert report.cone == "mjCONE_ELLIPTIC" and report.integrator == "mjINT_IMPLICITFAST"
    # the hand collides with the cabinet and the floor: every pair has an MJX collision function
    assert report.collision_pairs > 50 and any("box" in k for k in report.pair_types)
    assert report.max_hull_vertices <= 64


@pytest.mark.slow
def test_a_batch_steps_in_mjx_as_mj_step_does(allegro_scene):
    """A batch of 2 copies of the scene, one physics step in MJX against ``mj_step``.

    XLA compiles a whole MJX step into one program, with one collision kernel per group of geom
    types: for the full scene (365 pairs, 9 groups) that took 6 minutes on this project's 2 shared
    CPU cores. The step here keeps every body, joint, actuator, the mocap weld and implicitfast, and
    only the floor's contacts (the hand starts in free air, so the scene's other contacts are not
    active at this state anyway): 2 groups, a few minutes under load, well under one idle.
    """
    model, data = allegro_scene
    contype, conaffinity = model.geom_contype.copy(), model.geom_conaffinity.copy()
    planes = model.geom_type == mujoco.mjtGeom.mjGEOM_PLANE
    model.geom_conaffinity[~planes] = 0
    try:
        assert mjx_report(model).collision_pairs > 0
        qpos, _ = batched_steps(model, data, batch=2, steps=1)
        reference = mujoco.MjData(model)
        mujoco.mj_copyData(reference, model, data)
        mujoco.mj_step(model, reference)
    finally:
        model.geom_contype[:], model.geom_conaffinity[:] = contype, conaffinity
    assert qpos.shape == (2, model.nq)
    assert np.array_equal(qpos[0], qpos[1])
    assert np.max(np.abs(qpos[0] - reference.qpos)) < 1e-5
