"""Push recovery: a door that started to open and was lost is pushed open from inside.

The hinge comes from the handle's held path (a circle fitted through it) where that agrees with the
hinge seen in depth, else from the hinge seen in depth. The hand, closed to a fist, goes round the
door's free edge into the gap between door and cabinet, palm toward the door's inside, and sweeps
along the arc, pushing the door open by contact alone.
"""

from __future__ import annotations

import math

import numpy as np

from opend_mj.policy.planner.moves import move
from opend_mj.policy.planner.records import PlanResult, PullState
from opend_mj.policy.planner.stage import Stage, StageContext
from opend_mj.transforms import mat_to_quat


class PushRecovery(Stage):
    """The push recovery (``config.recovery``): the fist from ``grasping``
    (:meth:`~opend_mj.policy.planner.grasp.Grasping.closed_profile`), a look before pushing through
    ``front``."""

    def __init__(self, ctx: StageContext, grasping, front):
        super().__init__(ctx)
        self.grasping = grasping
        self.front = front

    def door_arc(self, state: PullState):
        """(hinge (x, y), the handle's radius (m), its start angle (rad), the sense of opening
        (+1 / -1), how far it opened (rad)): from the handle's held path where that agrees with the
        hinge seen in depth, else from the hinge seen in depth. None when neither is known."""
        cfg = self.config.recovery
        if len(state.track) < cfg.push_min_track or state.flap is not None:
            return None  # too short, or a flap's (its hinge is horizontal: no side door's arc)
        track = np.array(state.track)
        p0 = track[0]
        seen = self.episode.hinge
        fit = fit_circle_xy(track) if abs(state.turned) >= cfg.push_min_turn else None
        centre = None
        if fit is not None:
            c, r = fit
            plausible = cfg.push_radius_range[0] <= r <= cfg.push_radius_range[1]
            if seen is not None:
                plausible &= float(np.linalg.norm(c - seen)) < cfg.hinge_agreement
            if plausible:
                centre = c
        if centre is None and seen is not None:
            centre = np.asarray(seen, float)
        if centre is None:
            return None
        radius = float(np.linalg.norm(p0[:2] - centre))
        a0 = math.atan2(p0[1] - centre[1], p0[0] - centre[0])
        a_now = math.atan2(track[-1][1] - centre[1], track[-1][0] - centre[0])
        sense = 1.0 if _wrap(a_now - a0) > 0 else -1.0
        return centre, radius, a0, sense, abs(_wrap(a_now - a0))

    def recover_door(self, robot, state: PullState, result: PlanResult) -> bool:
        """Push a door that opened and was lost open from inside; False where its arc is unknown or
        it opened too little (``push_min_turn``) or too little time is left (``push_min_time``)."""
        cfg = self.config.recovery
        if self.ctx.time_left(robot) < cfg.push_min_time:
            result.events.append({"push_skipped": {"time_left": round(self.ctx.time_left(robot), 2)}})
            return False
        arc = self.door_arc(state)
        if arc is None:
            return False
        centre, radius, a0, sense, opened = arc
        if math.degrees(opened) < cfg.push_min_turn or not (cfg.push_radius_range[0] <= radius <= cfg.push_radius_range[1]):
            result.events.append({"push_skipped": {"opened_deg": round(math.degrees(opened), 1), "radius": round(radius, 3)}})
            return False
        seen = self.door_seen_turn(robot)
        if seen == "unseen":
            result.events.append({"push_skipped": {"front_seen": None}})
            return False
        p0 = state.track[0]
        self.ctx.enter(result, "recover", hinge=[round(float(x), 3) for x in centre], radius=round(radius, 3),
                    opened_deg=round(math.degrees(opened), 1))
        z = float(p0[2])

        def point(rho, phi):
            a = a0 + sense * phi
            return np.array([centre[0] + rho * math.cos(a), centre[1] + rho * math.sin(a), z])

        def palm_quat(phi):
            a = a0 + sense * phi
            radial = np.array([math.cos(a), math.sin(a), 0.0])
            tangent = sense * np.array([-math.sin(a), math.cos(a), 0.0])  # the opening direction
            y = np.cross(tangent, radial)
            return mat_to_quat(np.column_stack([radial, y, tangent]))

        fist = self.grasping.closed_profile("vertical")
        site, squat = robot.site_pose()
        out = radius + cfg.push_clearance
        # round the edge ahead of the door as far as it is known to have turned: by the held path or
        # as seen (a grip that slid along the bar leaves a path that turned less than the door)
        edge = max(opened, seen or 0.0) + math.radians(cfg.push_edge_deg)
        speed = self.config.approach.approach_speed * cfg.push_speed_factor
        # round the free edge: out beyond it, across into the gap, in behind the door
        b = point(out, edge)
        move(robot, site, site + np.array([-cfg.push_step_back, 0.0, 0.0]), squat, fist, self.config.approach.move_speed)
        move(robot, robot.site_pos(), b, palm_quat(edge), fist, self.config.approach.move_speed)
        phi_in = opened * cfg.push_entry_fraction
        a = point(out, phi_in)
        move(robot, b, a, palm_quat(phi_in), fist, speed)
        rho = radius * cfg.push_radius_fraction
        c = point(rho, phi_in)
        move(robot, a, c, palm_quat(phi_in), fist, speed)
        # sweep: the palm meets the door's inside and pushes it along the arc
        phi = phi_in
        phi_end = math.radians(cfg.push_to_deg)
        dphi = self.config.pulling.speed / rho * robot.control_dt
        while phi < phi_end and self.ctx.time_left(robot) > 0.0:
            phi = min(phi_end, phi + dphi)
            robot.step(point(rho, phi), palm_quat(phi), fist)
        result.pushed = True
        result.events.append({"pushed_to_deg": round(math.degrees(phi), 1)})
        return True

    def door_seen_turn(self, robot):
        """Look before pushing: how far (rad) the door's front is seen turned across
        (:func:`~opend_mj.policy.perception.front_motion`: the tangent of a side door's angle);
        "unseen" where too little of the front around the handle is seen coming toward the
        camera: the door has either swung wide (edge-on to the camera, its place showing the
        cabinet's inside) or never moved (the hand followed its own path, not the door's), and a
        push from inside helps in neither case (one that meets a door swinging on by itself
        shuts it). None where the robot cannot look again or ``push_look`` is off."""
        if not self.config.recovery.push_look or getattr(robot, "look", None) is None:
            return None
        seen = self.front.seen(robot, robot.site_pos())
        if seen is None:
            return "unseen"
        return math.atan(abs(seen["across"]))


def _wrap(a: float) -> float:
    """An angle (rad) wrapped to [-pi, pi)."""
    return (a + math.pi) % (2 * math.pi) - math.pi


def fit_circle_xy(points: np.ndarray):
    """Least-squares circle through points' (x, y): (centre, radius), or None when degenerate."""
    xy = points[:, :2]
    A = np.column_stack([2 * xy, np.ones(len(xy))])
    b = (xy ** 2).sum(axis=1)
    try:
        sol, *_ = np.linalg.lstsq(A, b, rcond=None)
    except np.linalg.LinAlgError:
        return None
    cx, cy, c = sol
    r2 = c + cx * cx + cy * cy
    if not np.isfinite(r2) or r2 <= 0:
        return None
    return np.array([cx, cy]), float(math.sqrt(r2))
