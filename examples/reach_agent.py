"""An agent for `opend run --policy` that reaches for the instructed handle and touches it.

    opend run --policy examples/reach_agent.py --hand allegro --split test --out results/reach_test.jsonl
    opend score --common results/reach_test.jsonl results/oracle_test.jsonl

SCORE

On the first observation the shipped Faster R-CNN finds the handle (`opend_mj.policy.solvers.locate`:
a pixel box and the handle's world point, from the RGB-D image and the camera arrays). The agent
then moves the hand's grasp site, in the hand's start orientation with the fingers open, to a point
``standoff`` in front of the handle, advances along +x (into the cabinet, which faces -x) until a
touch sensor feels more than ``touch_force`` or the site is ``depth`` past the handle's front, holds
``hold`` seconds and stops. It never closes the fingers: it does not open anything.
"""

from __future__ import annotations

import numpy as np

from opend_mj.policy.solvers import locate
from opend_mj.sim.hands import grasp_pose_to_root_pose


class Agent:
    name = "reach"
    control = "absolute"  # root target position (m, world), root quaternion (w x y z), finger targets
    images = "first"

    def __init__(self, solver: str = "fasterrcnn", standoff: float = 0.08, depth: float = 0.03,
                 speed: float = 0.15, touch_force: float = 0.5, hold: float = 0.3):
        self.solver = solver
        self.standoff = float(standoff)  # m in front of the handle's front where the approach starts
        self.depth = float(depth)  # m past the handle's front where the advance ends without a touch
        self.speed = float(speed)  # m/s of the advance
        self.touch_force = float(touch_force)  # N on any part of the hand that counts as a touch
        self.hold = float(hold)  # s held at the touch before stopping

    def reset(self, episode) -> None:
        self.spec = episode.hand_spec
        self.dt = episode.control_dt
        self.fingers = np.asarray(episode.hand_spec.open_pose, float)
        self.goal = None  # the grasp site's target (world, m)
        self.phase = "locate"
        self.until = None

    def _action(self, site_pos) -> np.ndarray:
        root_pos, root_quat = grasp_pose_to_root_pose(self.spec, site_pos, self.quat)
        return np.concatenate([root_pos, root_quat, self.fingers])

    def act(self, obs: dict):
        site, t = obs["grasp_site_pos"], float(obs["time"][0])
        if self.phase == "locate":
            found = locate(obs, solver=self.solver)
            if found is None:
                return None  # no handle found: nothing to reach for
            self.quat = obs["grasp_site_quat"].copy()
            self.handle = found.point
            self.front_x = found.front_x
            self.goal = np.array([found.front_x - self.standoff, found.point[1], found.point[2]])
            self.phase = "approach"
        if self.phase == "approach" and (np.linalg.norm(site - self.goal) < 0.01 or t > 6.0):
            self.phase = "advance"
        if self.phase == "advance":
            touched = float(np.max(obs["touch"])) > self.touch_force
            if touched or self.goal[0] >= self.front_x + self.depth:
                self.phase, self.until = "hold", t + self.hold
            else:
                self.goal = self.goal + np.array([self.speed * self.dt, 0.0, 0.0])
        if self.phase == "hold" and t >= self.until:
            return None
        return self._action(self.goal)
