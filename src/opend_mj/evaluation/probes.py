"""Ground-truth probes that run beside the planner or an agent, for labelling only: contact depth,
how close the hand came to the handle, whether it held the instructed part, and video."""

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


class HandReach:
    """How close the hand's gripping surfaces are to the instructed handle (metres, ground truth,
    for labelling only): the least signed distance between any geom that carries one of the hand's
    touch sensors (palm, finger segments, pads; every hand geom for a hand without touch sensors)
    and any geom of the handle, by MuJoCo's convex distance (``mj_geomDistance``; below 0 where they
    overlap), capped at ``cap``.

    This, not the grasp site, says whether the hand got to the handle: grasps that hold a bar with
    the fingers' far segments (a hook that slides the site back along the fingers, a hand lifted
    above a low bar with its fingers pointing down) keep the site centimetres from the handle when
    the fingers are on it."""

    def __init__(self, task, physics, cap: float = 0.05):
        import mujoco

        from opend_mj.sim.hands import touch_geoms

        self._distance = mujoco.mj_geomDistance
        self._m, self._d = physics.model.ptr, physics.data.ptr
        self.cap = float(cap)
        hand = task.hand
        geoms = list(touch_geoms(hand, physics))
        if not geoms:
            geoms = [int(g) for g in physics.bind(hand.mjcf_model.find_all("geom")).element_id]
        self._hand = sorted(set(geoms))
        self._handle = [mujoco.mj_name2id(self._m, mujoco.mjtObj.mjOBJ_GEOM, f"cabinet/{g}")
                        for g in task.target.handle_geoms]
        self._handle = [g for g in self._handle if g >= 0]
        #: farthest any of those geoms reaches from the grasp site at the start pose, plus 5 cm for
        #: fingers that open wider (m): no hand geom can be nearer the handle than the site's
        #: distance less this, so `__call__` is needed only when the site is within ``span + cap``.
        site = int(physics.bind(hand.grasp_site).element_id)
        d = self._d
        self.span = 0.05 + max(float(np.linalg.norm(d.geom_xpos[g] - d.site_xpos[site])) + float(self._m.geom_rbound[g])
                               for g in self._hand)

    def __call__(self) -> float:
        best = self.cap
        m, d, distance, cap = self._m, self._d, self._distance, self.cap
        for g1 in self._hand:
            for g2 in self._handle:
                dist = distance(m, d, g1, g2, cap, None)
                if dist < best:
                    best = dist
        return float(best)


class HoldProbe:
    """Whether the hand is on the instructed part, step by step (ground truth, for labelling only):
    any contact between a hand geom and a geom of the body the target joint moves (its front, its
    handle), and the part's open ratio. Read at the end of each control step; :meth:`summary` gives
    what :func:`opend_mj.evaluation.grading.episode_ending` classifies."""

    def __init__(self, task, physics):
        m = physics.model.ptr
        hand_bodies = {int(b) for b in physics.bind(task.hand.mjcf_model.find_all("body")).element_id}
        joint = int(physics.bind(task.cabinet.mjcf_model.find("joint", task.target.joint)).element_id)
        part = int(m.jnt_bodyid[joint])
        moving = {part} | {b for b in range(m.nbody) if self._descends(m, b, part)}
        self._hand_geom = np.isin(m.geom_bodyid, sorted(hand_bodies))
        self._part_geom = np.isin(m.geom_bodyid, sorted(moving))
        self._d = physics.data.ptr
        self._task, self._physics = task, physics
        self.steps = 0
        self.held_steps = 0  # steps with the hand on the part
        self.first_held: int | None = None  # step of the first contact
        self.last_held: int | None = None  # step of the latest contact
        self.peak_ratio = 0.0  # the highest open ratio reached

    @staticmethod
    def _descends(m, body: int, ancestor: int) -> bool:
        while body > 0:
            body = int(m.body_parentid[body])
            if body == ancestor:
                return True
        return False

    def __call__(self) -> None:
        d = self._d
        on = False
        if d.ncon:
            g1, g2 = d.contact.geom1[:d.ncon], d.contact.geom2[:d.ncon]
            on = bool(np.any((self._hand_geom[g1] & self._part_geom[g2]) | (self._hand_geom[g2] & self._part_geom[g1])))
        if on:
            self.held_steps += 1
            self.last_held = self.steps
            if self.first_held is None:
                self.first_held = self.steps
        self.peak_ratio = max(self.peak_ratio, float(self._task.open_ratio(self._physics)))
        self.steps += 1

    def summary(self) -> dict:
        """``held_steps``, ``first_held`` / ``last_held`` (steps, None where never), ``steps``, ``peak_ratio``."""
        return {"held_steps": self.held_steps, "first_held": self.first_held, "last_held": self.last_held,
                "steps": self.steps, "peak_ratio": round(self.peak_ratio, 4)}
