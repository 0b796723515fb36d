"""`pixel_to_world` / `world_to_pixel`: an agent's camera_K and camera_pose, pixels and world points."""

from __future__ import annotations

import numpy as np
import pytest

from opend_mj.sim.camera import CameraView, pixel_to_world, world_to_pixel


def _arrays(view: CameraView) -> tuple[np.ndarray, np.ndarray]:
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = view.rot, view.pos
    return view.intrinsics.matrix, pose


def test_round_trip_over_arrays(front_view):
    K, pose = _arrays(front_view)
    rng = np.random.default_rng(0)
    u, v = rng.uniform(0, 256, (2, 5, 7))
    depth = rng.uniform(0.3, 4.0, (5, 7))
    points = pixel_to_world(u, v, depth, K, pose)
    assert points.shape == (5, 7, 3)
    u2, v2, d2 = world_to_pixel(points, K, pose)
    assert u2.shape == v2.shape == d2.shape == (5, 7)
    np.testing.assert_allclose(np.stack([u2, v2, d2]), np.stack([u, v, depth]), atol=1e-9)
    # one pixel at a time gives the same point as the array
    np.testing.assert_allclose(pixel_to_world(u[2, 3], v[2, 3], depth[2, 3], K, pose), points[2, 3])


def test_axes_and_sign_flip(front_view):
    """The camera at x = -2 looks along +x, image right is world -y, image up is world +z: a pixel
    above the centre (smaller v) is higher in the world, one right of it (larger u) at smaller y."""
    K, pose = _arrays(front_view)
    centre = pixel_to_world(128.0, 128.0, 2.0, K, pose)
    np.testing.assert_allclose(centre, [0.0, 0.0, 1.0], atol=1e-12)
    up = pixel_to_world(128.0, 28.0, 2.0, K, pose)
    right = pixel_to_world(228.0, 128.0, 2.0, K, pose)
    assert up[2] > 1.0 and abs(up[1]) < 1e-12 and up[0] == pytest.approx(0.0)
    assert right[1] < 0.0 and right[2] == pytest.approx(1.0)
    _, _, behind = world_to_pixel([-3.0, 0.0, 1.0], K, pose)
    assert behind == pytest.approx(-1.0)
    u, v, _ = world_to_pixel([-3.0, 0.0, 1.0], K, pose)
    assert np.isnan(u) and np.isnan(v)  # behind the camera: no pixel


def test_handle_pixels_against_the_simulated_handle(proc_cabinets):
    """In a rendered scene, with the arrays an agent gets: each handle's world centre projects into
    the pixels where the renderer drew that handle, and those pixels, back-projected with the rendered
    depth, land on the handle's world box (within 1 cm), the nearest of them on its front face."""
    import mujoco

    from opend_mj.sim.camera import RGBDCamera
    from opend_mj.sim.scene_reader import SceneReader
    from opend_mj.sim.task import EpisodeSpec, make_environment

    cabinet = proc_cabinets[0]
    env = make_environment(EpisodeSpec(cabinet.dir, cabinet.info["targets"][0]["joint"], "allegro", seed=0))
    checked = 0
    try:
        env.reset()
        physics, task = env.physics, env.task
        reader = SceneReader(env, 256)
        arrays = reader.camera_arrays()
        K, pose = arrays["camera_K"], arrays["camera_pose"]
        handles = {t.joint: [mujoco.mj_name2id(physics.model.ptr, mujoco.mjtObj.mjOBJ_GEOM, f"cabinet/{g}")
                             for g in t.handle_geoms] for t in task.cabinet.targets}
        # the collision geoms' groups only: handle geoms are collision geoms (the visual meshes merge a
        # link's parts), so the renderer draws each handle as its own geom
        option = mujoco.MjvOption()
        option.geomgroup[:] = 0
        for ids in handles.values():
            option.geomgroup[physics.model.geom_group[ids]] = 1
        with RGBDCamera(physics, task.camera.full_identifier, 256, 256) as camera:
            depth = camera.render_depth(option)
            segmentation = camera.render_segmentation(option)
        for target in task.cabinet.targets:
            ids = handles[target.joint]
            corners = task.handle_corners(physics, target)
            lo, hi = corners.min(axis=0), corners.max(axis=0)
            drawn = np.isin(segmentation[..., 0], ids) & (segmentation[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM))
            rows, cols = np.nonzero(drawn)
            if len(rows) < 4:
                continue  # hidden behind the hand or another part
            u, v, d = world_to_pixel((lo + hi) / 2, K, pose)
            assert cols.min() - 1 <= u <= cols.max() + 2 and rows.min() - 1 <= v <= rows.max() + 2, target.joint
            points = pixel_to_world(cols + 0.5, rows + 0.5, depth[rows, cols], K, pose)
            assert np.all(points >= lo - 0.01) and np.all(points <= hi + 0.01), target.joint
            nearest = np.argmin((cols + 0.5 - u) ** 2 + (rows + 0.5 - v) ** 2)
            assert abs(points[nearest, 0] - lo[0]) < 0.01, target.joint  # the handle's front (it faces -x)
            checked += 1
        reader.close()
    finally:
        env.close()
    assert checked >= 2, checked
