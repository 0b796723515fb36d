"""One fake robot for the planner's stage tests: the planner's ``Robot`` interface over a part whose
handle moves as a real one's does, with no simulator.

A :class:`FakeRobot` holds its part's handle from the start: each control step the handle goes to
the point of its path nearest the hand's target (:meth:`FakeRobot.follow`, the part's own motion),
at most ``HANDLE_SPEED`` fast and within the part's range. A part may lose the grip
(:meth:`FakeRobot.let_go`): the hand then moves freely and feels nothing. Subclasses are the parts:
a drawer or a side door (``test_pull_to_stop``), a flap (``test_pull_flap``), a door seen by the
camera (``test_pull_door_hinge``, ``test_pull_gripper``), a sliding panel (``test_pull_slide``).
"""

from __future__ import annotations

import numpy as np

DT = 1.0 / 60.0  # the task's control step (s)
HANDLE_SPEED = 2.0  # the fastest a hand can move a handle (m/s)
HELD_TOUCH = {"ff": 5.0, "mf": 5.0, "rf": 5.0}  # what a hand holding a bar feels per part (N)


class FakeRobot:
    """The robot interface over a held part (subclasses: :meth:`handle_pos` and :meth:`follow`).

    ``look``: None (no camera to look again) unless a part renders its depth; ``dof``: the finger
    joints reported (16: the Allegro's)."""

    look = None
    control_dt = DT

    def __init__(self, dof: int = 16):
        self.dof = dof
        self.n_steps = 0
        self.held = True
        self.free: np.ndarray | None = None  # the site once the grip is lost

    @property
    def time(self) -> float:
        return self.n_steps * DT

    def handle_pos(self) -> np.ndarray:
        raise NotImplementedError

    def follow(self, target: np.ndarray, quat: np.ndarray, fingers) -> None:
        """Move the held handle toward ``target`` (the part's motion; may :meth:`let_go`)."""
        raise NotImplementedError

    def site_pos(self) -> np.ndarray:
        return self.handle_pos() if self.held else self.free.copy()

    def site_pose(self):
        return self.site_pos(), np.array([1.0, 0.0, 0.0, 0.0])

    def finger_qpos(self) -> np.ndarray:
        return np.zeros(self.dof)

    def touch(self) -> dict:
        """What the hand feels while it holds."""
        return dict(HELD_TOUCH)

    def contact_touch(self) -> dict:
        return self.touch() if self.held else {}

    def step(self, site_pos, site_quat, fingers) -> None:
        p = np.asarray(site_pos, float)
        self.n_steps += 1
        if not self.held:
            self.free = p
            return
        self.follow(p, site_quat, fingers)

    def let_go(self, at: np.ndarray) -> None:
        """The grip is lost, for good, with the site at ``at``."""
        self.held, self.free = False, np.asarray(at, float).copy()

    @staticmethod
    def moved(now: float, want: float, travel: float, rate: float) -> float:
        """The part's opening after one step toward ``want``: at most ``rate`` from ``now``, within
        [0, ``travel``]."""
        return float(np.clip(want, max(0.0, now - rate), min(travel, now + rate)))
