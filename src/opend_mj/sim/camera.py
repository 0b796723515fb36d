"""The front RGB-D camera: placement, pinhole model, rendering, projection.

Conventions
-----------
* World: z up, metres. The cabinet faces -x; the camera stands at negative x and looks along +x,
  so image-left is world +y.
* MuJoCo cameras look along their local **-z** axis, with local +x = image right and local +y =
  image up. ``data.cam_xmat`` holds those three axes as the *columns* of a 3x3 matrix.
* Image coordinates are continuous pixels ``(u, v)``: ``u`` to the right, ``v`` down, origin at the
  top-left corner of the top-left pixel. Pixel ``[row, col]`` covers ``[col, col+1) x [row, row+1)``
  and its centre is ``(col + 0.5, row + 0.5)``. So ``cx = width / 2``, ``cy = height / 2``, and boxes
  from :func:`box_in_image` are in the same convention as torchvision boxes (``x1, y1, x2, y2``).
* ``depth`` is planar depth in metres (distance along the optical axis, not along the ray), which
  is what :class:`mujoco.Renderer` returns with depth rendering enabled.
* MuJoCo's ``fovy`` is the vertical field of view; pixels are square, so ``fx == fy``.
"""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

from dataclasses import dataclass  # noqa: E402
from typing import Sequence  # noqa: E402

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from opend_mj.transforms import look_rotation  # noqa: E402

__all__ = [
    "CameraPose",
    "CameraIntrinsics",
    "CameraView",
    "RGBDCamera",
    "place_camera",
    "add_camera",
    "camera_view",
    "pixel_to_world",
    "world_to_pixel",
    "box_corners",
    "geom_box_corners",
    "box_in_image",
]


# --------------------------------------------------------------------------------------------------
# Placement
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CameraPose:
    """A camera pose in the world frame.

    ``rot`` has the camera axes (right, up, backward) as columns, like ``data.cam_xmat``.
    """

    pos: np.ndarray  # (3,)
    rot: np.ndarray  # (3, 3)
    fovy: float  # degrees, vertical

    @property
    def quat(self) -> np.ndarray:
        """Orientation as a MuJoCo quaternion (w, x, y, z)."""
        q = np.zeros(4)
        mujoco.mju_mat2Quat(q, np.ascontiguousarray(self.rot).reshape(-1))
        return q

    @property
    def xyaxes(self) -> np.ndarray:
        """Orientation as MJCF ``xyaxes`` (image-right then image-up, world frame)."""
        return np.concatenate([self.rot[:, 0], self.rot[:, 1]])

    @property
    def forward(self) -> np.ndarray:
        """Unit viewing direction in the world frame."""
        return -self.rot[:, 2]


def place_camera(
    bounds_min: Sequence[float],
    bounds_max: Sequence[float],
    fovy_deg: float = 45.0,
    margin: float = 1.15,
    shift: Sequence[float] = (0.0, 0.0, 0.0),
    pitch_deg: float = 12.0,
    aspect: float = 1.0,
    min_distance: float = 0.3,
    shift_tolerance: float = 0.1,
) -> CameraPose:
    """A camera in front (-x side) of an axis-aligned box, looking along +x and ``pitch_deg`` down.

    The camera aims at the box centre and backs off along its viewing direction until all eight box
    corners fall inside the image shrunk by ``margin`` (1.15: the box spans at most 1/1.15 of the
    half-width and half-height). ``aspect`` is width / height of the image that will be rendered.
    ``shift`` (metres, world frame) is added to the position afterwards without changing the
    orientation; training data uses up to 0.1 m per axis. The fit is made for the box grown by
    ``shift_tolerance`` on every side, so any shift up to that much per axis keeps the whole box in
    view, and the unshifted pose does not depend on the shift (train and test cameras agree).
    """
    tol = float(shift_tolerance)
    lo = np.asarray(bounds_min, float) - tol
    hi = np.asarray(bounds_max, float) + tol
    centre = 0.5 * (lo + hi)
    p = np.deg2rad(pitch_deg)
    fwd = np.array([np.cos(p), 0.0, -np.sin(p)])
    rot = look_rotation(fwd)
    right, up = rot[:, 0], rot[:, 1]
    tan_v = np.tan(np.deg2rad(fovy_deg) / 2.0)
    tan_h = tan_v * aspect
    corners = box_corners(lo, hi) - centre
    # Moving along fwd leaves the right/up components of each corner unchanged; the forward
    # component is (corner . fwd) + t.  Need |r| * margin <= tan_h * f and |u| * margin <= tan_v * f.
    r = np.abs(corners @ right)
    u = np.abs(corners @ up)
    f0 = corners @ fwd
    need = np.maximum(r * margin / tan_h, u * margin / tan_v) - f0
    t = float(max(need.max(), (f0.max() + min_distance)))
    pos = centre - t * fwd + np.asarray(shift, float)
    return CameraPose(pos=pos, rot=rot, fovy=float(fovy_deg))


def add_camera(mjcf_root, pose: CameraPose, name: str = "front"):
    """Add a fixed camera at ``pose`` to the worldbody of a dm_control MJCF model; returns it.

    To move it per episode without recompiling, write ``physics.bind(cam).pos`` / ``.quat`` and
    call ``physics.forward()`` before rendering.
    """
    return mjcf_root.worldbody.add(
        "camera",
        name=name,
        pos=[float(x) for x in pose.pos],
        quat=[float(x) for x in pose.quat],
        fovy=float(pose.fovy),
    )


# --------------------------------------------------------------------------------------------------
# Pinhole model
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CameraIntrinsics:
    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    @classmethod
    def from_fovy(cls, fovy_deg: float, width: int, height: int) -> "CameraIntrinsics":
        fy = 0.5 * height / np.tan(np.deg2rad(fovy_deg) / 2.0)
        return cls(fx=fy, fy=fy, cx=width / 2.0, cy=height / 2.0, width=int(width), height=int(height))

    @property
    def matrix(self) -> np.ndarray:
        """The 3x3 K matrix (for a camera frame with z forward and y down, as in OpenCV)."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class CameraView:
    """Intrinsics plus world pose of a camera at one instant: enough to project and backproject."""

    intrinsics: CameraIntrinsics
    pos: np.ndarray  # (3,) world
    rot: np.ndarray  # (3,3) columns = camera right, up, backward in world

    @property
    def width(self) -> int:
        return self.intrinsics.width

    @property
    def height(self) -> int:
        return self.intrinsics.height

    def world_to_camera(self, points_world) -> np.ndarray:
        p = np.asarray(points_world, float)
        return (p - self.pos) @ self.rot  # == R^T (p - pos), row-wise

    def project(self, points_world, return_depth: bool = False):
        """World points (..., 3) -> continuous pixels (..., 2) as (u, v); optionally planar depth.

        Points behind the camera get NaN pixels.
        """
        pc = self.world_to_camera(points_world)
        depth = -pc[..., 2]
        k = self.intrinsics
        with np.errstate(divide="ignore", invalid="ignore"):
            u = k.cx + k.fx * pc[..., 0] / depth
            v = k.cy - k.fy * pc[..., 1] / depth
        uv = np.stack([u, v], axis=-1)
        uv[depth <= 0] = np.nan
        return (uv, depth) if return_depth else uv

    def backproject(self, u, v, depth) -> np.ndarray:
        """Continuous pixel(s) (u, v) with planar depth (metres) -> world point(s) (..., 3)."""
        u = np.asarray(u, float)
        v = np.asarray(v, float)
        d = np.asarray(depth, float)
        k = self.intrinsics
        xc = (u - k.cx) * d / k.fx
        yc = -(v - k.cy) * d / k.fy
        pc = np.stack(np.broadcast_arrays(xc, yc, -d), axis=-1)
        return pc @ self.rot.T + self.pos

    def pixel_to_point(self, row: int, col: int, depth_image: np.ndarray) -> np.ndarray:
        """World point seen at integer pixel ``[row, col]`` of a depth image."""
        return self.backproject(col + 0.5, row + 0.5, depth_image[row, col])

    def point_cloud(self, depth_image: np.ndarray) -> np.ndarray:
        """(H, W, 3) world points for every pixel of a depth image."""
        h, w = depth_image.shape
        vv, uu = np.meshgrid(np.arange(h) + 0.5, np.arange(w) + 0.5, indexing="ij")
        return self.backproject(uu, vv, depth_image)

    @classmethod
    def from_arrays(cls, camera_K, camera_pose) -> "CameraView":
        """The view of an agent's ``camera_K`` (3 x 3, OpenCV-style) and ``camera_pose`` (4 x 4,
        camera to world, columns right, up, backward, position); the image is ``2 cx`` x ``2 cy``
        pixels (the principal point is the image centre here)."""
        k = np.asarray(camera_K, float)
        pose = np.asarray(camera_pose, float)
        intrinsics = CameraIntrinsics(fx=float(k[0, 0]), fy=float(k[1, 1]), cx=float(k[0, 2]), cy=float(k[1, 2]),
                                      width=int(round(2 * k[0, 2])), height=int(round(2 * k[1, 2])))
        return cls(intrinsics=intrinsics, pos=pose[:3, 3].copy(), rot=pose[:3, :3].copy())


def pixel_to_world(u, v, depth, camera_K, camera_pose) -> np.ndarray:
    """World points (..., 3; m) seen at continuous pixels ``(u, v)`` with planar ``depth`` (m).

    Arrays broadcast together. ``u`` runs right, ``v`` down, and the pixel ``depth_image[row, col]``
    is seen at ``u = col + 0.5``, ``v = row + 0.5``. ``camera_K`` is OpenCV-style (a camera frame
    with x right, y down, z forward), ``camera_pose`` maps MuJoCo's camera frame (x right, y up, z
    backward) to the world, so the camera-frame point is ``((u - cx) d / fx, -(v - cy) d / fy, -d)``:
    y and z flip sign between the two. `CameraView.backproject` does the arithmetic.
    """
    return CameraView.from_arrays(camera_K, camera_pose).backproject(u, v, depth)


def world_to_pixel(points, camera_K, camera_pose) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(u, v, depth)`` of world points (..., 3; m): continuous pixels and planar depth (m), each
    of shape (...); the inverse of :func:`pixel_to_world`. Points behind the camera (depth <= 0)
    get NaN pixels."""
    uv, depth = CameraView.from_arrays(camera_K, camera_pose).project(points, return_depth=True)
    return uv[..., 0], uv[..., 1], np.asarray(depth)


def _raw_model_data(physics_or_model_data, data=None):
    """Accept a dm_control Physics, a (MjModel, MjData) pair, or model and data separately."""
    if data is not None:
        return physics_or_model_data, data
    obj = physics_or_model_data
    if isinstance(obj, (tuple, list)):
        return obj[0], obj[1]
    if hasattr(obj, "model") and hasattr(obj, "data"):  # dm_control Physics
        m, d = obj.model, obj.data
        return getattr(m, "ptr", m), getattr(d, "ptr", d)
    raise TypeError("expected a dm_control Physics, (MjModel, MjData), or model and data")


def _camera_id(model, name_or_id) -> int:
    if isinstance(name_or_id, (int, np.integer)):
        return int(name_or_id)
    cid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, name_or_id)
    if cid < 0:
        names = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_CAMERA, i) for i in range(model.ncam)]
        raise KeyError(f"no camera named {name_or_id!r}; cameras: {names}")
    return cid


def camera_view(physics_or_model, name="front", width=256, height=256, data=None) -> CameraView:
    """The :class:`CameraView` of a model camera from the current ``cam_xpos``/``cam_xmat``.

    Needs kinematics to be current (``mj_forward`` / ``physics.forward()`` after moving things).
    """
    model, d = _raw_model_data(physics_or_model, data)
    cid = _camera_id(model, name)
    k = CameraIntrinsics.from_fovy(float(model.cam_fovy[cid]), width, height)
    return CameraView(
        intrinsics=k,
        pos=np.array(d.cam_xpos[cid], float),
        rot=np.array(d.cam_xmat[cid], float).reshape(3, 3),
    )


# --------------------------------------------------------------------------------------------------
# Rendering
# --------------------------------------------------------------------------------------------------


class _ProcessGLContext:
    """One off-screen OpenGL context per process, shared by every renderer made here.

    Making a context and its first MuJoCo render context costs about 0.1 s on a CPU (llvmpipe
    compiles its shaders per context); a render context for a further model in the same GL
    context costs a few milliseconds. The context lives as long as the process: ``free`` is a
    no-op, so closing a renderer frees only its own MuJoCo render context.
    """

    _context = None
    _pid = None

    @classmethod
    def get(cls) -> "_ProcessGLContext":
        if cls._context is None or cls._pid != os.getpid():
            from mujoco import gl_context

            if gl_context.GLContext is None:
                raise RuntimeError("no off-screen OpenGL backend (set MUJOCO_GL=egl or osmesa)")
            cls._context = cls(gl_context.GLContext(64, 64))
            cls._pid = os.getpid()
        return cls._context

    def __init__(self, context):
        self._gl = context

    def make_current(self) -> None:
        self._gl.make_current()

    def free(self) -> None:
        pass


class SharedContextRenderer(mujoco.Renderer):
    """``mujoco.Renderer`` on the process's shared GL context (see `_ProcessGLContext`).

    Same images and API as ``mujoco.Renderer`` (rendering goes to the model's off-screen buffer,
    whatever the context's own size); only the set-up differs.
    """

    def __init__(self, model: mujoco.MjModel, height: int = 240, width: int = 320, max_geom: int = 2000):
        self._gl_context = None
        self._mjr_context = None
        vis = model.vis.global_
        if width > vis.offwidth or height > vis.offheight:
            raise ValueError(f"image {width}x{height} larger than the model's off-screen buffer "
                             f"{vis.offwidth}x{vis.offheight}; raise <visual><global offwidth offheight>")
        self._width, self._height, self._model = int(width), int(height), model
        self._scene = mujoco.MjvScene(model=model, maxgeom=max_geom)
        self._scene_option = mujoco.MjvOption()
        self._rect = mujoco.MjrRect(0, 0, self._width, self._height)
        self._gl_context = _ProcessGLContext.get()
        self._gl_context.make_current()
        self._mjr_context = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150.value)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN.value, self._mjr_context)
        self._mjr_context.readDepthMap = mujoco.mjtDepthMap.mjDEPTH_ZEROFAR
        self._depth_rendering = False
        self._segmentation_rendering = False


def make_renderer(model: mujoco.MjModel, height: int, width: int) -> mujoco.Renderer:
    """A renderer for ``model``: on the process's shared GL context where that works."""
    try:
        return SharedContextRenderer(model, height=height, width=width)
    except ValueError:
        raise
    except Exception:  # noqa: BLE001 (a MuJoCo version whose Renderer differs: the plain one)
        return mujoco.Renderer(model, height=height, width=width)


class RGBDCamera:
    """Renders RGB (uint8 HxWx3), depth (float32 metres) and segmentation from a model camera.

    Works with a dm_control ``mjcf.Physics`` or raw ``mujoco.MjModel``/``MjData``. Holds one
    ``mujoco.Renderer``; call :meth:`close` (or use as a context manager) when done.
    The model's ``visual/global`` ``offwidth``/``offheight`` must be at least ``width``/``height``.
    """

    def __init__(self, physics_or_model_data, name="front", width: int = 256, height: int = 256, data=None):
        self._model, self._data = _raw_model_data(physics_or_model_data, data)
        self.name = name
        self.width = int(width)
        self.height = int(height)
        self.cam_id = _camera_id(self._model, name)
        vis = self._model.vis.global_
        if vis.offwidth < self.width or vis.offheight < self.height:
            raise ValueError(
                f"offscreen buffer {vis.offwidth}x{vis.offheight} smaller than {self.width}x{self.height}; "
                "raise <visual><global offwidth offheight>"
            )
        self._renderer = make_renderer(self._model, height=self.height, width=self.width)

    # context manager / cleanup
    def close(self) -> None:
        r, self._renderer = getattr(self, "_renderer", None), None
        if r is not None:
            r.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):  # best effort; prefer explicit close()
        try:
            self.close()
        except Exception:
            pass

    @property
    def view(self) -> CameraView:
        return camera_view((self._model, self._data), self.cam_id, self.width, self.height)

    @property
    def intrinsics(self) -> CameraIntrinsics:
        return self.view.intrinsics

    def _update(self, scene_option=None):
        if self._renderer is None:
            raise RuntimeError("RGBDCamera is closed")
        if scene_option is None:
            self._renderer.update_scene(self._data, camera=self.cam_id)
        else:
            self._renderer.update_scene(self._data, camera=self.cam_id, scene_option=scene_option)

    def render_rgb(self, scene_option=None) -> np.ndarray:
        self._update(scene_option)
        return self._renderer.render().copy()

    def render_depth(self, scene_option=None) -> np.ndarray:
        self._update(scene_option)
        self._renderer.enable_depth_rendering()
        try:
            return self._renderer.render().astype(np.float32, copy=True)
        finally:
            self._renderer.disable_depth_rendering()

    def render_segmentation(self, scene_option=None) -> np.ndarray:
        """(H, W, 2) int32: [..., 0] object id, [..., 1] object type (mjtObj; geoms are 5); -1 = none."""
        self._update(scene_option)
        self._renderer.enable_segmentation_rendering()
        try:
            return self._renderer.render().copy()
        finally:
            self._renderer.disable_segmentation_rendering()

    def render(self, scene_option=None) -> tuple[np.ndarray, np.ndarray]:
        """(rgb uint8 HxWx3, depth float32 HxW metres) of the current state (one scene update)."""
        self._update(scene_option)
        rgb = self._renderer.render().copy()
        self._renderer.enable_depth_rendering()
        try:
            depth = self._renderer.render().astype(np.float32, copy=True)
        finally:
            self._renderer.disable_depth_rendering()
        return rgb, depth


# --------------------------------------------------------------------------------------------------
# Boxes
# --------------------------------------------------------------------------------------------------


def box_corners(aabb_min, aabb_max) -> np.ndarray:
    """The 8 corners (8, 3) of an axis-aligned box."""
    lo = np.asarray(aabb_min, float)
    hi = np.asarray(aabb_max, float)
    idx = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    return np.where(idx == 0, lo, hi)


def geom_box_corners(physics_or_model, geom, data=None) -> np.ndarray:
    """World corners (8, 3) of a geom's oriented bounding box (MuJoCo ``geom_aabb``, current pose).

    ``geom`` is an id or a full geom name (e.g. ``"cabinet/handle_link_1_0"``).
    """
    model, d = _raw_model_data(physics_or_model, data)
    gid = geom if isinstance(geom, (int, np.integer)) else mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, geom)
    if gid < 0:
        raise KeyError(f"no geom {geom!r}")
    aabb = np.asarray(model.geom_aabb[gid], float)  # centre(3), half-size(3) in the geom frame
    local = box_corners(aabb[:3] - aabb[3:], aabb[:3] + aabb[3:])
    rot = np.asarray(d.geom_xmat[gid], float).reshape(3, 3)
    return local @ rot.T + np.asarray(d.geom_xpos[gid], float)


def box_in_image(points_or_min, camera, aabb_max=None, clip: bool = True):
    """Image box ``(u0, v0, u1, v1)`` enclosing a 3D box, or ``None`` if it is not in view.

    ``points_or_min``: either world points (N, 3) (e.g. from :func:`geom_box_corners`) or, with
    ``aabb_max`` given, the min corner of an axis-aligned world box. ``camera``: a
    :class:`CameraView` or :class:`RGBDCamera`. Points behind the camera are dropped; with
    ``clip`` the box is clipped to ``[0, width] x [0, height]``.
    """
    view = camera.view if isinstance(camera, RGBDCamera) else camera
    if aabb_max is not None:
        pts = box_corners(points_or_min, aabb_max)
    else:
        pts = np.asarray(points_or_min, float).reshape(-1, 3)
    uv = view.project(pts)
    uv = uv[np.all(np.isfinite(uv), axis=1)]
    if len(uv) == 0:
        return None
    u0, v0 = uv.min(axis=0)
    u1, v1 = uv.max(axis=0)
    if clip:
        u0, u1 = np.clip([u0, u1], 0.0, view.width)
        v0, v1 = np.clip([v0, v1], 0.0, view.height)
        if u1 <= u0 or v1 <= v0:
            return None
    return (float(u0), float(v0), float(u1), float(v1))
