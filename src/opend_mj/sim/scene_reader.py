"""Observations of one compiled scene, read from MjData through indices bound once per scene.

`SceneReader` is what the environments over the dataset (`sim.envs`) and the agent harness
(`evaluation.agents`) read an agent's inputs with. Two paths give the same numbers to the bit:

* `SceneReader.proprio` / `SceneReader.privileged`: one dict of fresh arrays per call, computed the
  straightforward way (the reference).
* `SceneReader.fill`: writes every float observation into one preallocated float64 vector at offsets
  fixed when the layout is bound (`bind_layout`), reading the step's contact list once for both the
  touch vector and the reward's contact term. This is the per-step path of the environments.

Rendering: one renderer per reader, made on first use on the process's shared GL context
(`sim.camera.SharedContextRenderer`), reused for every frame of the scene; rgb and depth are rendered
only where the observation mode asks for them, at the configured size.
"""

from __future__ import annotations

import numpy as np

from opend_mj.sim.hands import HandTouch
from opend_mj.sim.rewards import RewardProbe
from opend_mj.transforms import mat9_to_quat, mat_to_quat

#: The proprioceptive keys in the order `fill` writes them.
PROPRIO_KEYS = ("hand_qpos", "hand_qvel", "root_pos", "root_quat", "root_vel", "grasp_site_pos",
                "grasp_site_quat", "mocap_pos", "mocap_quat", "touch", "time")


class SceneReader:
    """Reads observations (the agent's inputs, optionally ground truth) from one compiled scene.

    Every value is float64 straight from MjData (what the planner's own reads give); renders only
    when asked. ``close()`` frees the renderer.
    """

    def __init__(self, env, image_size: int):
        self.env = env
        self.task = task = env.task
        physics = env.physics
        self.physics = physics
        self.image_size = int(image_size)
        self._data = physics.data.ptr
        self._qpos = np.array([int(a) for a in physics.bind(task.hand.joints).qposadr])
        self._qvel = np.array([int(a) for a in physics.bind(task.hand.joints).dofadr])
        self._root = physics.model.name2id(task.hand.root_body.full_identifier, "body")
        self._site = int(physics.bind(task.hand.grasp_site).element_id)
        self._free_dof = int(physics.bind(task.mocap.freejoint).dofadr)
        self._mocap = task.mocap.mocap_id(physics)
        self.probe = RewardProbe(task, physics)
        self._touch = HandTouch(task.hand, physics)
        self._camera = None
        self._slices: dict[str, slice] = {}
        self._views: tuple | None = None
        self._camera_cache: dict | None = None

    # ------------------------------------------------------------------ reference path
    def proprio(self) -> dict:
        d = self._data
        return {
            "hand_qpos": d.qpos[self._qpos],
            "hand_qvel": d.qvel[self._qvel],
            "root_pos": d.xpos[self._root].copy(),
            "root_quat": d.xquat[self._root].copy(),
            "root_vel": d.qvel[self._free_dof:self._free_dof + 6].copy(),
            "grasp_site_pos": d.site_xpos[self._site].copy(),
            "grasp_site_quat": mat_to_quat(d.site_xmat[self._site].reshape(3, 3)),
            "mocap_pos": d.mocap_pos[self._mocap].copy(),
            "mocap_quat": d.mocap_quat[self._mocap].copy(),
            "touch": self._touch.vector_reference(),
            "time": np.array([float(d.time)]),
        }

    def privileged(self) -> dict:
        lo, hi = self.probe.handle_box_reference()
        return {"handle_pos": (lo + hi) / 2, "handle_size": hi - lo,
                "open_ratio": np.array([self.task.open_ratio(self.physics)])}

    # ------------------------------------------------------------------ per-step path
    def bind_layout(self, slices: dict[str, slice]) -> None:
        """Offsets of each float observation in the vector `fill` writes (keys it does not know are
        left alone: the caller writes them)."""
        self._slices = dict(slices)
        self._views = None

    def _bind_views(self, out: np.ndarray) -> tuple:
        """(out, [(destination, source)] of the plain copies `fill` makes, [(destination, source,
        indices)] of its gathers, ...): views of ``out``'s slices and of the MjData rows they copy
        (one MjData per scene, so the rows stay valid). The finger joints' qpos and qvel addresses
        are usually one run each: then they are plain copies too."""
        d, s = self._data, self._slices
        sources = {"root_pos": d.xpos[self._root], "root_quat": d.xquat[self._root],
                   "root_vel": d.qvel[self._free_dof:self._free_dof + 6], "grasp_site_pos": d.site_xpos[self._site],
                   "mocap_pos": d.mocap_pos[self._mocap], "mocap_quat": d.mocap_quat[self._mocap]}
        gathers = []  # (destination, source array, indices) where the indices are not one run
        for key, source, index in (("hand_qpos", d.qpos, self._qpos), ("hand_qvel", d.qvel, self._qvel)):
            first = int(index[0]) if len(index) else 0
            if np.array_equal(index, np.arange(first, first + len(index))):
                sources[key] = source[first:first + len(index)]  # a run of addresses: a plain copy
            else:
                gathers.append((out[s[key]], source, index))
        copies = [(out[s[key]], source) for key, source in sources.items()]
        keys = ("grasp_site_quat", "touch", "time")
        self._views = (out, copies, gathers, *(out[s[key]] for key in keys), d.site_xmat[self._site])
        return self._views

    def fill(self, out: np.ndarray, privileged: bool = False):
        """Write the proprioceptive (and with ``privileged`` the ground-truth) observations into
        ``out`` at the bound offsets; returns the step's reward terms (`RewardProbe.read`).

        The same numbers as `proprio`, `privileged` and `RewardProbe.terms`, to the bit.
        """
        d = self._data
        views = self._views
        if views is None or views[0] is not out:
            views = self._bind_views(out)
        _, copies, gathers, site_quat, touch, time, site_xmat = views
        for destination, source in copies:
            destination[...] = source
        for destination, source, index in gathers:
            np.take(source, index, out=destination)
        mat9_to_quat(site_xmat, out=site_quat)
        time[0] = d.time
        box = self.probe.target_box()
        if privileged:
            s = self._slices
            lo, hi = box
            out[s["handle_pos"]] = (lo + hi) / 2
            out[s["handle_size"]] = hi - lo
            out[s["open_ratio"]] = self.task.open_ratio(self.physics)
        if not d.ncon:  # nothing touches anything: no touch, no handle contact
            touch.fill(0.0)
            return self.probe.read(None, None, box)
        contact = d.contact  # one read of the contact list for touch and the reward's contact term
        touch[:] = self._touch.vector_from(contact)
        return self.probe.read(contact.geom1, contact.geom2, box)

    # ------------------------------------------------------------------ camera
    def camera_view(self):
        return self.task.camera_view(self.physics)

    def camera_arrays(self) -> dict:
        """The front camera's intrinsics and pose (fixed in the world: computed once per scene)."""
        if self._camera_cache is None:
            view = self.camera_view()
            pose = np.eye(4)
            pose[:3, :3] = view.rot
            pose[:3, 3] = view.pos
            self._camera_cache = {"camera_K": view.intrinsics.matrix, "camera_pose": pose}
        return {k: v.copy() for k, v in self._camera_cache.items()}

    #: The one reader per process whose renderer is open. Renderers of several models open at once
    #: on the process's shared GL context give images that depend on which was made last (textures),
    #: so a scene's renderer is closed when another scene renders.
    _rendering: "SceneReader | None" = None

    def _renderer(self):
        if self._camera is None:
            from opend_mj.sim.camera import RGBDCamera

            other = SceneReader._rendering
            if other is not None and other is not self:
                other.close()
            self._camera = RGBDCamera(self.physics, "front", self.image_size, self.image_size)
            SceneReader._rendering = self
        return self._camera

    def render(self, frames: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """(rgb uint8 HxWx3, depth float32 HxW metres) of the current state (the depth as the
        task's sensor gives it: `OpenCabinetTask.sense_depth`; ``frames`` > 1: that many sensor
        frames of a still scene, fused)."""
        rgb, depth = self._renderer().render()
        sense = getattr(self.env.task, "sense_depth", None)
        return rgb, (depth if sense is None else sense(rgb, depth, frames=frames))

    def render_rgb(self) -> np.ndarray:
        return self._renderer().render_rgb()

    def render_depth(self) -> np.ndarray:
        return self._renderer().render_depth()

    def close(self) -> None:
        if self._camera is not None:
            self._camera.close()
            self._camera = None
        if SceneReader._rendering is self:
            SceneReader._rendering = None
