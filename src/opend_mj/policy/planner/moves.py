"""Elementary hand motions in control steps: a straight move of the grasp-site target, a hold."""

from __future__ import annotations

import math

import numpy as np


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
