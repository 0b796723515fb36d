"""ctypes side of `step.c`: its context struct, bound to a task (`TaskStep`) and to an environment's
observation vector and reward terms (`EnvStep`).

A `TaskStep` is made at each episode's start (`OpenCabinetTask.initialize_episode`), an `EnvStep` at
each environment reset; both hold every array whose address the context keeps, so the pointers stay
valid while they live. Limits of the C side (fixed-size buffers): at most 64 substeps per control
step, 64 finger actuators and 8 bodies carrying the instructed target's handle geoms; beyond them the
Python step runs.
"""

from __future__ import annotations

import ctypes

import numpy as np

from opend_mj.sim.rewards import RewardTerms

MAX_SUBSTEPS = 64
MAX_FINGERS = 64
MAX_HANDLE_BODIES = 8

# status bits (step.c's OFS_*)
WARNING_BITS = 7  # bit k: the k-th instability warning of `environment.INSTABILITY_WARNINGS`
NAN, LAST, BOX_STALE, BAD_ACTION, ZERO_QUAT, DISTANCE = 8, 16, 32, 64, 128, 256

_P, _I, _D = ctypes.c_void_p, ctypes.c_int64, ctypes.c_double


class Ctx(ctypes.Structure):
    """Mirror of step.c's ``ofs_ctx`` (field for field; every field is 8 bytes wide)."""

    _fields_ = [
        ("m", _P), ("d", _P), ("ddot", _P), ("ddot_ilp64", _I),
        ("substeps", _I), ("mocap_id", _I), ("n_fingers", _I),
        ("ctrl_index", _P), ("ctrl_lo", _P), ("ctrl_hi", _P), ("workspace", _P), ("travel", _P), ("turn", _P),
        ("warn_ids", _I * 3), ("time_limit", _D),
        ("has_pos", _I), ("has_quat", _I), ("writes", _I),
        ("path_pos", _D * (MAX_SUBSTEPS * 3)), ("path_quat", _D * (MAX_SUBSTEPS * 4)), ("root_target", _D * 7),
        ("action", _P), ("native", _P), ("step_pos", _D), ("step_rot", _D), ("finger_low", _P), ("half_span", _P),
        ("out", _P), ("n_hand_joints", _I), ("hand_qpos_adr", _P), ("hand_dof_adr", _P),
        ("off_hand_qpos", _I), ("off_hand_qvel", _I), ("off_root_pos", _I), ("off_root_quat", _I),
        ("off_root_vel", _I), ("off_site_pos", _I), ("off_site_quat", _I), ("off_mocap_pos", _I),
        ("off_mocap_quat", _I), ("off_touch", _I), ("off_time", _I), ("off_handle_pos", _I),
        ("off_handle_size", _I), ("off_open_ratio", _I),
        ("root_body", _I), ("site", _I), ("free_dof", _I),
        ("n_parts", _I), ("touch_hand_geom", _P), ("part_of_geom", _P), ("elliptic", _I),
        ("probe_hand_geom", _P), ("handle_geom", _P), ("n_targets", _I), ("target_adr", _P),
        ("target_closed", _P), ("target_sign", _P), ("target_span", _P), ("target_index", _I),
        ("target_closed_value", _D), ("target_sign_value", _D), ("open_span", _D), ("range_span", _D),
        ("threshold", _D), ("moved_threshold", _D),
        ("n_handle_bodies", _I), ("handle_bodies", _P), ("box_valid", _I),
        ("box_key", _D * (MAX_HANDLE_BODIES * 7)), ("box", _D * 6),
        ("terms", _D * 7),
    ]


def _array(values, dtype) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(values), dtype=dtype)


class TaskStep:
    """The task's part of the compiled step: mocap path, finger controls, substeps.

    ``native`` is the task's action buffer (root position, quaternion, finger targets) that
    `apply` reads; ``action`` the environment's delta action buffer.
    """

    def __init__(self, lib, task, physics, ddot: tuple[int, int], warning_ids):
        """``ddot``: (address or 0, 1 for 64-bit integers) of the dot product (`fast.ddot_pointer`);
        ``warning_ids``: the mjtWarning numbers of the instability warnings, in the order of the
        status bits."""
        self.lib = lib
        self._model, self._data = physics.model.ptr, physics.data.ptr  # kept alive with the context
        ctx = self.ctx = Ctx()
        ctx.m, ctx.d = self._model._address, self._data._address
        ctx.ddot, ctx.ddot_ilp64 = ddot[0] or None, ddot[1]
        ctx.substeps, ctx.mocap_id = task._substeps, task._mocap_id
        n = len(task._ctrl_index)
        ctx.n_fingers = n
        lo, hi = task._ctrl_range
        self._keep = [_array(task._ctrl_index, np.int64), _array(lo, np.float64), _array(hi, np.float64),
                      _array(np.concatenate(task._workspace), np.float64), _array(task._planner.travel, np.float64),
                      _array(task._planner._turn, np.float64)]
        (ctx.ctrl_index, ctx.ctrl_lo, ctx.ctrl_hi, ctx.workspace, ctx.travel,
         ctx.turn) = (a.ctypes.data for a in self._keep)
        ctx.warn_ids[:] = [int(w) for w in warning_ids]
        ctx.time_limit = task.config.time_limit
        self.native = np.zeros(7 + n)
        self.action = np.zeros(6 + n)
        ctx.native, ctx.action = self.native.ctypes.data, self.action.ctypes.data
        self.ptr = ctypes.addressof(ctx)
        self._apply, self._substeps, self._write_row = lib.ofs_apply, lib.ofs_substeps, lib.ofs_write_row
        self.root_target = np.ctypeslib.as_array(ctx.root_target)

    @staticmethod
    def supports(task) -> bool:
        return task._substeps <= MAX_SUBSTEPS and len(task._ctrl_index) <= MAX_FINGERS

    def apply(self) -> int:
        """`OpenCabinetTask.apply_action` of ``native`` (nonzero: a zero-norm quaternion, nothing done)."""
        return self._apply(self.ptr)

    def substeps(self, cameras: bool) -> int:
        """`OpenCabinetTask.fast_substeps` of the path `apply` planned; the instability warning bits."""
        return self._substeps(self.ptr, 1 if cameras else 0)

    def write_row(self, i: int) -> None:
        self._write_row(self.ptr, i)

    def path(self) -> tuple[np.ndarray | None, np.ndarray | None, int]:
        """(position rows (n, 3) or None, quaternion rows (n, 4) or None, writes) of the last plan."""
        ctx, n = self.ctx, self.ctx.substeps
        pos = np.ctypeslib.as_array(ctx.path_pos)[:3 * n].reshape(n, 3).copy() if ctx.has_pos else None
        quat = np.ctypeslib.as_array(ctx.path_quat)[:4 * n].reshape(n, 4).copy() if ctx.has_quat else None
        return pos, quat, int(ctx.writes)


class EnvStep:
    """The environment's whole step in one call: `OpenDCore.step` (lean) for one episode.

    Binds the observation vector's offsets, the touch parts and the reward probe's instructed target
    to the task's context; `step` runs a control step and fills the vector and the reward terms.
    """

    def __init__(self, task_step: TaskStep, scene, out: np.ndarray, adapter, delta: bool, cameras: bool,
                 privileged: bool):
        task, probe, touch = scene.task, scene.probe, scene._touch
        ctx = task_step.ctx
        self.task_step, self.ctx, self._probe = task_step, ctx, probe
        self._delta, self._cameras, self._privileged = int(delta), int(cameras), int(privileged)
        self._input = task_step.action if delta else task_step.native
        self._shape = self._input.shape
        keep = self._keep = {}

        def ptr(name, values, dtype):
            keep[name] = a = _array(values, dtype)
            return a.ctypes.data

        ctx.step_pos, ctx.step_rot = adapter.step_pos, adapter.step_rot
        ctx.finger_low = ptr("finger_low", adapter.finger_low, np.float64)
        ctx.half_span = ptr("half_span", adapter._half_span, np.float64)
        if out.dtype != np.float64 or not out.flags.c_contiguous:
            raise ValueError("the observation vector must be contiguous float64")
        self._out = out
        ctx.out = out.ctypes.data
        ctx.n_hand_joints = len(scene._qpos)
        ctx.hand_qpos_adr = ptr("qpos", scene._qpos, np.int64)
        ctx.hand_dof_adr = ptr("dof", scene._qvel, np.int64)
        slices = scene._slices
        for key, field in (("hand_qpos", "off_hand_qpos"), ("hand_qvel", "off_hand_qvel"), ("root_pos", "off_root_pos"),
                           ("root_quat", "off_root_quat"), ("root_vel", "off_root_vel"),
                           ("grasp_site_pos", "off_site_pos"), ("grasp_site_quat", "off_site_quat"),
                           ("mocap_pos", "off_mocap_pos"), ("mocap_quat", "off_mocap_quat"), ("touch", "off_touch"),
                           ("time", "off_time"), ("handle_pos", "off_handle_pos"),
                           ("handle_size", "off_handle_size"), ("open_ratio", "off_open_ratio")):
            setattr(ctx, field, slices[key].start if key in slices else -1)
        if privileged and min(ctx.off_handle_pos, ctx.off_handle_size, ctx.off_open_ratio) < 0:
            raise ValueError("privileged observations without their offsets in the layout")
        ctx.root_body, ctx.site, ctx.free_dof = scene._root, scene._site, scene._free_dof
        ctx.n_parts = len(touch.parts)
        ctx.touch_hand_geom = ptr("touch_hand", touch._hand_geom, np.uint8)
        ctx.part_of_geom = ptr("part_of_geom", touch._part_of_geom, np.int64)
        ctx.elliptic = int(touch._elliptic)
        _, _, _, handle_mask, bodies, _, (ratios, open_span, range_span) = probe._bind(task.target.joint)
        ctx.probe_hand_geom = ptr("probe_hand", probe._hand_mask, np.uint8)
        ctx.handle_geom = ptr("handle", handle_mask, np.uint8)
        ctx.n_targets = len(ratios)
        ctx.target_adr = ptr("target_adr", probe._addresses, np.int64)
        ctx.target_closed = ptr("closed", [r[1] for r in ratios], np.float64)
        ctx.target_sign = ptr("sign", [r[2] for r in ratios], np.float64)
        ctx.target_span = ptr("span", [r[3] for r in ratios], np.float64)
        ctx.target_index = [r[0] for r in ratios].index(True)
        target = task.target
        ctx.target_closed_value, ctx.target_sign_value = target.closed, target.open_sign
        ctx.open_span, ctx.range_span = open_span, range_span
        ctx.threshold, ctx.moved_threshold = task.checker.threshold, task.checker.moved_threshold
        ctx.n_handle_bodies = len(bodies)
        ctx.handle_bodies = ptr("bodies", bodies, np.int64)
        ctx.box_valid = 0
        self._box = np.ctypeslib.as_array(ctx.box)
        self._terms = np.ctypeslib.as_array(ctx.terms)
        lib = task_step.lib
        self._step, self._fill = lib.ofs_env_step, lib.ofs_fill
        self._ptr = task_step.ptr

    @staticmethod
    def supports(scene) -> bool:
        bodies = scene.probe._bind(scene.task.target.joint)[4]
        return len(bodies) <= MAX_HANDLE_BODIES and len(scene._qpos) == len(scene._qvel)

    def step(self, action) -> int | None:
        """One control step; its status bits, or None where the Python step must run (an action of
        the wrong shape or kind, a non-finite action, a zero-norm quaternion: it raises the error)."""
        a = action if type(action) is np.ndarray else np.asarray(action)
        if a.shape != self._shape or a.dtype.kind not in "biuf":
            return None
        self._input[...] = a
        status = self._step(self._ptr, self._delta, self._cameras, self._privileged)
        if status & (BAD_ACTION | ZERO_QUAT):
            return None
        if status & BOX_STALE:  # the handle moved: its box the Python way, then the observations
            lo, hi = self._probe.target_box()
            box = self._box
            box[:3] = lo
            box[3:] = hi
            status = (status & ~BOX_STALE) | self._fill(self._ptr, self._privileged, 1)
        return status

    def terms(self, status: int) -> RewardTerms:
        """The reward terms of the step that returned ``status`` (`RewardProbe.read`'s)."""
        distance, contact, open_ratio, others_range, success, moved, range_ratio = self._terms.tolist()
        probe = self._probe
        if status & DISTANCE:  # a non-finite grasp site or box: the reference's distance
            distance = probe.distance(probe.target_box())
        return RewardTerms(distance, probe.start_distance, contact != 0.0, open_ratio, others_range, success != 0.0,
                           moved != 0.0, 0.0, 0.0, 0.0, range_ratio)
