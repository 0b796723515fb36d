"""The environments' action spaces: normalised delta actions turned into the task's own action.

See `opend_mj.sim.envs` for the two control modes (``"delta"``, ``"absolute"``).
"""

from __future__ import annotations

import math

import numpy as np

from opend_mj.sim.hands import get_hand, load_spec
from opend_mj.sim.task import TaskConfig
from opend_mj.transforms import axis_angle_quat, quat_mul

#: Root position bounds of the absolute action space (the task clips to the cabinet's bounds +- 1.5 m).
ABSOLUTE_ROOT_LOW = (-3.0, -3.0, 0.0)
ABSOLUTE_ROOT_HIGH = (3.0, 3.0, 3.0)


class ActionAdapter:
    """Turns a normalised delta action into the task's own action (see the module doc)."""

    def __init__(self, hand: str, task_config: TaskConfig):
        import mujoco

        self.spec = load_spec(hand)
        model = mujoco.MjModel.from_xml_path(str(get_hand(hand).xml_path))
        ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a) for a in self.spec.actuator_names]
        ranges = model.actuator_ctrlrange[ids]
        self.finger_low, self.finger_high = ranges[:, 0].copy(), ranges[:, 1].copy()
        self.n_fingers = len(ids)
        self.step_pos = task_config.max_root_speed / task_config.control_hz
        self.step_rot = task_config.max_root_angular_speed / task_config.control_hz
        self._unit_low, self._unit_high = -np.ones(self.delta_dim), np.ones(self.delta_dim)
        self._half_span = 0.5 * (self.finger_high - self.finger_low)
        # buffers of `delta_parts`: the clipped action and the finger targets
        self._clipped = np.zeros(self.delta_dim)
        self._delta_shape = (self.delta_dim,)
        self._clipped_fingers = self._clipped[6:]
        self._fingers = np.zeros(self.n_fingers)

    @property
    def delta_dim(self) -> int:
        return 6 + self.n_fingers

    @property
    def absolute_dim(self) -> int:
        return 7 + self.n_fingers

    def absolute_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        low = np.concatenate([ABSOLUTE_ROOT_LOW, -np.ones(4), self.finger_low])
        high = np.concatenate([ABSOLUTE_ROOT_HIGH, np.ones(4), self.finger_high])
        return low, high

    def fingers_from_unit(self, unit) -> np.ndarray:
        u = np.clip(np.asarray(unit, float), -1.0, 1.0)
        return self.finger_low + (u + 1.0) * 0.5 * (self.finger_high - self.finger_low)

    def fingers_to_unit(self, fingers) -> np.ndarray:
        span = np.maximum(self.finger_high - self.finger_low, 1e-12)
        return np.clip(2.0 * (np.asarray(fingers, float) - self.finger_low) / span - 1.0, -1.0, 1.0)

    def from_delta(self, action, mocap_pos, mocap_quat) -> np.ndarray:
        """The task's action for a delta action from the current mocap pose (see `delta_parts`)."""
        pos, quat, fingers = self.delta_parts(action, mocap_pos, mocap_quat)
        return np.array(pos + quat.tolist() + fingers.tolist())

    def delta_parts(self, action, mocap_pos, mocap_quat) -> tuple[list, np.ndarray, np.ndarray]:
        """`from_delta` in parts: root target position (3 floats), quaternion (a new 4-array) and
        finger targets (an array of this adapter's, overwritten by the next call).

        Plain float arithmetic where numpy's would be per-call overhead on 3- and 4-vectors; the
        operations and their order are those of ``pos + a * step``, `axis_angle_quat`, `quat_mul`
        and `fingers_from_unit` (``np.linalg.norm`` of a vector is ``sqrt(v.dot(v))``; dot products
        and sin/cos stay numpy's: BLAS may fuse multiply-adds, numpy may vectorise sin; ``np.clip(a,
        -1, 1)`` is ``minimum(maximum(a, -1), 1)`` with array bounds), so the numbers are the same
        to the bit.
        """
        a = action if type(action) is np.ndarray and action.dtype.kind == "f" else np.asarray(action, float)
        if a.shape != self._delta_shape:
            raise ValueError(f"delta action has shape {a.shape}, expected ({self.delta_dim},)")
        clipped = self._clipped  # float64: the clip of a float32 action is that of its float64 copy
        np.minimum(np.maximum(a, self._unit_low, out=clipped), self._unit_high, out=clipped)
        values = clipped.tolist()
        px, py, pz = (mocap_pos if type(mocap_pos) is np.ndarray else np.asarray(mocap_pos, float)).tolist()
        sp, sr = self.step_pos, self.step_rot
        ax, ay, az = values[3] * sr, values[4] * sr, values[5] * sr
        rotvec = np.array((ax, ay, az))
        angle = math.sqrt(rotvec.dot(rotvec))  # what rotvec @ rotvec gives (numpy's dot), cheaper
        if angle > 1e-12:
            axis = np.array((ax / angle, ay / angle, az / angle))
            norm = math.sqrt(axis.dot(axis))
            half = angle / 2
            s = float(np.sin(half))
            w1, x1, y1, z1 = (float(np.cos(half)), s * (ax / angle / norm), s * (ay / angle / norm),
                              s * (az / angle / norm))
            w2, x2, y2, z2 = (mocap_quat if type(mocap_quat) is np.ndarray else np.asarray(mocap_quat, float)).tolist()
            quat = np.array((w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                             w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2))
            quat /= math.sqrt(quat.dot(quat))
        else:
            quat = np.array(mocap_quat, float)
        # lo + (u + 1) * 0.5 * span as lo + (u + 1) * (0.5 * span), into a buffer: halving is exact
        # (u + 1 is 0 or at least 2**-53, never subnormal), so both round the same product
        fingers = self._fingers
        np.add(self._clipped_fingers, 1.0, out=fingers)
        np.multiply(fingers, self._half_span, out=fingers)
        np.add(self.finger_low, fingers, out=fingers)
        pos = [px + values[0] * sp, py + values[1] * sp, pz + values[2] * sp]
        # the task's check of a native action (`OpenCabinetTask.before_step`): a finger target is
        # finite where its clipped action is, so one sum tests all (a sum of finite numbers can
        # only overflow, which the full test then clears)
        if not math.isfinite(sum(pos) + sum(quat.tolist()) + sum(values)):
            native = np.concatenate([pos, quat, fingers])
            if not np.isfinite(native).all():
                raise ValueError(f"action has non-finite values: {native}")
        return pos, quat, fingers

    def from_delta_reference(self, action, mocap_pos, mocap_quat) -> np.ndarray:
        """`from_delta` written with the rotation helpers (the reference it is tested against)."""
        a = np.clip(np.asarray(action, float), -1.0, 1.0)
        if a.shape != (self.delta_dim,):
            raise ValueError(f"delta action has shape {a.shape}, expected ({self.delta_dim},)")
        pos = np.asarray(mocap_pos, float) + a[:3] * self.step_pos
        rotvec = a[3:6] * self.step_rot
        angle = float(math.sqrt(rotvec @ rotvec))
        quat = np.asarray(mocap_quat, float)
        if angle > 1e-12:
            quat = quat_mul(axis_angle_quat(rotvec / angle, angle), quat)
            quat = quat / np.linalg.norm(quat)
        return np.concatenate([pos, quat, self.fingers_from_unit(a[6:])])
