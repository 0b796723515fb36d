"""A compiled generated scene with a hand in MJX (JAX on CPU): accepted whole, and stepped in a batch.

The MJX work runs in a child Python process: JAX starts threads when it is imported, and a test
process that later forks (the Ray and process-pool tests do) must not have it loaded.
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys

import pytest

if importlib.util.find_spec("jax") is None or importlib.util.find_spec("mujoco.mjx") is None:
    pytest.skip("mujoco-mjx / JAX not installed: the optional extra '.[mjx]' (pip install -e '.[mjx]' or make install-mjx)",
                allow_module_level=True)

from opend_mj.assets.layout import load_manifest  # noqa: E402

_CHILD = """
import json, sys
import mujoco, numpy as np
from opend_mj.sim.batched import batched_steps, mjx_report, scene_model

cabinet_dir, joint, step = sys.argv[1], sys.argv[2], sys.argv[3] == "step"
model, data = scene_model(cabinet_dir, joint, hand="allegro")
report = mjx_report(model)
out = {"accepted": report.accepted, "error": report.error, "pairs": report.collision_pairs,
       "pair_types": report.pair_types, "max_hull_vertices": report.max_hull_vertices,
       "cone": report.cone, "integrator": report.integrator}
if step:
    model.geom_conaffinity[model.geom_type != mujoco.mjtGeom.mjGEOM_PLANE] = 0  # the floor's contacts only
    out["floor_pairs"] = mjx_report(model).collision_pairs
    qpos, _ = batched_steps(model, data, batch=2, steps=1)
    reference = mujoco.MjData(model)
    mujoco.mj_copyData(reference, model, data)
    mujoco.mj_step(model, reference)
    out["shape"] = list(qpos.shape)
    out["copies_equal"] = bool(np.array_equal(qpos[0], qpos[1]))
    out["max_dq"] = float(np.max(np.abs(qpos[0] - reference.qpos)))
    out["nq"] = int(model.nq)
print("RESULT " + json.dumps(out))
"""


def _run_child(small_dataset, mode: str) -> dict:
    cab, tgt = load_manifest(small_dataset).targets("all")[0]
    env = {**os.environ, "JAX_PLATFORMS": "cpu"}
    proc = subprocess.run([sys.executable, "-c", _CHILD, str(small_dataset / cab["path"]), tgt["joint"], mode],
                          capture_output=True, text=True, env=env, timeout=1800)
    assert proc.returncode == 0, proc.stderr[-3000:]
    line = next(ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT "))
    return json.loads(line[len("RESULT "):])


def test_mjx_accepts_a_whole_benchmark_scene(small_dataset):
    out = _run_child(small_dataset, "report")
    assert out["accepted"], out["error"]
    assert out["cone"] == "mjCONE_ELLIPTIC" and out["integrator"] == "mjINT_IMPLICITFAST"
    # the hand collides with the cabinet and the floor: every pair has an MJX collision function
    assert out["pairs"] > 50 and any("box" in k for k in out["pair_types"])
    assert out["max_hull_vertices"] <= 64


@pytest.mark.slow
def test_a_batch_steps_in_mjx_as_mj_step_does(small_dataset):
    """A batch of 2 copies of the scene, one physics step in MJX against ``mj_step``.

    XLA compiles a whole MJX step into one program, with one collision kernel per group of geom
    types: for the full scene (365 pairs, 9 groups) that took 6 minutes on this project's 2 shared
    CPU cores. The step here keeps every body, joint, actuator, the mocap weld and implicitfast, and
    only the floor's contacts (the hand starts in free air, so the scene's other contacts are not
    active at this state anyway).
    """
    out = _run_child(small_dataset, "step")
    assert out["accepted"], out["error"]
    assert out["floor_pairs"] > 0
    assert out["shape"] == [2, out["nq"]] and out["copies_equal"]
    assert out["max_dq"] < 1e-5
