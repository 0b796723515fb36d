"""Watching the instructed front while acting: what a new depth image says of the part being opened.

The planner looks again mid-pull (`policy.planner.kind.FrontWatch`: :func:`front_motion` between
the episode's first depth image and a new one); a learner gets the same reading as numbers, at a
rate that rendering on a CPU affords (``WatchConfig.every`` control steps between looks). The
reading (:class:`FrontWatcher`) is the front's motion seen around the handle that the first image
located: its shift toward the camera at the handle (a drawer's travel, m), the angles its plane
turned about a vertical axis (a side-hinged door) and a horizontal one (a flap), and where the
handle is now as that motion carries it (about the hinge line seen in the first image, for a door);
every step, the grasp site relative to that handle (m) says whether the hand is still with it.
Nothing here reads ground truth: the inputs are the depth images, the camera view, the first
image's percept (`policy.learned.bc_model.HandlePercept`) and the hand's own grasp site.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from opend_mj.policy.perception.front import FrontMotionConfig, front_motion


@dataclass(frozen=True)
class WatchConfig:
    """How often the front is looked at again and how a look is read."""

    #: control steps between looks (12: 5 looks per second at 60 Hz control); a look costs a
    #: depth render (about 2 ms at 256 px on a CPU) and :func:`front_motion` (a few ms)
    every: int = 12
    #: a front whose shift changes this much (m per m across) turned about a vertical axis
    min_turn: float = 0.05
    front: FrontMotionConfig = field(default_factory=FrontMotionConfig)

    def __post_init__(self):
        if self.every < 1:
            raise ValueError(f"watch every must be >= 1 control step, not {self.every}")

    def looks_at(self, step: int) -> bool:
        """Whether control step ``step`` (0 = the first action's) brings a new image."""
        return step > 0 and step % self.every == 0


#: Names of the numbers :meth:`FrontWatcher.vector` gives (units in :class:`FrontWatcher`).
WATCH_NAMES = ("looked", "seen", "shift", "turn_across", "turn_up", "handle_dx", "handle_dy",
               "site_dx", "site_dy", "site_dz", "age")
WATCH_DIM = len(WATCH_NAMES)


class FrontWatcher:
    """The latest reading of the instructed front, from the episode's first depth image and the
    looks since (:meth:`look`); :meth:`vector` gives it with the grasp site every step.

    ``vector``: ``looked`` (1 once a look was made), ``seen`` (1 where the latest look saw the front
    moved), ``shift`` (m toward the camera at the handle, within the front's ``max_shift``), ``turn_across`` / ``turn_up`` (rad: the
    front's turn about a vertical / horizontal axis, the arctangent of the shift's slope), the
    handle's displacement since the first image as that motion carries it (``handle_dx``,
    ``handle_dy``; m, world), the grasp site relative to the handle so carried (``site_d*``; m,
    world), and the latest look's ``age`` (s)."""

    def __init__(self, first_depth, view, centre, panel_x: float, hinge_point=None,
                 config: WatchConfig = WatchConfig()):
        self.first_depth = np.asarray(first_depth, np.float32)
        self.view = view
        self.centre = np.asarray(centre, float)
        self.panel_x = float(panel_x)
        self.hinge_point = None if hinge_point is None else np.asarray(hinge_point, float)
        self.config = config
        self.reading: dict | None = None  # the latest look's front_motion (None: not seen moving)
        self.looked_at: float | None = None  # s: simulated time of the latest look
        self.turn: float | None = None  # rad: the front's turn about the hinge line at the latest look

    @classmethod
    def from_percept(cls, first_depth, view, percept, config: WatchConfig = WatchConfig()) -> "FrontWatcher":
        """A watcher of the handle ``percept`` (`policy.learned.bc_model.HandlePercept`) found in
        ``first_depth``."""
        return cls(first_depth, view, percept.handle.centre, percept.handle.panel_x,
                   getattr(percept, "hinge_point", None), config)

    def look(self, depth, site, time: float) -> None:
        """Read a new depth image taken at ``time`` (s) with the grasp site at ``site`` (world, m)."""
        self.reading = front_motion(self.first_depth, np.asarray(depth, np.float32), self.view, self.centre,
                                    self.panel_x, site, self.config.front)
        self.turn = self._turn(self.reading)
        self.looked_at = float(time)

    def handle_offset(self) -> np.ndarray:
        """(dx, dy) m: the handle's displacement since the first image, as the latest look's motion
        carries it: about the hinge line where the front turned about it (:attr:`turn`), else
        straight toward the camera by the shift at the handle (within ``max_shift``: a plane fitted
        to a door turned far reads a meaningless shift where the handle was)."""
        r = self.reading
        if r is None:
            return np.zeros(2)
        if self.turn is not None:
            arm = float(self.centre[1] - self.hinge_point[1])  # m: hinge line to handle, across
            return np.array([-abs(arm) * math.sin(self.turn), -math.copysign(abs(arm) * (1.0 - math.cos(self.turn)), arm)])
        limit = self.config.front.max_shift
        return np.array([-float(np.clip(r["shift"], -limit, limit)), 0.0])

    def _turn(self, reading: dict | None) -> float | None:
        """rad: how far the front turned about the hinge line seen in the first image, or None where
        it did not (not seen moving, no hinge line, ``across`` under ``min_turn``). A turn agrees
        with the hinge line where the shift grows away from it; past a right angle the plane seen
        is the door's edge and inner face, whose slope has the other sign: a reading against the
        hinge line after a turn of over 45 degrees is read as past 90."""
        if reading is None or self.hinge_point is None:
            return None
        across = float(reading["across"])
        if abs(across) < self.config.min_turn:
            return None
        arm = float(self.centre[1] - self.hinge_point[1])
        seen = math.atan(abs(across))
        if arm * across > 0:
            return seen
        if self.turn is not None and self.turn > math.pi / 4:
            return math.pi - seen
        return None

    def vector(self, site, time: float) -> np.ndarray:
        """:data:`WATCH_DIM` numbers (:data:`WATCH_NAMES`) at ``time`` (s) with the grasp site at ``site``."""
        r = self.reading
        offset = self.handle_offset()
        handle = self.centre + np.array([offset[0], offset[1], 0.0])
        rel = np.asarray(site, float) - handle
        age = float(time) - self.looked_at if self.looked_at is not None else 0.0
        limit = self.config.front.max_shift
        seen = [0.0, 0.0, 0.0] if r is None else [float(np.clip(r["shift"], -limit, limit)),
                                                  math.atan(float(r["across"])), math.atan(float(r["up"]))]
        return np.array([float(self.looked_at is not None), float(r is not None), *seen, *offset, *rel, age],
                        np.float32)


def blind_vector(site, centre) -> np.ndarray:
    """The watch vector of an episode that never looks again (nothing seen): the grasp site relative
    to the first image's handle centre."""
    v = np.zeros(WATCH_DIM, np.float32)
    v[7:10] = np.asarray(site, float) - np.asarray(centre, float)
    return v


__all__ = ["FrontWatcher", "WATCH_DIM", "WATCH_NAMES", "WatchConfig", "blind_vector"]
