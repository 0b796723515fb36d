"""The planner's handle on an environment: the task action and the hand's own state only."""

from __future__ import annotations

from typing import Callable

import numpy as np

from opend_mj.policy.planner.clearance import FLOOR_Z
from opend_mj.sim.hands import HandSpec, HandTouch, grasp_pose_to_root_pose
from opend_mj.transforms import mat_to_quat

#: The band above the floor (m) where a touch is the floor's: no handle reaches that low (the
#: lowest stand 2-3 cm above it).
FLOOR_BAND = 0.005


class Robot:
    """Drives a dm_control environment's hand through its task action (a mocap target for the root,
    position targets for the fingers) and reads the hand's own state: grasp-site pose, finger
    joints, touch. ``look``: a new depth image from the episode's camera (the one that took the
    first observation), or None where the robot cannot look again. ``on_step``: called after every
    control step (video, probes)."""

    def __init__(self, env, on_step: Callable[[], None] | None = None,
                 look: Callable[[], np.ndarray] | None = None):
        self.env = env
        self.look = look
        self.physics = env.physics
        self.task = env.task
        self.spec: HandSpec = env.task.hand.spec
        self.on_step = on_step
        self.n_steps = 0
        # Indices read on every control step (physics.bind costs more than a physics substep).
        self._data = self.physics.data.ptr
        self._site_id = int(self.physics.bind(self.task.hand.grasp_site).element_id)
        self._finger_qpos = np.array([int(a) for a in self.physics.bind(self.task.hand.joints).qposadr])
        self._finger_ctrl = np.array([int(a) for a in self.physics.bind(self.task.hand.actuators).element_id])
        self._touch = HandTouch(self.task.hand, self.physics)  # the hand's own state

    @property
    def control_dt(self) -> float:
        """Seconds per control step."""
        return self.task.control_timestep

    @property
    def time(self) -> float:
        """Simulated seconds since the episode began."""
        return float(self._data.time)

    def site_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """The grasp site's world position (m) and orientation (quaternion w, x, y, z)."""
        d = self._data
        return d.site_xpos[self._site_id].copy(), mat_to_quat(d.site_xmat[self._site_id].reshape(3, 3))

    def site_pos(self) -> np.ndarray:
        """Where the grasp site is (the position of `site_pose`, without the orientation)."""
        return self._data.site_xpos[self._site_id].copy()

    def finger_qpos(self) -> np.ndarray:
        """The finger joints' positions (rad for hinges, m for slides)."""
        return self._data.qpos[self._finger_qpos]

    def finger_targets(self) -> np.ndarray:
        """The finger actuators' current targets (what the hand was last commanded; actuator units)."""
        return self._data.ctrl[self._finger_ctrl].copy()

    def contact_touch(self) -> dict[str, float]:
        """Normal force (N) on each part of the hand from things that are not the hand (`HandTouch`),
        leaving out presses within `FLOOR_BAND` of the floor: fingers that brush the floor below a
        low handle do not feel like a grip on it."""
        return self._touch.read(above=FLOOR_Z + FLOOR_BAND)

    def step(self, site_pos, site_quat, fingers) -> None:
        """One control step toward a grasp-site target pose (converted to the root target)."""
        root_pos, root_quat = grasp_pose_to_root_pose(self.spec, site_pos, site_quat)
        self.env.step(self.task.make_action(root_pos, root_quat, fingers))
        self.n_steps += 1
        if self.on_step is not None:
            self.on_step()


def new_depth(robot) -> np.ndarray | None:
    """A new depth image from the episode's camera, or None where the robot cannot look again
    (a robot of another kind may have no ``look``)."""
    fn = getattr(robot, "look", None)
    return fn() if fn is not None else None
