"""The kind check: is the held handle a door's or a drawer's, and is it the one the instruction names?

A drawer's handle slides straight, a door's swings on a circle (or tips, a flap hinged at its
bottom edge). Two readings: the held handle's path (the grasp site's track while the grip held)
and the front seen moving in a new depth image (:func:`~opend_mj.policy.perception.front_motion`).
Only learned solvers that can be asked again are checked: a handle of the other kind is taken back
along its path, let go, and the solver asked again with what was seen.
"""

from __future__ import annotations

import math

import numpy as np

from opend_mj.policy.perception import front_motion
from opend_mj.policy.planner.moves import move
from opend_mj.policy.planner.records import GraspChoice, PlanResult, PullState
from opend_mj.policy.planner.robot import new_depth
from opend_mj.policy.planner.stage import Stage, StageContext


class FrontWatch(Stage):
    """The camera looking again mid-pull: how the pulled handle's front moved since the episode's
    first image (``config.perception.front``). Read by the kind check, the door's and the flap's
    pull and the push recovery."""

    def seen(self, robot, site) -> dict | None:
        """How the pulled handle's front moved since the first image (:func:`front_motion`), where
        the robot can look again."""
        handle, first = self.episode.handle, self.episode.first
        if handle is None or first is None or first.depth is None:
            return None
        depth = new_depth(robot)
        if depth is None:
            return None
        seen = front_motion(first.depth, depth, first.camera_view, handle.centre, handle.panel_x, site,
                            self.config.perception.front)
        return None if seen is None else {k: round(v, 4) if isinstance(v, float) else v for k, v in seen.items()}


class KindCheck(Stage):
    """The kind check (``config.kind``): is the held handle the kind the instruction names? Asks
    the ``solver`` again only where it can be asked (:meth:`checks_kind`); gives a wrong handle back
    through ``approach`` (:meth:`~opend_mj.policy.planner.approach.Approach.back_off`)."""

    def __init__(self, ctx: StageContext, solver, front: FrontWatch, approach):
        super().__init__(ctx)
        self.solver = solver
        self.front = front
        self.approach = approach

    def checks_kind(self) -> bool:
        """Whether pulls watch the handle's kind: a learned solver that can be asked again."""
        return (self.config.kind.verify_kind and not getattr(self.solver, "needs_ground_truth", False)
                and getattr(self.solver, "accepts_observed", False))

    def kind_from_track(self, track: list) -> tuple[str | None, float | None, float | None]:
        """(kind, turn, tilt) of a held handle's path (site positions): the turn (deg) between the
        path's first and last ``chord`` seen from above, the tilt (deg) between them seen from the
        side. "drawer" for a path straight both ways, "door" for one that turns (a side-hinged door)
        or tilts much (a flap hinged at its bottom edge), None where too short or unclear."""
        cfg = self.config.kind
        pts = np.asarray(track, float)
        if len(pts) < 3:
            return None, None, None
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
        if s[-1] < cfg.check_distance:
            return None, None, None
        i0 = int(np.searchsorted(s, cfg.chord))
        i1 = int(np.searchsorted(s, s[-1] - cfg.chord, side="right")) - 1
        d0, d1 = pts[i0] - pts[0], pts[-1] - pts[max(0, i1)]
        h0, h1 = float(np.linalg.norm(d0[:2])), float(np.linalg.norm(d1[:2]))
        if h0 < 1e-6 or h1 < 1e-6:
            return None, None, None
        turn = abs(math.degrees(math.atan2(d0[0] * d1[1] - d0[1] * d1[0], float(d0[:2] @ d1[:2]))))
        tilt = abs(math.degrees(math.atan2(d1[2], h1) - math.atan2(d0[2], h0)))
        if cfg.door_turn <= turn <= cfg.door_turn_max or tilt >= cfg.door_tilt:
            return "door", turn, tilt
        if turn <= cfg.drawer_turn and tilt <= cfg.drawer_tilt:
            return "drawer", turn, tilt
        return None, turn, tilt

    def judge_kind(self, robot, site, state: PullState, result: PlanResult) -> bool | None:
        """The held handle's kind, from its path and from the front seen moving (both logged in
        ``result.events``): True where it is the other kind than the instruction's and is to be
        given up (``state.seen_kind``, ``seen_by``, ``seen_turn`` set), False where not, None
        where the path does not tell yet."""
        seen, turn, tilt = self.kind_from_track(state.track[state.pull_start:])
        if turn is None:
            return None
        result.events.append({"kind_seen": seen, "turn_deg": round(turn, 2), "tilt_deg": round(tilt, 2)})
        front = self.front.seen(robot, site)
        front_kind = self.kind_from_front(front)
        if front is not None:
            result.events.append({"front_seen": front, "front_kind": front_kind})
        wrong = self.wrong_kind(result.target_kind, seen, front_kind)
        if wrong is None or not self.checks_kind():
            return False
        state.seen_kind, state.seen_by = wrong
        state.seen_turn = turn
        return True

    def wrong_kind(self, named: str, path_kind: str | None, front_kind: str | None) -> tuple[str, str] | None:
        """(kind, what showed it: "front" or "path") where the pulled handle is of another kind than
        the ``named`` one, else None. The path and the front must not disagree, but for a named
        door: pulled as a door, the hand is steered round a circle whatever the part does, so the
        path's "door" shows nothing and does not stand against the front's "drawer"."""
        cfg = self.config.kind
        path_shows = None if named == "door" and path_kind == "door" else path_kind
        if front_kind in cfg.front_retry_on and front_kind != named and path_shows in (None, front_kind):
            return front_kind, "front"
        if path_kind in cfg.retry_on and path_kind != named and front_kind in (None, path_kind):
            return path_kind, "path"
        return None

    def kind_from_front(self, front: dict | None) -> str | None:
        """"door" for a front that turned, "drawer" for one that slid out level, None where unclear
        (or not seen)."""
        cfg = self.config.kind
        if front is None:
            return None
        if abs(front["across"]) >= cfg.front_door_slope or front["up"] >= cfg.front_door_slope:
            return "door"
        if max(abs(front["across"]), abs(front["up"])) <= cfg.front_drawer_slope \
                and front["shift"] >= cfg.front_drawer_shift:
            return "drawer"
        return None

    def push_back(self, robot, g: GraspChoice, state: PullState) -> None:
        """Take a wrong handle back along the path it came (still held), then let go and back off:
        the part closes again (a drawer pulled as a door may stay a little out: the hand slid
        along its bar) and leaves the way to the next handle free."""
        site, squat = robot.site_pose()
        path = [site] + [np.asarray(p, float) for p in reversed(state.track[state.pull_start:])]
        for a, b in zip(path[:-1], path[1:]):
            if float(np.linalg.norm(b - a)) > 1e-4:
                move(robot, a, b, squat, g.closed, self.config.pulling.speed)
        self.approach.back_off(robot, g)
