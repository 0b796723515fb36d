import os

os.environ.setdefault("MUJOCO_GL", "egl")

import mujoco  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from dm_control import mjcf  # noqa: E402

from opend_mj.sim.camera import (  # noqa: E402
    CameraIntrinsics,
    RGBDCamera,
    box_corners,
    box_in_image,
    camera_view,
    geom_box_corners,
    place_camera,
)
from opend_mj.sim.rooms import RoomArena  # noqa: E402

HX, HY, H = 0.25, 0.45, 1.2
MARK = np.array([-0.45, 0.2, 0.9])  # a small bright sphere in front of the box


def scene(shift=(0, 0, 0), room=0, seed=0):
    arena = RoomArena(room, seed)
    wb = arena.mjcf_model.worldbody
    wb.add("geom", name="standin", type="box", pos=[0, 0, H / 2], size=[HX, HY, H / 2], rgba=[0.3, 0.3, 0.3, 1])
    arena.mjcf_model.asset.add("material", name="glow", rgba=[1, 0, 0, 1], emission=1, specular=0)
    wb.add("geom", name="mark", type="sphere", pos=MARK, size=[0.012], material="glow", contype=0, conaffinity=0)
    pose = place_camera([-HX, -HY, 0], [HX, HY, H], shift=shift)
    arena.add_camera(pose, name="front")
    return arena, pose


@pytest.fixture(scope="module")
def physics():
    arena, _ = scene()
    p = mjcf.Physics.from_mjcf_model(arena.mjcf_model)
    p.forward()
    return p


def test_intrinsics():
    k = CameraIntrinsics.from_fovy(45, 256, 256)
    assert k.fx == k.fy == pytest.approx(128 / np.tan(np.deg2rad(22.5)))
    assert (k.cx, k.cy) == (128, 128)


def test_pose_looks_along_plus_x_and_image_left_is_plus_y():
    pose = place_camera([-HX, -HY, 0], [HX, HY, H])
    assert pose.pos[0] < -1.0 and pose.forward[0] > 0.9
    view = camera_view_from_pose(pose)
    (ul, _), (ur, _) = view.project(np.array([[0, 0.3, 0.6], [0, -0.3, 0.6]]))
    assert ul < ur


def camera_view_from_pose(pose, w=256, h=256):
    from opend_mj.sim.camera import CameraView

    return CameraView(CameraIntrinsics.from_fovy(pose.fovy, w, h), pose.pos, pose.rot)


def test_camera_pose_in_model_matches_placement(physics):
    _, pose = scene()
    view = camera_view(physics, "front")
    np.testing.assert_allclose(view.pos, pose.pos, atol=1e-6)
    np.testing.assert_allclose(view.rot, pose.rot, atol=1e-6)


def test_marker_projects_where_it_shows_up(physics):
    with RGBDCamera(physics, "front", 256, 256) as cam:
        rgb = cam.render_rgb()
        view = cam.view
    red = (rgb[..., 0] > 200) & (rgb[..., 1] < 80) & (rgb[..., 2] < 80)
    assert red.sum() > 3
    rows, cols = np.nonzero(red)
    centroid = np.array([cols.mean() + 0.5, rows.mean() + 0.5])
    uv = view.project(MARK)
    assert np.linalg.norm(uv - centroid) < 1.0


def test_backproject_inverts_project(physics):
    with RGBDCamera(physics, "front", 256, 256) as cam:
        rgb, depth = cam.render()
        view = cam.view
    assert depth.dtype == np.float32 and depth.shape == (256, 256)
    for p in ([-HX, 0.1, 0.6], [-HX, -0.3, 1.0], [-HX, 0.35, 0.2]):
        p = np.array(p)
        (u, v), d = view.project(p, return_depth=True)
        row, col = int(v), int(u)
        assert abs(depth[row, col] - d) < 0.01
        q = view.backproject(u, v, depth[row, col])
        assert np.linalg.norm(q - p) < 0.005
        q2 = view.pixel_to_point(row, col, depth)
        assert abs(q2[0] + HX) < 0.003  # on the front face
    cloud = view.point_cloud(depth)
    assert cloud.shape == (256, 256, 3)


def test_box_fully_in_view_with_shifts():
    corners = box_corners([-HX, -HY, 0], [HX, HY, H])
    for shift in [(0, 0, 0), (0.1, 0.1, 0.1), (-0.1, -0.1, -0.1), (0.1, -0.1, 0.1)]:
        view = camera_view_from_pose(place_camera([-HX, -HY, 0], [HX, HY, H], shift=shift))
        u0, v0, u1, v1 = box_in_image(corners, view, clip=False)
        assert 0 <= u0 < u1 <= 256 and 0 <= v0 < v1 <= 256
    # A wide, tall cabinet too.
    view = camera_view_from_pose(place_camera([-0.5, -0.8, 0], [0.5, 0.8, 2.0]))
    u0, v0, u1, v1 = box_in_image([-0.5, -0.8, 0], view, aabb_max=[0.5, 0.8, 2.0], clip=False)
    assert 0 < u0 and u1 < 256 and 0 < v0 and v1 < 256


def test_box_in_image_matches_rendered_box(physics):
    with RGBDCamera(physics, "front", 128, 128) as cam:
        seg = cam.render_segmentation()
        gid = mujoco.mj_name2id(physics.model.ptr, mujoco.mjtObj.mjOBJ_GEOM, "standin")
        box = box_in_image(geom_box_corners(physics, gid), cam)
    rows, cols = np.nonzero((seg[..., 0] == gid) & (seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM)))
    np.testing.assert_allclose(box, (cols.min(), rows.min(), cols.max() + 1, rows.max() + 1), atol=1.5)


def test_raw_model_and_data():
    arena, _ = scene()
    m = mujoco.MjModel.from_xml_string(arena.mjcf_model.to_xml_string(), arena.mjcf_model.get_assets())
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    with RGBDCamera(m, "front", 64, 48, data=d) as cam:
        rgb, depth = cam.render()
    assert rgb.shape == (48, 64, 3) and depth.shape == (48, 64)
    with RGBDCamera((m, d), "front", 64, 64) as cam:
        assert cam.render_rgb().std() > 1
    with pytest.raises(ValueError):
        RGBDCamera((m, d), "front", 4096, 4096)


def test_shared_context_renderer_gives_mujocos_images(physics):
    """Renderers share one GL context per process; the images are mujoco.Renderer's, to the bit."""
    import mujoco

    from opend_mj.sim.camera import RGBDCamera

    model, data = physics.model.ptr, physics.data.ptr
    for _ in range(2):  # a second renderer on the same (kept) context
        with RGBDCamera(physics, "front", 128, 128) as cam:
            rgb, depth = cam.render()
    ref = mujoco.Renderer(model, height=128, width=128)
    try:
        cid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, "front")
        ref.update_scene(data, camera=cid)
        rgb_ref = ref.render().copy()
        ref.enable_depth_rendering()
        depth_ref = ref.render().copy()
    finally:
        ref.close()
    assert np.array_equal(rgb, rgb_ref)
    assert np.array_equal(depth, depth_ref)
    assert rgb.std() > 5  # a real picture, not a cleared buffer
