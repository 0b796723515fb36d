"""`policy.solvers.locate`: a shipped solver's box and world point from an agent's observation."""

from __future__ import annotations

import numpy as np
import pytest

from opend_mj.policy.handle_box import HandleBox
from opend_mj.policy.solvers import locate


@pytest.fixture(scope="module")
def first_look(proc_cabinets):
    """An agent's first observation of a drawer (instruction, camera arrays, RGB-D), with the true
    image box and world box of its handle."""
    from opend_mj.sim.scene_reader import SceneReader
    from opend_mj.sim.task import EpisodeSpec, make_environment

    cabinet, target = next((c, t) for c in proc_cabinets for t in c.info["targets"] if t["type"] == "drawer")
    env = make_environment(EpisodeSpec(cabinet.dir, target["joint"], "allegro", seed=0))
    try:
        env.reset()
        reader = SceneReader(env, 256)
        obs = {"instruction": env.task.instruction, **reader.camera_arrays()}
        obs["rgb"], obs["depth"] = reader.render()
        reader.close()
        box = env.task.handle_boxes(env.physics)[target["joint"]]
        corners = env.task.handle_corners(env.physics)
    finally:
        env.close()
    return obs, box, corners.min(axis=0), corners.max(axis=0)


class _GivenBox:
    """A solver that answers with a fixed box."""

    def __init__(self, box):
        self.box = box

    def solve(self, rgb, depth, instruction, camera_view):
        return HandleBox(*self.box)


def test_the_true_box_locates_the_handle_in_the_world(first_look):
    obs, box, lo, hi = first_look
    found = locate(obs, solver=_GivenBox(box))
    assert found is not None
    assert np.all(found.point[1:] > lo[1:] - 0.01) and np.all(found.point[1:] < hi[1:] + 0.01)
    assert abs(found.front_x - lo[0]) < 0.01  # the handle's front face (the cabinet faces -x)
    assert found.point[0] >= found.front_x


def test_the_shipped_detector_finds_the_instructed_handle(first_look):
    obs, box, lo, hi = first_look
    found = locate(obs, solver="fasterrcnn")
    assert found is not None
    u, v = found.box.centre
    assert box[0] <= u <= box[2] and box[1] - 2 <= v <= box[3] + 2
    assert np.all(found.point > lo - 0.03) and np.all(found.point < hi + 0.03)


def test_a_ground_truth_solver_is_refused(first_look):
    with pytest.raises(ValueError, match="ground truth"):
        locate(first_look[0], solver="oracle")
