"""Batched environments on MuJoCo Warp: N worlds of one compiled scene, stepped together.

`WarpBatchEnv` runs N copies ("worlds") of one episode's scene (a cabinet, its instructed target, a
room, the hand on its mocap weld) in MuJoCo Warp (``mujoco_warp``, NVIDIA Warp kernels), on a GPU
where Warp finds one and on the CPU otherwise. It has the gymnasium environment's (`sim.envs`,
`sim.gym_env`) state observation, delta (or absolute) action, dense or sparse reward, success,
termination and truncation, per world; a world that ends is reset at once (automatic reset) to
a start drawn as the CPU environment draws it.

What is the CPU environment's own code, and what is rewritten for the batch:

* The scene, the reset states and every index are the CPU environment's: an `OpenDCore` compiles
  the scene, and each start state (hand start shifted and turned as ``start_noise`` /
  ``start_yaw_noise`` draw it from the reset seed) is the state its ``reset`` leaves in MjData,
  with its first observation and reward terms (a pool of ``reset_pool`` of them, on the device).
  The observation's indices (finger joints, root body, grasp site, mocap, touch parts) and the
  reward's (hand and handle geoms, target joints and their spans) are read from its `SceneReader`
  and `RewardProbe`.
* Per step, on the device, in torch over all worlds: the delta action (`ActionAdapter.delta_parts`),
  the task's clipping and mocap path at bounded speed (`OpenCabinetTask.apply_action`,
  `MocapPathPlanner.plan`), the float observation vector (`SceneReader.fill`, the same layout:
  `OpenDCore.flat_layout`), the reward terms (`RewardProbe.read`) and `rewards.dense_reward`. The
  mocap pose and the simulated time are kept in float64 beside Warp's float32 data, so the action
  arithmetic and the time limit are the CPU environment's.
* `cpu_terms(world)` checks the batch against the CPU code itself: it copies one world's Warp
  state into the CPU scene's MjData and runs `SceneReader.fill` there (tests compare the two).

Outputs stay on the device: torch tensors (zero-copy views of Warp's arrays through DLPack) on the
Warp device (``cuda:0`` or ``cpu``); ``.numpy()`` of a CPU tensor is zero-copy too.

Physics randomisation (`PhysicsRandomization`): the perturbation axis ``physics`` of `sim.perturb`
(handle friction, joint friction loss and damping of the cabinet's joints, the moving parts' mass and
inertia, each times a log-uniform factor) drawn per world in batched Model fields, which Warp
supports for these arrays (``put_model(batch_sizes=...)``).

Images (``obs_mode`` "depth", "rgb", "rgbd"): Warp's ray-traced renderer (`mujoco_warp.render`,
BVH over the geoms) from the front camera, batched: planar depth in metres (the CPU renderer's
convention) and RGB (flat shading, textures; not the CPU's OpenGL image to the pixel).

Several cabinets: a batch holds one compiled model, so one batch is one (cabinet, target, room);
`CabinetCycle` builds one batch per cabinet and steps them in turn (see docs/batched-simulation.md
for the cost).

Needs the optional extra ``pip install -e '.[warp]'`` (``mujoco-warp``, ``warp-lang``); nothing
else in the package imports Warp.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from opend_mj.sim.envs import EnvConfig, OpenDCore, make_config
from opend_mj.sim.warp_parts import (PhysicsRandomization, WarpRenderer, capture_state, mat_to_quat, quat_mul,
                                      randomize_physics)

#: The extra's packages: a test or tool that needs them says this when they are missing.
MISSING = "the optional extra .[warp] (mujoco-warp, warp-lang) is not installed"


def available() -> bool:
    """True where ``mujoco_warp`` and ``warp`` import."""
    try:
        import mujoco_warp  # noqa: F401
        import warp  # noqa: F401
    except ImportError:
        return False
    return True


def _torch():
    import torch

    return torch


class WarpBatchEnv:
    """N worlds of one scene in MuJoCo Warp with the CPU environment's observation, action, reward.

    ``cabinet``, ``target``: the episode's cabinet id and target joint (a target of ``split``);
    ``room``, ``scene_seed``: the room and its appearance seed (the compiled scene); every other
    keyword is a field of `EnvConfig` (``hand``, ``cabinets``, ``control``, ``reward_mode``,
    ``privileged``, ``start_noise``, ``time_limit``, ...). ``seed``: the reset seeds are
    ``seed``, ``seed + 1``, ... (the CPU environment's ``reset(seed=...)`` with the cabinet, target,
    room and scene fixed: the same start state). ``reset_pool``: how many start states are
    computed (on the CPU, at construction: about a millisecond each); world w's k-th episode starts
    from pool entry ``(k * N + w) % reset_pool``. ``reset_options``: more of the CPU reset's options
    (``start_offset``, ``start_yaw``: a fixed start). ``device``: a Warp device ("cpu", "cuda:0");
    None: Warp's default. ``nconmax`` / ``njmax``: contacts and constraint rows per world.
    """

    def __init__(self, num_worlds: int, cabinet: str, target: str, room: int = 0, scene_seed: int = 0,
                 seed: int = 0, reset_pool: int | None = None, reset_options: dict | None = None,
                 device: str | None = None, randomize: PhysicsRandomization | None = None,
                 nconmax: int = 96, njmax: int = 400, **env_kwargs):
        import mujoco
        import mujoco_warp as mjw
        import warp as wp

        torch = _torch()
        env_kwargs.setdefault("split", "all")
        env_kwargs["cabinet_ids"] = (cabinet,)
        config = make_config(**env_kwargs)
        if config.range_success is not None:
            raise ValueError("range_success is not supported by the batched environment")
        self.config: EnvConfig = config
        self.num_worlds = n = int(num_worlds)
        wp.init()
        self.wp_device = wp.get_device(device)
        self.device = torch.device("cuda", self.wp_device.ordinal) if self.wp_device.is_cuda else torch.device("cpu")
        self._options = {"cabinet": cabinet, "target": target, "room": int(room), "scene_seed": int(scene_seed),
                         **(reset_options or {})}
        # ---------------------------------------------------------- the CPU environment: scene, starts
        # the CPU core renders nothing: images come from Warp's renderer
        self.core = core = OpenDCore(replace(config, obs_mode="state"))
        self.seed = int(seed)
        pool = int(reset_pool) if reset_pool is not None else min(n, 256)
        self.reset_pool = pool
        flats, states, starts, infos = [], [], [], []
        for k in range(pool):
            _, info = core.reset(self.seed + k, self._options)
            data = core.scene._data
            states.append(capture_state(data))
            flats.append(core.flat.copy())
            starts.append(core.scene.probe.start_distance)
            infos.append(info)
        scene = self.scene = core.scene
        self.episode = core.episode
        self.instruction = core.episode.instruction
        self.start_infos = infos
        mjm = scene.physics.model.ptr
        self.mj_model = mjm
        task = scene.task
        # ---------------------------------------------------------- Warp model and data
        with wp.ScopedDevice(self.wp_device):
            batch = {}
            if randomize is not None:
                draws = randomize.draws or n
                batch = {f: draws for f in ("dof_damping", "dof_frictionloss", "geom_friction", "body_mass",
                                            "body_inertia", "body_subtreemass", "body_invweight0",
                                            "dof_invweight0")}
            self.model = mjw.put_model(mjm, batch_sizes=batch or None)
            self.data = mjw.put_data(mjm, scene._data, nworld=n, nconmax=nconmax, njmax=njmax)
            if randomize is not None:
                self.physics_factors = randomize_physics(self, randomize, batch["body_mass"])
            else:
                self.physics_factors = None
        wp.synchronize_device(self.wp_device)
        self._mjw, self._wp = mjw, wp
        d = self.data
        t = wp.to_torch
        self._qpos, self._qvel, self._ctrl = t(d.qpos), t(d.qvel), t(d.ctrl)
        self._act = t(d.act) if d.act.shape[-1] else None
        self._mocap_pos, self._mocap_quat = t(d.mocap_pos), t(d.mocap_quat)
        self._qacc_ws = t(d.qacc_warmstart)
        self._time32 = t(d.time)
        self._xpos, self._xquat = t(d.xpos), t(d.xquat)
        self._site_xpos, self._site_xmat = t(d.site_xpos), t(d.site_xmat)
        self._geom_xpos, self._geom_xmat = t(d.geom_xpos), t(d.geom_xmat)
        self._efc_force = t(d.efc.force)
        self._nacon = t(d.nacon)
        con = d.contact
        self._con_geom, self._con_world, self._con_type = t(con.geom), t(con.worldid), t(con.type)
        self._con_efc = t(con.efc_address)
        from mujoco_warp._src.types import ContactType

        self._exported = int(ContactType.CONSTRAINT | ContactType.PASSIVE)
        # ---------------------------------------------------------- the pool of start states
        f64 = dict(dtype=torch.float64, device=self.device)
        self._pool = {k: torch.as_tensor(np.stack([s[k] for s in states]), **f64) for k in states[0]}
        self._pool_flat = torch.as_tensor(np.stack(flats), **f64)
        self._pool_start = torch.as_tensor(np.array(starts), **f64)
        # ---------------------------------------------------------- indices (the CPU readers')
        idx = dict(dtype=torch.long, device=self.device)
        probe = scene.probe
        self._i_hand_qpos = torch.as_tensor(scene._qpos, **idx)
        self._i_hand_qvel = torch.as_tensor(scene._qvel, **idx)
        self._root, self._site, self._free, self._mocap = scene._root, scene._site, scene._free_dof, scene._mocap
        _, handle_ids, local, handle_mask, _, _, (ratios, open_span, range_span) = probe._bind(task.target.joint)
        self._handle_ids = torch.as_tensor(handle_ids, **idx)
        self._handle_local = torch.as_tensor(local, **f64)  # (h, 8, 3) corners in the geom frames
        self._handle_mask = torch.as_tensor(handle_mask, device=self.device)
        self._hand_mask = torch.as_tensor(probe._hand_mask, device=self.device)
        target = task.target
        self._target_q = int(probe._qpos[target.joint])
        self._target_closed, self._target_sign = float(target.closed), float(target.open_sign)
        self._open_span, self._range_span = float(open_span), float(range_span)
        others = [(a, closed, sign, span) for (is_t, closed, sign, span), a in zip(ratios, probe._addresses.tolist())
                  if not is_t]
        self._other_addr = torch.as_tensor([o[0] for o in others], **idx)
        self._other_closed = torch.as_tensor([o[1] for o in others], **f64)
        self._other_sign = torch.as_tensor([o[2] for o in others], **f64)
        self._other_span = torch.as_tensor([o[3] for o in others], **f64)
        self._threshold, self._moved = float(task.checker.threshold), float(task.checker.moved_threshold)
        touch = scene._touch
        self._n_parts = len(touch.parts)
        self._touch_geom_hand = torch.as_tensor(touch._hand_geom, device=self.device)
        self._part_of_geom = torch.as_tensor(touch._part_of_geom, **idx)
        if not touch._elliptic:
            raise ValueError("the batched touch vector reads elliptic-cone contact forces (the scenes' cone)")
        # the action: `ActionAdapter` and `OpenCabinetTask.apply_action`'s constants
        adapter = core.adapter
        self._step_pos, self._step_rot = float(adapter.step_pos), float(adapter.step_rot)
        self._finger_low = torch.as_tensor(adapter.finger_low, **f64)
        self._half_span = torch.as_tensor(adapter._half_span, **f64)
        ws_lo, ws_hi = task._workspace
        self._ws_lo, self._ws_hi = torch.as_tensor(ws_lo, **f64), torch.as_tensor(ws_hi, **f64)
        ctrl_lo, ctrl_hi = task._ctrl_range
        self._ctrl_lo, self._ctrl_hi = torch.as_tensor(ctrl_lo, **f64), torch.as_tensor(ctrl_hi, **f64)
        self._ctrl_index = torch.as_tensor(task._ctrl_index, **idx)
        planner = task._planner
        self._substeps = planner.n
        self._travel = torch.as_tensor(planner.travel, **f64)  # (n,)
        self._turn = torch.as_tensor(planner._turn, **f64)  # (n,)
        self._dt = float(mjm.opt.timestep)
        self._time_limit = float(core.task_config.time_limit)
        self._delta = config.control == "delta"
        self.action_dim = adapter.delta_dim if self._delta else adapter.absolute_dim
        self.action_low, self.action_high = (torch.as_tensor(b, **f64) for b in core.action_bounds())
        # ---------------------------------------------------------- the observation vector
        self.layout = core.flat_layout()
        self.obs_size = core.flat_size
        self._slices = {key: sl for key, sl, _ in self.layout}
        # ---------------------------------------------------------- per-world state
        self._mocap_pos64 = torch.zeros(n, 3, **f64)
        self._mocap_quat64 = torch.zeros(n, 4, **f64)
        self._time64 = torch.zeros(n, **f64)
        self._start_distance = torch.zeros(n, **f64)
        self.episodes = torch.zeros(n, dtype=torch.long, device=self.device)  # episodes started per world
        self.steps = torch.zeros(n, dtype=torch.long, device=self.device)  # control steps this episode
        self.obs = torch.zeros(n, self.obs_size, **f64)
        self._dense = config.dense
        # ---------------------------------------------------------- images
        self._render = None
        #: the front camera's intrinsics (3, 3) and pose (4, 4), fixed per batch (`SceneReader.camera_arrays`)
        cam = scene.camera_arrays()
        self.camera_K, self.camera_pose = cam["camera_K"], cam["camera_pose"]
        if config.obs_mode != "state":
            self._render = WarpRenderer(self, config.obs_mode, config.image_size, task.camera.full_identifier)
        self._needs_reset = True
        self._mujoco = mujoco

    # ------------------------------------------------------------------ physics randomisation
    def _scope(self):
        """Warp's launches on this env's device; on a GPU, on torch's current stream, so that the
        torch operations on the same memory (actions, resets, observations) are ordered with them."""
        wp = self._wp
        if self.wp_device.is_cuda:
            return wp.ScopedStream(wp.stream_from_torch(_torch().cuda.current_stream(self.device)))
        return wp.ScopedDevice(self.wp_device)

    # ------------------------------------------------------------------ reset
    def reset(self):
        """Start an episode in every world (world w from pool entry w % reset_pool); returns the
        observations (N, obs_size) and the info dict of `step`."""
        torch = _torch()
        self.episodes.zero_()
        with self._scope():
            self._mjw.reset_data(self.model, self.data)
        self._reset_worlds(torch.ones(self.num_worlds, dtype=torch.bool, device=self.device))
        self._needs_reset = False
        with self._scope():
            self._mjw.kinematics(self.model, self.data)
        terms = self._terms()
        info = {"success": terms["success"], "open_ratio": terms["open_ratio"]}
        if self._render is not None:
            info.update(self._render.images())
        return self.obs.clone(), info

    def _reset_worlds(self, mask) -> None:
        """Write each masked world's next start state (the pool's) into the Warp data and the float64
        shadows; its observation row becomes the CPU environment's first observation."""
        torch = _torch()
        worlds = torch.nonzero(mask).squeeze(1)
        if worlds.numel() == 0:
            return
        k = (self.episodes[worlds] * self.num_worlds + worlds) % self.reset_pool
        self.episodes[worlds] += 1
        p = self._pool
        self._qpos[worlds] = p["qpos"][k].float()
        self._qvel[worlds] = p["qvel"][k].float()
        self._ctrl[worlds] = p["ctrl"][k].float()
        if self._act is not None:
            self._act[worlds] = p["act"][k].float()
        self._mocap_pos[worlds] = p["mocap_pos"][k].float().view(-1, *self._mocap_pos.shape[1:])
        self._mocap_quat[worlds] = p["mocap_quat"][k].float().view(-1, *self._mocap_quat.shape[1:])
        self._qacc_ws[worlds] = p["qacc_warmstart"][k].float()
        self._time32[worlds] = p["time"][k].float()
        self._time64[worlds] = p["time"][k]
        m = self._mocap
        self._mocap_pos64[worlds] = p["mocap_pos"][k].view(len(k), -1, 3)[:, m]
        self._mocap_quat64[worlds] = p["mocap_quat"][k].view(len(k), -1, 4)[:, m]
        self._start_distance[worlds] = self._pool_start[k]
        self.obs[worlds] = self._pool_flat[k]
        self.steps[worlds] = 0

    # ------------------------------------------------------------------ step
    def step(self, action):
        """One control step of every world: (obs, reward, terminated, truncated, info).

        ``action``: (N, action_dim), a torch tensor on this env's device or anything torch takes.
        Worlds that terminate or truncate are reset before returning (their ``obs`` row is the new
        episode's first; ``info["final_obs"]`` holds the last one of the episode that ended, and
        ``info["success"]`` / ``info["open_ratio"]`` that episode's final verdict). Tensors on the
        device: obs float64 (N, obs_size) in `layout` (images under ``info`` keys ``rgb`` / ``depth``
        with an image mode), reward float64 (N,), terminated and truncated bool (N,).
        """
        if self._needs_reset:
            raise RuntimeError("call reset() first")
        torch = _torch()
        a = torch.as_tensor(action, device=self.device).to(torch.float64)
        if a.shape != (self.num_worlds, self.action_dim):
            raise ValueError(f"action has shape {tuple(a.shape)}, expected ({self.num_worlds}, {self.action_dim})")
        if not bool(torch.isfinite(a).all()):  # as the CPU environment, which raises on a non-finite action
            raise ValueError("actions have non-finite values")
        pos, quat, fingers = self._native(a)
        rows_pos, rows_quat = self._apply(pos, quat, fingers)
        mjw, m, d = self._mjw, self.model, self.data
        mp, mq, mid = self._mocap_pos, self._mocap_quat, self._mocap
        with self._scope():
            for i in range(self._substeps):
                mp[:, mid] = rows_pos[:, i].float()
                mq[:, mid] = rows_quat[:, i].float()
                mjw.step(m, d)
                self._time64 += self._dt
            mjw.kinematics(m, d)
        self._mocap_pos64 = rows_pos[:, -1].clone()
        self._mocap_quat64 = rows_quat[:, -1].clone()
        self.steps += 1
        terms = self._terms()
        self._fill(terms)
        finite = torch.isfinite(self._qpos).all(1) & torch.isfinite(self._qvel).all(1)
        reward = self._reward(terms)
        reward = torch.where(finite, reward, torch.zeros_like(reward))
        terminated = (terms["success"] & bool(self.config.terminate_on_success)) | ~finite
        last = self._time64 >= self._time_limit
        truncated = last & ~terminated
        done = terminated | truncated
        info = {"success": terms["success"], "open_ratio": terms["open_ratio"], "others_moved": terms["others_moved"],
                "physics_failed": ~finite, "reward_terms": terms}
        if self._render is not None:
            info.update(self._render.images())
        if bool(done.any()):
            info["final_obs"] = self.obs.clone()
            self._reset_worlds(done)
            if self._render is not None:  # the new episodes' first images
                with self._scope():
                    mjw.kinematics(m, d)
                info.update(self._render.images(where=done, into={k: info[k] for k in ("rgb", "depth") if k in info}))
        return self.obs, reward, terminated, truncated, info

    # ------------------------------------------------------------------ the action (vectorised)
    def _native(self, a):
        """(root target position (N, 3), quaternion (N, 4), finger targets (N, F)) of the actions:
        `ActionAdapter.delta_parts` for delta actions (from the float64 mocap pose), the actions
        themselves for absolute ones."""
        torch = _torch()
        if not self._delta:
            return a[:, :3], a[:, 3:7], a[:, 7:]
        c = torch.clamp(a, -1.0, 1.0)
        pos = self._mocap_pos64 + c[:, :3] * self._step_pos
        rotvec = c[:, 3:6] * self._step_rot
        angle = torch.sqrt((rotvec * rotvec).sum(1))
        safe = torch.where(angle > 1e-12, angle, torch.ones_like(angle))
        axis = rotvec / safe[:, None]
        axis = axis / torch.sqrt((axis * axis).sum(1))[:, None].clamp_min(1e-300)
        half = angle / 2
        q1 = torch.cat([torch.cos(half)[:, None], torch.sin(half)[:, None] * axis], 1)
        quat = quat_mul(q1, self._mocap_quat64)
        quat = quat / torch.sqrt((quat * quat).sum(1))[:, None]
        quat = torch.where((angle > 1e-12)[:, None], quat, self._mocap_quat64)
        fingers = self._finger_low + (c[:, 6:] + 1.0) * self._half_span
        return pos, quat, fingers

    def _apply(self, pos, quat, fingers):
        """`OpenCabinetTask.apply_action` and `MocapPathPlanner.plan` for every world: clips the root
        target to the workspace and the finger targets to their ranges (written to ctrl), and
        returns the mocap's rows per substep, (N, n, 3) and (N, n, 4), float64."""
        torch = _torch()
        norm = torch.sqrt((quat * quat).sum(1))
        ok = norm >= 1e-6  # a zero quaternion (the CPU task raises): keep the current orientation
        target_quat = torch.where(ok[:, None], quat / torch.where(ok, norm, torch.ones_like(norm))[:, None],
                                  self._mocap_quat64)
        target_pos = torch.minimum(torch.maximum(pos, self._ws_lo), self._ws_hi)
        ctrl = torch.minimum(torch.maximum(fingers, self._ctrl_lo), self._ctrl_hi)
        self._ctrl[:, self._ctrl_index] = ctrl.float()
        p0, q0 = self._mocap_pos64, self._mocap_quat64
        delta = target_pos - p0
        dist = torch.sqrt((delta * delta).sum(1))
        moving = dist > 1e-12
        unit = delta / torch.where(moving, dist, torch.ones_like(dist))[:, None]
        travel = torch.minimum(self._travel[None, :], dist[:, None])  # (N, n)
        rows_pos = p0[:, None, :] + unit[:, None, :] * travel[:, :, None]
        rows_pos = torch.where(moving[:, None, None], rows_pos, p0[:, None, :].expand_as(rows_pos))
        # the orientation: unchanged (set to the target at once) or a slerp at bounded angle
        cos = (q0 * target_quat).sum(1)
        still = cos.abs() > 1.0 - 1e-12
        qn = q0 / torch.sqrt((q0 * q0).sum(1))[:, None]
        tn = target_quat / torch.sqrt((target_quat * target_quat).sum(1))[:, None]
        dot = (qn * tn).sum(1)
        tn = torch.where((dot < 0)[:, None], -tn, tn)
        dot = dot.abs()
        angle = 2 * torch.acos(torch.clamp(dot, max=1.0))
        tiny = angle < 1e-9
        half = angle / 2
        sin_half = torch.sin(torch.where(tiny, torch.ones_like(half), half))
        t = torch.clamp(self._turn[None, :] / torch.where(tiny, torch.ones_like(angle), angle)[:, None], max=1.0)
        wa = torch.sin((1 - t) * half[:, None]) / sin_half[:, None]
        wb = torch.sin(t * half[:, None]) / sin_half[:, None]
        x = wa[:, :, None] * qn[:, None, :] + wb[:, :, None] * tn[:, None, :]
        x = x / torch.sqrt((x * x).sum(2, keepdim=True))
        n = self._substeps
        x = torch.where(tiny[:, None, None], tn[:, None, :].expand(-1, n, -1), x)
        rows_quat = torch.where(still[:, None, None], target_quat[:, None, :].expand(-1, n, -1), x)
        return rows_pos, rows_quat

    # ------------------------------------------------------------------ observation and reward
    def _terms(self) -> dict:
        """`RewardProbe.read` for every world: distance (grasp site to the handle's box), contact,
        open ratio, the largest other range ratio, success, others moved, range ratio."""
        torch = _torch()
        f64 = torch.float64
        site = self._site_xpos[:, self._site].to(f64)
        lo, hi = self._handle_box()
        outside = torch.clamp(torch.maximum(lo - site, site - hi), min=0.0)
        distance = torch.sqrt((outside * outside).sum(1))
        q = self._qpos[:, self._target_q].to(f64)
        opening = torch.clamp((q - self._target_closed) * self._target_sign, min=0.0)
        open_ratio = opening / self._open_span
        if self._other_addr.numel():
            values = self._qpos[:, self._other_addr].to(f64)
            ratios = torch.clamp((values - self._other_closed) * self._other_sign, min=0.0) / self._other_span
            others_range = ratios.max(1).values
            others_moved = others_range > self._moved
        else:
            others_range = torch.zeros_like(open_ratio)
            others_moved = torch.zeros_like(open_ratio, dtype=torch.bool)
        contact, touch = self._contacts()
        return {"distance": distance, "start_distance": self._start_distance.clone(), "contact": contact,
                "open_ratio": open_ratio, "others_range": others_range, "success": open_ratio > self._threshold,
                "others_moved": others_moved, "range_ratio": opening / self._range_span, "touch": touch,
                "handle_box": (lo, hi)}

    def _handle_box(self):
        """World box (lo, hi) (N, 3) around the instructed target's handle geoms (`RewardProbe._handle_box`)."""
        torch = _torch()
        f64 = torch.float64
        ids = self._handle_ids
        xmat = self._geom_xmat[:, ids].to(f64)  # (N, h, 3, 3)
        xpos = self._geom_xpos[:, ids].to(f64)  # (N, h, 3)
        pts = torch.einsum("hkj,nhij->nhki", self._handle_local, xmat) + xpos[:, :, None, :]
        pts = pts.reshape(self.num_worlds, -1, 3)
        return pts.min(1).values, pts.max(1).values

    def _contacts(self):
        """(hand touches the instructed handle (N,) bool, touch force per hand part (N, parts)) from
        the step's contact list (`RewardProbe.read`, `HandTouch.vector_from`)."""
        torch = _torch()
        n = self.num_worlds
        count = self._con_geom.shape[0]
        valid = torch.arange(count, device=self.device) < self._nacon[0].to(torch.long)
        valid &= (self._con_type & self._exported) != 0
        g = self._con_geom.to(torch.long)
        g1, g2 = g[:, 0].clamp_min(0), g[:, 1].clamp_min(0)
        world = self._con_world.to(torch.long).clamp(0, n - 1)
        hand, handle = self._hand_mask, self._handle_mask
        hit = valid & ((hand[g1] & handle[g2]) | (hand[g2] & handle[g1]))
        contact = torch.zeros(n, dtype=torch.int32, device=self.device)
        contact.index_add_(0, world, hit.to(torch.int32))
        th1, th2 = self._touch_geom_hand[g1], self._touch_geom_hand[g2]
        mixed = valid & (th1 != th2)
        adr = self._con_efc[:, 0].to(torch.long)
        force = self._efc_force[world, adr.clamp_min(0)].to(torch.float64)
        force = torch.where(mixed & (adr >= 0), force.abs(), torch.zeros_like(force))
        part = self._part_of_geom[torch.where(th1, g1, g2)]
        touch = torch.zeros(n * self._n_parts, dtype=torch.float64, device=self.device)
        touch.index_add_(0, world * self._n_parts + part, force)
        return contact > 0, touch.view(n, self._n_parts)

    def _fill(self, terms) -> None:
        """The float observation vector of every world (`SceneReader.fill`'s keys and offsets)."""
        torch = _torch()
        f64 = torch.float64
        s, o = self._slices, self.obs
        o[:, s["hand_qpos"]] = self._qpos[:, self._i_hand_qpos].to(f64)
        o[:, s["hand_qvel"]] = self._qvel[:, self._i_hand_qvel].to(f64)
        o[:, s["root_pos"]] = self._xpos[:, self._root].to(f64)
        o[:, s["root_quat"]] = self._xquat[:, self._root].to(f64)
        o[:, s["root_vel"]] = self._qvel[:, self._free:self._free + 6].to(f64)
        o[:, s["grasp_site_pos"]] = self._site_xpos[:, self._site].to(f64)
        o[:, s["grasp_site_quat"]] = mat_to_quat(self._site_xmat[:, self._site].to(f64))
        o[:, s["mocap_pos"]] = self._mocap_pos64
        o[:, s["mocap_quat"]] = self._mocap_quat64
        o[:, s["touch"]] = terms["touch"]
        o[:, s["time"]] = self._time64[:, None]
        if "handle_pos" in s:
            lo, hi = terms["handle_box"]
            o[:, s["handle_pos"]] = (lo + hi) / 2
            o[:, s["handle_size"]] = hi - lo
            o[:, s["open_ratio"]] = terms["open_ratio"][:, None]
        # the instruction code (fixed per batch) stays as the pool's rows wrote it

    def _reward(self, terms):
        """`rewards.dense_reward` (or `sparse_reward`) for every world; fills reach / open / others."""
        torch = _torch()
        success = terms["success"]
        if self.config.reward_mode == "sparse":
            self._dense_terms(terms)
            return success.to(torch.float64)
        return self._dense_terms(terms)

    def _dense_terms(self, terms):
        torch = _torch()
        c = self._dense
        start, dist = terms["start_distance"], terms["distance"]
        span = start - c.reach_dead_zone
        reach = torch.clamp((start - dist - c.reach_dead_zone) / torch.where(span > 1e-9, span, torch.ones_like(span)),
                            0.0, 1.0)
        reach = torch.where(span > 1e-9, reach, (dist <= c.reach_dead_zone).to(torch.float64))
        open_span = max(self._threshold - c.open_dead_zone, 1e-9)
        open_term = torch.clamp((terms["open_ratio"] - c.open_dead_zone) / open_span, 0.0, 1.0)
        others = torch.clamp(terms["others_range"] / c.others_full, 0.0, 1.0)
        terms.update(reach=reach, open=open_term, others=others)
        total = c.reach_weight + c.contact_weight + c.open_weight
        base = (c.reach_weight * reach + c.contact_weight * terms["contact"].to(torch.float64)
                + c.open_weight * open_term) / total
        dense = torch.clamp(base * (1.0 - c.others_penalty * others), 0.0, 1.0)
        return torch.where(terms["success"] & ~terms["others_moved"], torch.ones_like(dense), dense)

    # ------------------------------------------------------------------ the CPU code on one world
    def cpu_terms(self, world: int):
        """(the float observation vector, the reward terms) that the CPU environment's own readers
        (`SceneReader.fill`, `RewardProbe.read`) give for world ``world``'s current Warp state: the
        state is copied into the CPU scene's MjData (mocap pose and time from the float64 shadows).
        For tests; the CPU scene's state is overwritten."""
        scene, mujoco = self.scene, self._mujoco
        data = scene._data
        self._mjw.get_data_into(data, self.mj_model, self.data, world_id=int(world))
        m = self._mocap
        data.mocap_pos[m] = self._mocap_pos64[world].cpu().numpy()
        data.mocap_quat[m] = self._mocap_quat64[world].cpu().numpy()
        data.time = float(self._time64[world])
        mujoco.mj_kinematics(self.mj_model, data)
        scene.probe.start_distance = float(self._start_distance[world])
        flat = np.zeros(self.obs_size)
        flat[:] = self.obs[world].cpu().numpy()  # the instruction code (not read from the state)
        terms = scene.fill(flat, self.config.privileged)
        return flat, terms

    def close(self) -> None:
        self.core.close()
        self._render = None


class CabinetCycle:
    """One `WarpBatchEnv` per (cabinet, target), stepped in turn: ``next()`` returns the next batch
    (round robin), so that training covers several cabinets. Every batch is built (compiled, put on
    the device, its start pool computed) at construction; keyword arguments go to each batch."""

    def __init__(self, num_worlds: int, episodes: list[tuple[str, str]], **kwargs):
        self.envs = [WarpBatchEnv(num_worlds, cab, joint, **kwargs) for cab, joint in episodes]
        self._i = -1

    def next(self) -> WarpBatchEnv:
        self._i = (self._i + 1) % len(self.envs)
        return self.envs[self._i]

    def close(self) -> None:
        for env in self.envs:
            env.close()


__all__ = ["CabinetCycle", "MISSING", "PhysicsRandomization", "WarpBatchEnv", "available"]
