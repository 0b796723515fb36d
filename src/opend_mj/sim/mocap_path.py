"""The mocap body's path over one control step: one pose per physics substep, toward the root target
at bounded speed (straight line for the position, slerp for the orientation).

Two implementations that give the same numbers to the bit:

* `MocapPathPlanner.plan`: the per-step path of the task. Plain float arithmetic on Python floats
  (for 3- and 4-vectors numpy's per-call overhead is larger than the arithmetic), the substeps'
  constants (travel per substep, slerp angle per substep) bound once, rows handed out as tuples
  (a row is written into MjData once; building an (n, 4) array first costs more than the writes).
* `plan_reference` / `slerp_path_reference`: the same path written with numpy rows, as the task
  computed it before; the reference the tests compare `plan` with.

Both keep the two numpy dot products of the reference (the distance to the target position and the
cosine between the quaternions): numpy's dot runs through BLAS, which may fuse multiply-adds, so a
plain-float sum of products is not guaranteed to give the same bits on every machine.
"""

from __future__ import annotations

import bisect
import math

import numpy as np


class MocapPathPlanner:
    """Plans the mocap's poses for the ``n`` substeps of a control step.

    ``max_travel``: metres the position may move per substep; ``max_angle``: radians the orientation
    may turn per substep.
    """

    def __init__(self, n: int, max_travel: float, max_angle: float):
        self.n = int(n)
        #: distance the mocap may have travelled by the end of each substep (m), as `plan_reference`
        #: computes it: k * (speed * timestep) for k = 1..n
        self.travel = (np.arange(1, self.n + 1, dtype=float) * max_travel).tolist()
        self.max_angle = float(max_angle)
        #: k * max_angle for k = 1..n (the slerp's angle budget by the end of each substep)
        self._turn = [k * self.max_angle for k in range(1, self.n + 1)]
        self._delta = np.zeros(3)

    def plan(self, pos: np.ndarray, quat: np.ndarray, target_pos, target_quat: np.ndarray):
        """(position rows or None, quaternion rows or None, writes) for the mocap at ``pos``, ``quat``
        (its MjData rows) moving toward ``target_pos`` (3 floats) and ``target_quat`` (unit, array).

        Rows are ``n`` tuples, one per substep; None where that part does not move. ``writes``: how
        many substeps change the mocap pose (from there on every row equals the last). When the
        orientation does not change, ``quat`` is set to ``target_quat`` now (what the reference does).
        """
        n = self.n
        px, py, pz = pos.tolist()
        tx, ty, tz = target_pos
        dx, dy, dz = tx - px, ty - py, tz - pz
        delta = self._delta
        delta[0], delta[1], delta[2] = dx, dy, dz
        dist = math.sqrt(float(delta.dot(delta)))  # delta @ delta: numpy's dot, without matmul's overhead
        writes = 0
        rows = None
        if dist > 1e-12:
            ux, uy, uz = dx / dist, dy / dist, dz / dist
            rows = []
            for travel in self.travel:
                # np.minimum(travel, dist); the first substep whose travel reaches dist arrives
                if travel < dist:
                    rows.append((px + ux * travel, py + uy * travel, pz + uz * travel))
                else:
                    rows.append((px + ux * dist, py + uy * dist, pz + uz * dist))
                    break
            writes = len(rows)
            if writes < n:
                rows.extend([rows[-1]] * (n - writes))
        cos = float(quat.dot(target_quat))
        if abs(cos) > 1.0 - 1e-12:  # no rotation: the common case of the planner
            quat[...] = target_quat
            return rows, None, writes
        quat_rows, quat_writes = self.slerp(quat.tolist(), target_quat.tolist())
        return rows, quat_rows, max(writes, quat_writes)

    def slerp(self, q, target) -> tuple[list, int]:
        """`slerp_path_reference` for this planner's ``n`` and angle per substep, as a list of tuples."""
        sqrt, sin = math.sqrt, math.sin
        q0, q1, q2, q3 = q
        norm = sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
        q0, q1, q2, q3 = q0 / norm, q1 / norm, q2 / norm, q3 / norm
        t0, t1, t2, t3 = target
        norm = sqrt(t0 * t0 + t1 * t1 + t2 * t2 + t3 * t3)
        t0, t1, t2, t3 = t0 / norm, t1 / norm, t2 / norm, t3 / norm
        dot = q0 * t0 + q1 * t1 + q2 * t2 + q3 * t3
        if dot < 0:  # the shorter way round
            t0, t1, t2, t3, dot = -t0, -t1, -t2, -t3, -dot
        angle = 2 * math.acos(min(1.0, dot))
        n = self.n
        if angle < 1e-9:
            return [(t0, t1, t2, t3)] * n, 1
        half = angle / 2
        sin_half = sin(half)
        rows = []
        append = rows.append
        for turn in self._turn:
            t = turn / angle
            if t > 1.0:  # min(t, 1.0)
                t = 1.0
            a, b = sin((1 - t) * half) / sin_half, sin(t * half) / sin_half
            x0, x1, x2, x3 = a * q0 + b * t0, a * q1 + b * t1, a * q2 + b * t2, a * q3 + b * t3
            norm = sqrt(x0 * x0 + x1 * x1 + x2 * x2 + x3 * x3)
            append((x0 / norm, x1 / norm, x2 / norm, x3 / norm))
            if t == 1.0:  # every later substep gives t = 1 again: the same inputs, the same row
                k = len(rows)
                rows.extend([rows[-1]] * (n - k))
                return rows, k
        return rows, n


def plan_reference(pos, quat, target_pos, target_quat, n: int, max_travel: float, max_angle: float):
    """`MocapPathPlanner.plan` with numpy rows ((n, 3) and (n, 4) arrays): the reference."""
    substep_travel = np.arange(1, n + 1, dtype=float)[:, None] * max_travel
    target_pos = np.asarray(target_pos, float)
    delta = target_pos - pos
    dist = math.sqrt(float(delta @ delta))
    writes = 0
    if dist > 1e-12:
        path_pos = pos + (delta / dist) * np.minimum(substep_travel, dist)
        # rows from the first whose travel reaches dist on are pos + unit * dist, all the same
        writes = min(bisect.bisect_left(substep_travel[:, 0].tolist(), dist) + 1, n)
    else:
        path_pos = None
    if abs(float(quat @ target_quat)) > 1.0 - 1e-12:
        quat[...] = target_quat
        return path_pos, None, writes
    path_quat, quat_writes = slerp_path_reference(quat, target_quat, max_angle, n)
    return path_pos, path_quat, max(writes, quat_writes)


def slerp_path_reference(q, target, step_angle: float, n: int) -> tuple[np.ndarray, int]:
    """``n`` quaternions (n, 4) from ``q`` toward ``target``, the k-th at most k * step_angle away,
    and how many rows differ from the last (the reference for `MocapPathPlanner.slerp`)."""
    q0, q1, q2, q3 = (float(x) for x in q)
    norm = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    q0, q1, q2, q3 = q0 / norm, q1 / norm, q2 / norm, q3 / norm
    t0, t1, t2, t3 = (float(x) for x in target)
    norm = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2 + t3 * t3)
    t0, t1, t2, t3 = t0 / norm, t1 / norm, t2 / norm, t3 / norm
    dot = q0 * t0 + q1 * t1 + q2 * t2 + q3 * t3
    if dot < 0:
        t0, t1, t2, t3, dot = -t0, -t1, -t2, -t3, -dot
    angle = 2 * math.acos(min(1.0, dot))
    if angle < 1e-9:
        return np.tile((t0, t1, t2, t3), (n, 1)), 1
    half = angle / 2
    sin_half = math.sin(half)
    rows = []
    for k in range(1, n + 1):
        t = min(k * step_angle / angle, 1.0)
        a, b = math.sin((1 - t) * half) / sin_half, math.sin(t * half) / sin_half
        x0, x1, x2, x3 = a * q0 + b * t0, a * q1 + b * t1, a * q2 + b * t2, a * q3 + b * t3
        norm = math.sqrt(x0 * x0 + x1 * x1 + x2 * x2 + x3 * x3)
        rows.append((x0 / norm, x1 / norm, x2 / norm, x3 / norm))
        if t == 1.0:
            rows.extend([rows[-1]] * (n - k))
            return np.array(rows), k
    return np.array(rows), n
