"""Push recovery: a door that started to open and was lost is pushed open from inside.

The hinge comes from the handle's held path (a circle fitted through it) where that agrees with the
hinge seen in depth, else from the hinge seen in depth. The hand, closed to a fist, goes round the
door's free edge into the gap between door and cabinet, palm toward the door's inside, and sweeps
along the arc, pushing the door open by contact alone.

A flap that was lost part way stays where it was let go (it is counterbalanced), its inside facing
down and out (hinged at its top) or up and out (at its bottom); the hand goes round its free edge the
same way and pushes it on by its inside along its circle about the front's far edge.
"""

from __future__ import annotations

import math

import numpy as np

from opend_mj.policy.perception import door_edges
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
        if state.flap is not None:
            return self.push_flap(robot, state, result)
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

        # beyond the door's free edge, which may be well beyond its handle; ahead of the door as far
        # as it is known to have turned: by the held path or as seen (a grip that slid along the bar
        # leaves a path that turned less than the door); across into the gap along the chord
        out = max(radius, self.door_width(centre) or 0.0) + cfg.push_clearance
        edge = max(opened, seen or 0.0) + math.radians(cfg.push_edge_deg)
        self._push_round(robot, point, palm_quat, self.grasping.closed_profile("vertical"), np.array([-1.0, 0.0, 0.0]),
                         out, edge, opened * cfg.push_entry_fraction, radius * cfg.push_radius_fraction,
                         math.radians(cfg.push_to_deg), None, result)
        return True

    def _push_round(self, robot, point, palm_quat, fist, back, out: float, edge: float, phi_in: float, rho: float,
                    phi_end: float, arc_step: float | None, result: PlanResult) -> None:
        """Round a part's free edge and push it open by its inside, the hand a ``fist``: a step of
        ``push_step_back`` (m) along ``back``, to ``point(out, edge)`` (m, rad) beyond the edge and
        ahead of the part, across to ``point(out, phi_in)`` (along the circle in steps of at most
        ``arc_step`` deg, or its chord where None: a long chord cuts inside the circle, by 5 cm for
        40 degrees 80 cm out, and can catch the edge and shut the part), in to ``point(rho, phi_in)``
        in the gap, then the sweep (:meth:`_sweep`) to ``phi_end``; oriented ``palm_quat(angle)``."""
        cfg = self.config.recovery
        site, squat = robot.site_pose()
        speed = self.config.approach.approach_speed * cfg.push_speed_factor
        move(robot, site, site + cfg.push_step_back * back, squat, fist, self.config.approach.move_speed)
        move(robot, robot.site_pos(), point(out, edge), palm_quat(edge), fist, self.config.approach.move_speed)
        steps = 1 if arc_step is None else max(1, int(math.ceil(math.degrees(abs(edge - phi_in)) / arc_step)))
        arc = np.linspace(edge, phi_in, steps + 1)
        for p0, p1 in zip(arc[:-1], arc[1:]):
            move(robot, point(out, p0), point(out, p1), palm_quat(p1), fist, speed)
        move(robot, point(out, phi_in), point(rho, phi_in), palm_quat(phi_in), fist, speed)
        self._sweep(robot, point, palm_quat, fist, rho, phi_in, phi_end, result)

    def _sweep(self, robot, point, palm_quat, fist, rho: float, phi: float, phi_end: float,
               result: PlanResult) -> None:
        """The palm meets the part's inside and pushes it along its arc at the pull speed: the
        site at ``point(rho, angle)``, oriented ``palm_quat(angle)``, from ``phi`` to ``phi_end``
        (rad) or until the time is up."""
        dphi = self.config.pulling.speed / rho * robot.control_dt
        while phi < phi_end and self.ctx.time_left(robot) > 0.0:
            phi = min(phi_end, phi + dphi)
            robot.step(point(rho, phi), palm_quat(phi), fist)
        result.pushed = True
        result.events.append({"pushed_to_deg": round(math.degrees(phi), 1)})

    def door_width(self, centre) -> float | None:
        """The distance (m) from the hinge ``centre`` (x, y) to the door's free edge, where its front
        plane ends along the handle's row in the first depth image on the handle's side
        (:func:`~opend_mj.policy.perception.door_edges`); None where unseen. A handle can sit well
        inside its door's edge (a 1 m door with its bar 30 cm from it)."""
        handle, first = self.episode.handle, self.episode.first
        if handle is None or first is None or first.depth is None:
            return None
        edges = door_edges(handle, first.depth, first.camera_view, self.config.perception)
        if edges is None:
            return None
        side = float(handle.centre[1]) - float(centre[1])
        edge = edges[0] if side > 0 else edges[1]  # (+y, -y) ends
        return abs(float(edge) - float(centre[1]))

    def flap_arc(self, state: PullState):
        """(hinge point (m), the handle's radius (m), how far it opened (rad)) of a flap, on the
        circle about the front's far edge (the largest radius it can have,
        :class:`~.records.Flap`: the angle is never over-estimated, where a radius fitted to a path
        the hand slid along is too small) through the held path's last point; None where no flap
        was seen."""
        flap = state.flap
        if flap is None or len(state.track) < 2:
            return None
        radius = flap.reach
        centre = np.asarray(flap.start, float) + np.array([0.0, 0.0, flap.sign * radius])
        d = np.asarray(state.track[-1], float) - centre
        return centre, radius, math.atan2(float(d[:2] @ flap.out[:2]), -flap.sign * float(d[2]))

    def swung(self, state: PullState) -> float:
        """How far (deg) a door swung while held: a flap as far as its held path opened it (the
        hand's pitch runs on after a lost grip until the slip is noticed; a flap stays where it was
        let go), else :meth:`PullState.swung`."""
        arc = self.flap_arc(state)
        return state.swung() if arc is None else math.degrees(arc[2])

    def push_flap(self, robot, state: PullState, result: PlanResult) -> bool:
        """Push a flap that was lost after opening ``flap_push_min_deg`` or more open by its inside
        (from below one hinged at its top, from above one hinged at its bottom): round its free
        edge (``push_clearance`` beyond the handle's radius, ``push_edge_deg`` ahead of it), into
        the wedge between flap and cabinet at ``push_entry_fraction`` of its angle and
        ``push_radius_fraction`` of the handle's radius from the hinge, then on along the circle to
        ``flap_push_to_deg``. False where no flap was seen or it opened too little."""
        cfg = self.config.recovery
        arc = self.flap_arc(state)
        if arc is None:
            return False
        centre, radius, opened = arc
        if math.degrees(opened) < cfg.flap_push_min_deg:
            result.events.append({"push_skipped": {"flap_opened_deg": round(math.degrees(opened), 1)}})
            return False
        out = state.flap.out
        self.ctx.enter(result, "recover", hinge=[round(float(x), 3) for x in centre], radius=round(radius, 3),
                       opened_deg=round(math.degrees(opened), 1), flap=True)
        sign = state.flap.sign

        def point(rho, phi):
            return centre + rho * (math.sin(phi) * out + np.array([0.0, 0.0, -sign * math.cos(phi)]))

        def palm_quat(phi):
            radial = math.sin(phi) * out + np.array([0.0, 0.0, -sign * math.cos(phi)])
            tangent = math.cos(phi) * out + np.array([0.0, 0.0, sign * math.sin(phi)])  # the opening direction
            return mat_to_quat(np.column_stack([radial, np.cross(tangent, radial), tangent]))

        self._push_round(robot, point, palm_quat, self.grasping.closed_profile("horizontal"), out,
                         radius + cfg.push_clearance, opened + math.radians(cfg.push_edge_deg),
                         opened * cfg.push_entry_fraction, radius * cfg.push_radius_fraction,
                         math.radians(cfg.flap_push_to_deg), 10.0, result)
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
