"""Flaps: doors hinged about a horizontal axis (at their top edge: they lift up; at their bottom
edge: they drop down), whose handle swings on a circle in the vertical plane.

The instruction says only "door", and a flap's front looks like a side door's in one image, so the
planner starts every door's pull as a side door's. What tells a flap is what the hand feels: the
held handle rises (or sinks) as it comes out, by as much as a circle about a hinge at the front's
far edge predicts. The front's top and bottom edges come from the depth image
(:func:`~opend_mj.policy.perception.door_edges_vertical`), the same way a side door's hinge line does
(:func:`~opend_mj.policy.perception.door_edges`): a handle sits near a front's free edge, its hinge
at the other one. The front may continue past the flap's own edge (a coplanar front beside it), so
the edge is only an upper bound on the radius; the held path's own circle sets it within that bound.
A hand that holds too loosely to record a held path is helped by the camera: one new depth image,
a few centimetres into the pull, shows the front's shift toward the camera growing down it (a flap
hinged at its top) or up it (at its bottom). Once seen, the pull follows that circle's opening
tangent (the flap's outward normal) and the hand pitches with it, so that the grip does not twist
off the bar.
"""

from __future__ import annotations

import math

import numpy as np

from opend_mj.policy.perception import door_edges_vertical
from opend_mj.policy.planner.moves import yawed
from opend_mj.policy.planner.records import Flap, PlanResult, PullState
from opend_mj.policy.planner.stage import Stage, StageContext


class FlapSteering(Stage):
    """The flap variant of a door's pull: a flap seen by the held path or by the camera
    (``front``), and the pull along its circle (``config.door``; the hand's
    ``flap_min_radius_share``)."""

    def __init__(self, ctx: StageContext, front):
        super().__init__(ctx)
        self.front = front

    def front_edges_z(self, state: PullState):
        """World z of the front's top and bottom edges above and below the handle (cached per pull
        state; None where unseen)."""
        if state.front_z is None:
            handle, first = self.episode.handle, self.episode.first
            edges = None
            if handle is not None and first is not None and first.depth is not None:
                edges = door_edges_vertical(handle, first.depth, first.camera_view, self.config.perception)
            state.front_z = edges if edges is not None else ()
        return state.front_z or None

    def seen(self, state: PullState, result: PlanResult) -> Flap | None:
        """A flap where the held path rises or sinks ``flap_min_rise`` (m) or more, within a factor
        ``flap_rise_ratio`` of what a circle about the front's far edge (above for a rising handle,
        below for a sinking one) predicts for the horizontal distance it came out, and came out
        straight (its chord turned at most ``flap_max_turn_deg`` from the pull's start direction);
        None otherwise, and never for a vertical bar."""
        cfg = self.config.door
        handle = self.episode.handle
        if len(state.track) < 2 or (handle is not None and handle.kind == "bar" and handle.orientation == "vertical"):
            return None  # a hand slides up and down a vertical bar: its rise is not the part's
        p0, p = np.asarray(state.track[0], float), np.asarray(state.track[-1], float)
        dz = float(p[2] - p0[2])
        out = p[:2] - p0[:2]
        dh = float(np.linalg.norm(out))
        if abs(dz) < cfg.flap_min_rise or dh < 1e-3:
            return None
        base = state.base_dir
        chord_turn = abs(math.degrees(math.atan2(base[0] * out[1] - base[1] * out[0], float(base[:2] @ out))))
        if chord_turn > cfg.flap_max_turn_deg:
            return None  # the handle came out turning about a vertical axis: a side door's
        edges = self.front_edges_z(state)
        if edges is None:
            return None
        sign = 1.0 if dz > 0 else -1.0
        reach = float(edges[0] - p0[2]) if sign > 0 else float(p0[2] - edges[1])
        lo, hi = cfg.hinge_radius_range
        if not (lo <= reach <= hi) or dh >= reach:
            return None
        predicted = reach - math.sqrt(reach * reach - dh * dh)  # the rise on the far edge's circle
        ratio = abs(dz) / max(predicted, 1e-6)
        if not (1.0 / cfg.flap_rise_ratio <= ratio <= cfg.flap_rise_ratio):
            return None
        flap = Flap(start=p0, out=np.array([out[0], out[1], 0.0]) / dh, sign=sign, reach=reach)
        result.events.append({"flap": {"hinge": "top" if sign > 0 else "bottom", "reach": round(reach, 3),
                                       "rise": round(dz, 4), "out": round(dh, 4),
                                       "turn": round(chord_turn, 1)}})
        state.hinge = None  # a side door's hinge line seen in depth is not this part's
        return flap

    def looked(self, robot, site, run, state: PullState, result: PlanResult) -> Flap | None:
        """A flap seen by the camera, for a hand that holds too loosely to record a held path: once
        per pull state at each of ``flap_look_distances`` (m) the site came out (a tall flap has
        turned less at the same distance than a short one), a new depth image shows
        the front around the handle shifted toward the camera more along z than across it (its
        shift's slope up the front at least ``flap_front_slope``, across it at most half that): a
        flap hinged at its top edge where the lower part came out more, else at its bottom edge."""
        cfg = self.config.door
        handle = self.episode.handle
        looks = cfg.flap_look_distances
        if state.flap_looked >= len(looks) or float(np.linalg.norm(site - run.start)) < looks[state.flap_looked] \
                or (handle is not None and handle.kind == "bar" and handle.orientation == "vertical"):
            return None
        state.flap_looked += 1
        front = self.front.seen(robot, site)
        if front is None or abs(front["up"]) < cfg.flap_front_slope or abs(front["across"]) > abs(front["up"]) / 2:
            return None
        edges = self.front_edges_z(state)
        if edges is None:
            return None
        start = np.asarray(run.start, float)
        sign = 1.0 if front["up"] < 0 else -1.0  # the lower part came out more: hinged at the top
        reach = float(edges[0] - start[2]) if sign > 0 else float(start[2] - edges[1])
        out = site[:2] - start[:2]
        dh = float(np.linalg.norm(out))
        if not (cfg.hinge_radius_range[0] <= reach <= cfg.hinge_radius_range[1]) or dh < 1e-3:
            return None
        result.events.append({"flap": {"hinge": "top" if sign > 0 else "bottom", "reach": round(reach, 3),
                                       "seen_up": round(float(front["up"]), 3), "out": round(dh, 4)}})
        state.hinge = None
        return Flap(start=start, out=np.array([out[0], out[1], 0.0]) / dh, sign=sign, reach=reach)

    def radius(self, flap: Flap, state: PullState) -> float:
        """The flap's radius: the held path's circle through its start, tangent to the front there
        (least squares), within ``flap_min_radius_share`` x the far edge's reach and the reach (the
        hand's own share where its ``planner.json`` sets one)."""
        cfg = self.config.door
        share = self.hand.flap_min_radius_share
        share = cfg.flap_min_radius_share if share is None else share
        if len(state.track) < 2:
            return flap.reach
        track = np.asarray(state.track, float) - flap.start
        u = track[:, :2] @ flap.out[:2]
        w = track[:, 2] * flap.sign
        den = 2.0 * float(w @ w)
        if den < 1e-9:
            return flap.reach
        fit = float(((u * u + w * w) * w).sum()) / den
        return float(np.clip(fit, share * flap.reach, flap.reach))

    def centre(self, flap: Flap, state: PullState) -> np.ndarray:
        """The centre (world, m) of the circle the pull follows: through the held path's start,
        tangent to the front there (:meth:`radius`)."""
        return flap.start + np.array([0.0, 0.0, flap.sign * self.radius(flap, state)])

    def _tangent(self, site, state: PullState) -> tuple[float, float]:
        """The flap circle's opening tangent at the site: (along ``out``, up), about :meth:`centre`."""
        flap = state.flap
        d = site - self.centre(flap, state)
        u = float(d[:2] @ flap.out[:2])
        w = float(d[2])
        norm = max(1e-6, math.hypot(u, w))
        return flap.sign * -w / norm, flap.sign * u / norm

    def press_direction(self, site, state: PullState) -> np.ndarray:
        """The world unit vector down the flap's front at the site (straight down while it is
        closed, turned with it as it opens): the way fingers on its bar's top press."""
        flap = state.flap
        radial = site - self.centre(flap, state)  # from the hinge out to the site
        norm = float(np.linalg.norm(radial))
        if norm < 1e-6:
            return np.array([0.0, 0.0, -1.0])
        return flap.sign * radial / norm

    def tilt_at(self, site, state: PullState) -> float:
        """The flap's angle (deg, rising positive) where its handle is at ``site``."""
        t_u, t_w = self._tangent(site, state)
        return math.degrees(math.atan2(t_w, t_u))

    def steer(self, site, run, state: PullState) -> None:
        """Pull along the flap's circle: the opening tangent at the site, the hand pitched by the
        flap's angle (``state.tilt``, deg, rising positive)."""
        flap = state.flap
        t_u, t_w = self._tangent(site, state)
        state.direction = t_u * flap.out + np.array([0.0, 0.0, t_w])
        state.tilt = math.degrees(math.atan2(t_w, t_u))
        state.peak_tilt = state.tilt if abs(state.tilt) > abs(state.peak_tilt) else state.peak_tilt
        run.quat = yawed(self.config.door, state, state.turned, state.tilt)
