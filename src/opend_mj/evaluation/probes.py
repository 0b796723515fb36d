"""Ground-truth probes that run beside the planner for labelling only: contact depth and video."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from opend_mj.evaluation.episode import EpisodeJob


class PenetrationProbe:
    """Deepest contact penetration seen at the end of any control step (metres): how soft the
    contacts are in practice (a coarser physics timestep makes them softer)."""

    def __init__(self, data):
        self._data = data
        self.deepest = 0.0

    def __call__(self) -> None:
        if self._data.ncon:
            deepest = -float(self._data.contact.dist.min())
            if deepest > self.deepest:
                self.deepest = deepest


class VideoRecorder:
    """Front camera and a side view side by side, every few control steps, written as MP4."""

    def __init__(self, job: EpisodeJob, physics, config, bounds, every: int = 2, size: int = 256):
        import mujoco

        from opend_mj.sim.camera import make_renderer

        self.physics = physics
        self.every = every
        self.frames: list[np.ndarray] = []
        self.n = 0
        self.path = Path(job.video_dir) / job.video_name()
        self.fps = int(round(config.control_hz / every))
        m, d = physics.model.ptr, physics.data.ptr
        self._m, self._d = m, d
        self._renderer = make_renderer(m, height=size, width=size)
        self._front = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_CAMERA, "front")
        if self._front < 0:
            self._front = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_CAMERA, "front/front")
        cam = mujoco.MjvCamera()
        cam.type = mujoco.mjtCamera.mjCAMERA_FREE
        # look at the cabinet from its front-right side
        lo, hi = (np.asarray(b, float) for b in bounds)
        cam.lookat[:] = [lo[0] - 0.2, 0.5 * (lo[1] + hi[1]), 0.5 * (lo[2] + hi[2])]
        cam.distance = float(1.2 + 1.0 * max(hi[1] - lo[1], hi[2] - lo[2]))
        cam.azimuth = 25.0
        cam.elevation = -50.0
        self._side = cam
        self.capture(force=True)

    def capture(self, force: bool = False) -> None:
        self.n += 1
        if not force and self.n % self.every:
            return
        r = self._renderer
        cams = []
        if self._front >= 0:
            r.update_scene(self._d, camera=self._front)
            cams.append(r.render().copy())
        r.update_scene(self._d, camera=self._side)
        cams.append(r.render().copy())
        self.frames.append(np.concatenate(cams, axis=1))

    def close(self) -> None:
        import imageio.v2 as imageio

        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        if self.frames:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            imageio.mimwrite(str(self.path), self.frames, fps=self.fps, codec="libx264", macro_block_size=1)
            self.frames = []
