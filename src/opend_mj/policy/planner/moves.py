"""Elementary hand motions in control steps: a straight move of the grasp-site target, a hold."""

from __future__ import annotations

import math

import numpy as np


def move(robot, start, goal, quat, fingers, speed: float) -> None:
    """Move the grasp-site target in a straight line from ``start`` to ``goal`` (m) at ``speed``
    (m/s; the task's mocap speed limit also applies), the site orientation and fingers held."""
    start, goal = np.asarray(start, float), np.asarray(goal, float)
    dist = float(np.linalg.norm(goal - start))
    n = max(1, int(math.ceil(dist / (speed * robot.control_dt))))
    for i in range(1, n + 1):
        robot.step(start + (goal - start) * i / n, quat, fingers)


def hold(robot, pos, quat, fingers, seconds: float) -> None:
    """Keep the grasp-site target and finger targets for ``seconds`` (s)."""
    for _ in range(max(0, int(round(seconds / robot.control_dt)))):
        robot.step(pos, quat, fingers)
