"""Parts of the batched MuJoCo Warp environment (`opend_mj.sim.warp_env`): per-world physics
randomisation, batched rotation helpers in torch, the batched renderer of the front camera, and the
start state a world is reset to. Needs the optional extra ``.[warp]`` (and torch)."""

from __future__ import annotations

import copy as copy_module
import math
from dataclasses import dataclass

import numpy as np


def _torch():
    import torch

    return torch


@dataclass(frozen=True)
class PhysicsRandomization:
    """Per-world factors on the cabinet's physics (the ``physics`` perturbation axis of `sim.perturb`):
    handle friction, joint friction loss, joint damping, and the moving parts' mass and inertia, each
    times a factor log-uniform in ``factor`` (0.5-2 by default; the perturbation's levels use
    0.7-1.5 and 0.4-3), drawn from ``seed``. ``draws``: distinct draws (world w takes draw
    w % draws; the model's batched arrays hold ``draws`` rows)."""

    factor: tuple[float, float] = (0.5, 2.0)
    seed: int = 0
    draws: int | None = None  # None: one per world


def randomize_physics(env, r: PhysicsRandomization, draws: int) -> np.ndarray:
    """`PhysicsRandomization` for a `WarpBatchEnv` (``env``): per-draw factors (draws, 4: handle
    friction, friction loss, damping, mass) written into its batched Model arrays; the constants
    `mj_setConst` derives from masses (subtree masses, inverse weights) recomputed on the CPU per
    draw."""
    import mujoco
    import warp as wp

    scene = env.scene
    task, physics = scene.task, scene.physics
    cab = task.cabinet
    dofs = np.array([int(physics.bind(cab.joint_element(j)).dofadr) for j in cab._joints])
    geoms = np.array([physics.model.name2id(f"cabinet/{g}", "geom")
                      for t in cab.targets for g in t.handle_geoms], int)
    bodies = np.array([physics.model.name2id(b.full_identifier, "body") for b in cab.moving_bodies()], int)
    rng = np.random.default_rng([int(r.seed), 71])
    lo, hi = (math.log(x) for x in r.factor)
    factors = np.exp(rng.uniform(lo, hi, (draws, 4)))
    base = env.mj_model
    copy = copy_module.copy(base)
    data = mujoco.MjData(copy)
    rows = {k: [] for k in ("dof_damping", "dof_frictionloss", "geom_friction", "body_mass", "body_inertia",
                            "body_subtreemass", "body_invweight0", "dof_invweight0")}
    for f_friction, f_loss, f_damp, f_mass in factors:
        copy.dof_damping[:] = base.dof_damping
        copy.dof_frictionloss[:] = base.dof_frictionloss
        copy.geom_friction[:] = base.geom_friction
        copy.body_mass[:] = base.body_mass
        copy.body_inertia[:] = base.body_inertia
        copy.dof_damping[dofs] *= f_damp
        copy.dof_frictionloss[dofs] *= f_loss
        if len(geoms):
            copy.geom_friction[geoms, 0] *= f_friction
        copy.body_mass[bodies] *= f_mass
        copy.body_inertia[bodies] *= f_mass
        mujoco.mj_setConst(copy, data)
        for k in rows:
            rows[k].append(np.array(getattr(copy, k)))
    for k, values in rows.items():
        arr = getattr(env.model, k)
        arr.assign(wp.array(np.stack(values).astype(np.float32), dtype=arr.dtype, device=env.wp_device))
    return factors


def capture_state(data) -> dict:
    """The state `WarpBatchEnv` resets a world to (copies of MjData's rows)."""
    return {"qpos": data.qpos.copy(), "qvel": data.qvel.copy(), "act": data.act.copy(), "ctrl": data.ctrl.copy(),
            "mocap_pos": data.mocap_pos.ravel().copy(), "mocap_quat": data.mocap_quat.ravel().copy(),
            "qacc_warmstart": data.qacc_warmstart.copy(), "time": np.array(float(data.time))}


def quat_mul(a, b):
    """Hamilton product of (N, 4) quaternions (w, x, y, z), as `transforms.quat_mul`."""
    torch = _torch()
    w1, x1, y1, z1 = a.unbind(1)
    w2, x2, y2, z2 = b.unbind(1)
    return torch.stack([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2], 1)


def mat_to_quat(mat):
    """`transforms.mat9_to_quat` of (N, 3, 3) rotation matrices: (N, 4), w >= 0, unit."""
    torch = _torch()
    m00, m01, m02 = mat[:, 0, 0], mat[:, 0, 1], mat[:, 0, 2]
    m10, m11, m12 = mat[:, 1, 0], mat[:, 1, 1], mat[:, 1, 2]
    m20, m21, m22 = mat[:, 2, 0], mat[:, 2, 1], mat[:, 2, 2]
    t = m00 + m11 + m22

    def branch(s_arg, build):
        s = torch.sqrt(torch.clamp(s_arg, min=1e-30)) * 2
        return torch.stack(build(s), 1)

    q0 = branch(t + 1.0, lambda s: [0.25 * s, (m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s])
    q1 = branch(1.0 + m00 - m11 - m22, lambda s: [(m21 - m12) / s, 0.25 * s, (m01 + m10) / s, (m02 + m20) / s])
    q2 = branch(1.0 + m11 - m00 - m22, lambda s: [(m02 - m20) / s, (m01 + m10) / s, 0.25 * s, (m12 + m21) / s])
    q3 = branch(1.0 + m22 - m00 - m11, lambda s: [(m10 - m01) / s, (m02 + m20) / s, (m12 + m21) / s, 0.25 * s])
    c0 = (t > 0)[:, None]
    c1 = ((m00 > m11) & (m00 > m22))[:, None]
    c2 = (m11 > m22)[:, None]
    q = torch.where(c0, q0, torch.where(c1, q1, torch.where(c2, q2, q3)))
    q = q / torch.sqrt((q * q).sum(1, keepdim=True))
    return torch.where(q[:, :1] < 0, -q, q)


class WarpRenderer:
    """Batched images of the front camera from Warp's ray-traced renderer (`mujoco_warp.render`)."""

    def __init__(self, env, mode: str, size: int, camera: str):
        import mujoco

        mjw, wp = env._mjw, env._wp
        self.env = env
        self.rgb = mode in ("rgb", "rgbd")
        self.depth = mode in ("depth", "rgbd")
        cam = mujoco.mj_name2id(env.mj_model, mujoco.mjtObj.mjOBJ_CAMERA, camera)
        if cam < 0:
            raise ValueError(f"no camera {camera!r} in the scene")
        self.size = int(size)
        with wp.ScopedDevice(env.wp_device):
            self.rc = mjw.create_render_context(env.mj_model, nworld=env.num_worlds, cam_res=(self.size, self.size),
                                                render_rgb=self.rgb, render_depth=self.depth, cam_active=[cam])
        self._rgb = wp.to_torch(self.rc.rgb_data) if self.rgb else None
        self._depth = wp.to_torch(self.rc.depth_data) if self.depth else None

    def images(self, where=None, into: dict | None = None) -> dict:
        """{"rgb": (N, S, S, 3) uint8, "depth": (N, S, S) float32 metres (planar; 0: nothing hit)} of the
        current state; ``where``: only those worlds' rows of ``into`` are replaced."""
        torch = _torch()
        env, mjw, wp = self.env, self.env._mjw, self.env._wp
        with env._scope():
            mjw.refit_bvh(env.model, env.data, self.rc)
            mjw.render(env.model, env.data, self.rc)
        n, s = env.num_worlds, self.size
        out = {}
        if self.rgb:
            packed = self._rgb[:, : s * s].view(torch.int32)
            rgb = torch.stack([(packed >> 16) & 0xFF, (packed >> 8) & 0xFF, packed & 0xFF], -1)
            out["rgb"] = rgb.to(torch.uint8).view(n, s, s, 3)
        if self.depth:
            out["depth"] = self._depth[:, : s * s].view(n, s, s).clone()
        if where is not None and into:
            for k, v in out.items():
                if k in into:
                    out[k] = torch.where(where.view(-1, *([1] * (v.dim() - 1))), v, into[k])
        return out
