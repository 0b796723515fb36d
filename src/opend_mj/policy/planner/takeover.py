"""Taking over an episode mid-way (the planner as an interactive expert, :mod:`opend_mj.policy.expert`):
the grasp chosen in the first image moved with its part, the pull's progress so far, a door's hinge
or a flap's, and whether the hand already holds the handle.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from opend_mj.policy.planner.moves import unyawed
from opend_mj.policy.planner.pull import Pulling
from opend_mj.policy.planner.records import Flap, GraspChoice, PartMotion, PlanResult, PullState, StageOutcome
from opend_mj.policy.planner.stage import Stage, StageContext

#: An episode taken over with its part open this share of its range or more is done (the benchmark's
#: second criterion already holds; pulling on from a wide angle, near its stop, would drag a door shut).
TAKEN_OVER_OPEN = 0.75


class TakeOver(Stage):
    """An episode taken over mid-way (``config.pulling``'s done travel and angle, ``config.door``,
    ``config.recovery``): reads the grip through ``approach``
    (:meth:`~opend_mj.policy.planner.approach.Approach.holds`), a flap's tilt through ``flap``, and
    pushes a door left ajar open through ``recovery``."""

    def __init__(self, ctx: StageContext, approach, flap, recovery):
        super().__init__(ctx)
        self.approach = approach
        self.flap = flap
        self.recovery = recovery

    def resume(self, robot, grasp: GraspChoice, motion: PartMotion, door: bool, state: PullState,
               result: PlanResult) -> tuple[StageOutcome | None, GraspChoice, bool]:
        """Take over from where another agent left the hand, the instructed part moved by ``motion``
        since the first image: (outcome, the moved grasp, held). The outcome is ``DONE`` where the
        part is as open as a finished pull leaves it, ``NOT_HELD`` where a door left ajar was pushed
        open from inside (as a lost one), else None: the planner goes on from the moved grasp (pulling
        on where ``held``, the hand already holding the handle)."""
        cfg = self.config
        start = grasp.pos
        grasp, held = self._moved_grasp(robot, grasp, motion, state, result)
        if (motion.angle_deg >= cfg.pulling.door_done_deg if door else state.travelled >= cfg.pulling.drawer_done) \
                or (motion.share is not None and motion.share >= TAKEN_OVER_OPEN):
            return StageOutcome.DONE, grasp, held
        if door and not held and cfg.recovery.push_recovery and self._door_turned(motion, start, state) \
                and self.recovery.recover_door(robot, state, result):
            return StageOutcome.NOT_HELD, grasp, held
        return None, grasp, held

    def _moved_grasp(self, robot, grasp: GraspChoice, motion: PartMotion, state: PullState, result: PlanResult):
        """The grasp chosen in the first image moved with its part (``motion``), the pull's travel so
        far (m) taken from the part's slide or the grasp point's path, and whether the hand already
        holds the handle (:meth:`Approach.holds`). Returns (the moved grasp, held)."""
        pos = motion.point(grasp.pos)
        moved = replace(grasp, pos=pos, quat=motion.orientation(grasp.quat),
                        probe=None if grasp.probe is None else motion.rot @ np.asarray(grasp.probe, float))
        state.travelled = float(np.linalg.norm(pos - grasp.pos))
        out = motion.rot @ state.base_dir
        out[2] = 0.0
        if result.target_kind == "door" and np.linalg.norm(out) > 1e-6:  # a door: the pull goes on along its turn
            out = out / np.linalg.norm(out)
            b = state.base_dir
            state.direction = out
            state.turned = state.peak_turn = math.degrees(math.atan2(b[0] * out[1] - b[1] * out[0], float(b @ out)))
            if motion.angle_deg > 2.0:
                # the camera's flap looks compare the front with the first image, in which this door was
                # still closed: the motion tells a side door from a flap instead
                state.flap_looked = len(self.config.door.flap_look_distances)
                if not motion.upright:  # turned about a level hinge: a flap, hinged above or below the grasp
                    start = np.asarray(grasp.pos, float)
                    sign = 1.0 if motion.pivot[2] > start[2] else -1.0
                    state.flap = Flap(start=start, out=state.base_dir.copy(), sign=sign,
                                      reach=abs(float(motion.pivot[2] - start[2])))
                    state.hinge = None
                    state.direction, state.turned, state.peak_turn = state.base_dir.copy(), 0.0, 0.0
                elif self.config.door.hinge_pull:  # a side door: the pull goes on about its hinge
                    hinge = np.asarray(motion.pivot[:2], float)
                    self.episode.hinge = hinge
                    Pulling.turn_about(state, hinge, np.asarray(grasp.pos[:2], float) - hinge)
        held = self.approach.holds(robot, moved)
        targets = getattr(robot, "finger_targets", None)
        if held and targets is not None:
            # a held handle is pulled on as it is held: the hand's orientation and finger targets kept
            # (turning the hand or changing its grip on a part that moves with it would throw the part)
            quat = robot.site_pose()[1]
            door = self.config.door
            ang = state.turned
            if state.flap is not None:  # a flap's pull pitches the grasp's orientation by the flap's angle
                tilt = self.flap.tilt_at(robot.site_pos(), state)
                state.quat0 = unyawed(door, state, quat, 0.0, tilt)
            else:
                state.quat0 = unyawed(door, state, quat, ang)  # so that the pull's yaw starts at it
            moved = replace(moved, quat=quat, closed=np.array(targets(), float))
        self.episode.taken_over = {"turned_deg": round(motion.angle_deg, 1), "slid": round(motion.distance, 4),
                                   "held": held, "style": moved.style}
        result.events.append({"taken_over": self.episode.taken_over})
        return moved, held

    def _door_turned(self, motion: PartMotion, start, state: PullState) -> bool:
        """Whether a door taken over turned about an upright hinge at least ``push_min_turn`` (deg);
        if so, the handle's path from ``start`` (its grasp point in the first image) along that turn
        becomes the pull's held track, from which the push recovery finds the door's arc."""
        rot = motion.rot
        if not motion.upright or motion.angle_deg < self.config.recovery.push_min_turn:
            return False
        turn = math.atan2(rot[1, 0], rot[0, 0])
        pivot = motion.pivot
        state.track = []
        for f in np.linspace(0.0, 1.0, 12):
            c, s = math.cos(f * turn), math.sin(f * turn)
            r = np.asarray(start, float) - pivot
            state.track.append(pivot + np.array([c * r[0] - s * r[1], s * r[0] + c * r[1], r[2]]))
        return True
