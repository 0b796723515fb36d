"""Elementary hand motions in control steps: a straight move of the grasp-site target, a hold, and
the hand's orientation along a pull."""

from __future__ import annotations

import math

import numpy as np

from opend_mj.transforms import axis_angle_quat, quat_mul, turn_about_z


def pressed(robot, target, press: float, floor: float | None = None) -> np.ndarray:
    """``target`` no more than ``press`` (m) below the grasp site, nor below ``floor`` (m, world z):
    fingers that rest on a handle press on it with a bounded force (the mocap weld's spring over
    ``press``), not with the whole of a target far below them. ``press`` 0: ``target``."""
    if not press:
        return target
    z = max(float(target[2]), float(robot.site_pos()[2]) - press)
    if floor is not None:
        z = max(z, floor)
    if z == float(target[2]):
        return target
    out = np.array(target, float)
    out[2] = z
    return out


def kept_down(robot, target, press: float, floor: float) -> np.ndarray:
    """``target``'s x and y at the height the press alone sets: ``press`` (m) below the grasp site,
    not below ``floor`` (m, world z): fingers hooked or pressed from above stay down on the bar,
    whatever height the pull or the verify's probe would aim at (:func:`pressed`)."""
    return pressed(robot, np.array([target[0], target[1], -np.inf]), press, floor=floor)


def move(robot, start, goal, quat, fingers, speed: float, press: float = 0.0) -> None:
    """Move the grasp-site target in a straight line from ``start`` to ``goal`` (m) at ``speed``
    (m/s; the task's mocap speed limit also applies), the site orientation and fingers held;
    ``press``: see :func:`pressed`."""
    start, goal = np.asarray(start, float), np.asarray(goal, float)
    dist = float(np.linalg.norm(goal - start))
    n = max(1, int(math.ceil(dist / (speed * robot.control_dt))))
    for i in range(1, n + 1):
        robot.step(pressed(robot, start + (goal - start) * i / n, press), quat, fingers)


def hold(robot, pos, quat, fingers, seconds: float, press: float = 0.0) -> None:
    """Keep the grasp-site target and finger targets for ``seconds`` (s); ``press``: see :func:`pressed`."""
    for _ in range(max(0, int(round(seconds / robot.control_dt)))):
        robot.step(pressed(robot, pos, press), quat, fingers)


def yawed(door, state, ang: float, tilt: float = 0.0) -> np.ndarray:
    """The site orientation for a pull (``state``: a :class:`~.records.PullState`; ``door``: the
    planner's :class:`~.config.DoorConfig`) whose direction is turned ``ang`` (deg) about z and tilted
    ``tilt`` (deg, up positive) out of the horizontal: the grasp's, turned about z, then pitched
    about the horizontal axis across the pull (the hand stays square to a flap it holds)."""
    cfg = door
    yaw = cfg.yaw_gain * ang + math.copysign(min(abs(ang), cfg.yaw_lead_deg), ang)
    quat = turn_about_z(state.quat0, math.radians(yaw))
    if tilt == 0.0:
        return quat
    a = math.radians(ang)
    b = state.base_dir
    h = np.array([b[0] * math.cos(a) - b[1] * math.sin(a), b[0] * math.sin(a) + b[1] * math.cos(a), 0.0])
    axis = np.cross(h, np.array([0.0, 0.0, 1.0]))  # rotating h about it by +tilt lifts it
    q = quat_mul(axis_angle_quat(axis, math.radians(cfg.tilt_gain * tilt)), quat)
    return q / np.linalg.norm(q)


def unyawed(door, state, quat, ang: float, tilt: float = 0.0) -> np.ndarray:
    """The grasp orientation from which :func:`yawed` gives ``quat`` for a pull turned ``ang`` (deg)
    and tilted ``tilt`` (deg): a pull taken over mid-way goes on from the hand's own orientation."""
    cfg = door
    q = np.asarray(quat, float)
    if tilt != 0.0:
        a = math.radians(ang)
        b = state.base_dir
        h = np.array([b[0] * math.cos(a) - b[1] * math.sin(a), b[0] * math.sin(a) + b[1] * math.cos(a), 0.0])
        axis = np.cross(h, np.array([0.0, 0.0, 1.0]))
        q = quat_mul(axis_angle_quat(axis, -math.radians(cfg.tilt_gain * tilt)), q)
    yaw = cfg.yaw_gain * ang + math.copysign(min(abs(ang), cfg.yaw_lead_deg), ang)
    q = turn_about_z(q, -math.radians(yaw))
    return q / np.linalg.norm(q)
