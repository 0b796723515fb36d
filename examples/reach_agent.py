"""An agent for `opend run --policy` that reaches for the instructed handle and touches it.

    opend run --policy examples/reach_agent.py --hand allegro --split test --out results/reach_test.jsonl
    opend score --common results/reach_test.jsonl results/oracle_test.jsonl

Measured on the generated test split (80 targets, Allegro hand, seed 0; the first command with
``--cabinets`` the default build's, 2.3 s of wall time per episode on 2 shared cores): success 0/80
(it never pulls); the hand in contact with the instructed handle in 65/80 episodes (``hand_to_handle``
<= 0 in the records: 37 of 41 doors, 28 of 39 drawers), within 2 cm in 70/80 (failure stage past
``approach``); no handle found in 1; no other target moved. ``opend score --common`` with the oracle's
file compares the 80 Allegro episodes both hold: oracle 96.2 % [89.5-98.7], reach 0.0 % [0.0-4.6].

On the first observation the shipped Faster R-CNN finds the handle (`opend_mj.policy.solvers.locate`:
a pixel box and the handle's world point, from the RGB-D image and the camera arrays). The agent
then moves the hand's grasp site, in the hand's start orientation with the fingers open, to a point
``standoff`` in front of the handle, advances along +x (into the cabinet, which faces -x) until a
touch sensor feels more than ``touch_force`` or the site is ``depth`` past the handle's front, then
closes the fingers to the hand's grasp profile for the handle's orientation (``hand_spec.grasp_profiles``)
over ``hand_spec.close_time``, holds ``hold`` seconds and stops. It never pulls: it opens nothing.
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
                 speed: float = 0.15, touch_force: float = 0.5, hold: float = 0.3, approach_time: float = 6.0):
        self.solver = solver
        self.standoff = float(standoff)  # m in front of the handle's front where the approach starts
        self.depth = float(depth)  # m past the handle's front where the advance ends without a touch
        self.speed = float(speed)  # m/s of the advance
        self.touch_force = float(touch_force)  # N on any part of the hand that counts as a touch
        self.hold = float(hold)  # s held, fingers closed, before stopping
        self.approach_time = float(approach_time)  # s (simulated) after which the advance starts, arrived or not

    def reset(self, episode) -> None:
        self.spec = episode.hand_spec
        self.dt = episode.control_dt
        self.open = np.asarray(episode.hand_spec.open_pose, float)  # finger targets, actuators' units
        self.goal = None  # the grasp site's target (world, m)
        self.phase = "locate"

    def _action(self, site_pos, fingers) -> np.ndarray:
        root_pos, root_quat = grasp_pose_to_root_pose(self.spec, site_pos, self.quat)
        return np.concatenate([root_pos, root_quat, fingers])

    def act(self, obs: dict):
        site, t = obs["grasp_site_pos"], float(obs["time"][0])
        if self.phase == "locate":
            found = locate(obs, solver=self.solver)
            if found is None:
                return None  # no handle found: nothing to reach for
            self.quat = obs["grasp_site_quat"].copy()
            profiles = self.spec.grasp_profiles
            self.closed = np.asarray(profiles.get(found.percept.handle.orientation, profiles["horizontal"]), float)
            self.front_x = found.front_x
            self.goal = np.array([found.front_x - self.standoff, found.point[1], found.point[2]])
            self.phase = "approach"
        if self.phase == "approach" and (np.linalg.norm(site - self.goal) < 0.01 or t > self.approach_time):
            self.phase = "advance"
        if self.phase == "advance":
            touched = float(np.max(obs["touch"])) > self.touch_force
            if touched or self.goal[0] >= self.front_x + self.depth:
                self.phase, self.since = "close", t
            else:
                self.goal = self.goal + np.array([self.speed * self.dt, 0.0, 0.0])
        fingers = self.open
        if self.phase == "close":
            w = min(1.0, (t - self.since) / max(self.spec.close_time, self.dt))
            fingers = (1.0 - w) * self.open + w * self.closed
            if t - self.since >= self.spec.close_time + self.hold:
                return None
        return self._action(self.goal, fingers)
