"""Grasp geometry: from the 3D handle and its measured shape to a grasp-site pose, finger targets
and a grasp style; the door's hinge seen in depth; where a re-grasp goes.

Site frame: +z is the approach axis (into the handle), the open fingers point along +y. A
horizontal bar is grasped with the fingers up (down near the floor or under a neighbour), a
vertical one with the fingers toward the door's hinge (dexterous hands), so that the door's pull
presses the handle into the finger curl.
"""

from __future__ import annotations

import math

import numpy as np

from opend_mj.language import hinge_side
from opend_mj.policy.perception import door_edges, infer_hinge_side
from opend_mj.policy.planner.records import GraspChoice, Observation, PlanResult, PullState
from opend_mj.sim.hands import orientation_for_handle
from opend_mj.transforms import axis_angle_quat, quat_axis_z, quat_mul, yaw_quat

#: the grasp-depth key of each style (``GraspConfig.depth[style]`` wins where it has one)
STYLE_KIND = {"hook": "bar", "pinch": "bar", "wrap": "knob"}


class GraspGeometry:
    """Grasp choice of :class:`~opend_mj.policy.planner.Planner` (uses its ``config.grasp``,
    ``spec``, ``hand``, ``grasp`` (the hand's grasp profile) and ``state``)."""

    def closed_profile(self, orientation: str) -> np.ndarray:
        """Finger targets when closed: ``close_scale`` of the way from the pre-grasp to the spec's grasp."""
        pre = self.spec.pregrasp_profile(orientation)
        closed = self.spec.grasp_profile(orientation)
        return pre + self.config.grasp.close_scale * (closed - pre)

    def choose_grasp(self, handle, shape, obs: Observation, result: PlanResult) -> GraspChoice:
        """Orientation from the handle and the instruction; style from the measured shape; the site
        at the handle (lifted, pitched or raised for a handle near the floor, per hand)."""
        cfg = self.config.grasp
        door = result.target_kind == "door"
        orientation = handle.orientation
        if handle.kind == "knob":
            orientation = self.grasp.knob_orientation if self.grasp is not None else "horizontal"
        quat = orientation_for_handle(orientation)
        neighbour_above = door and self._neighbour_above(shape)
        if orientation == "horizontal" and (handle.centre[2] < cfg.flip_below or neighbour_above):
            quat = quat_mul(quat, yaw_quat(math.pi))  # fingers down (site frame: rotate about +z)
        side = self.hinge_side(handle, obs) if door else None
        flip_doors = cfg.flip_right_doors and (orientation == "vertical" or not cfg.horizontal_doors_unflipped)
        if door and flip_doors and self.spec.hand_type != "parallel_gripper":
            # fingers toward the hinge: the door's pull presses the handle into the finger curl
            result.events.append({"hinge_side": side})
            if side == "right":
                quat = quat_mul(quat, yaw_quat(math.pi))
        self.state.hinge = self.hinge_from_depth(handle, side, obs, result) if door else None
        style = self.grasp_style(handle, shape)
        depth = float(cfg.depth.get(style, cfg.depth.get(STYLE_KIND[style], 0.0)))
        pos = handle.centre + np.array([depth, 0.0, 0.0])
        quat, pos = self._low_handle(handle, orientation, quat, pos, result)
        pre = self.spec.pregrasp_profile(orientation)
        closed = self.closed_profile(orientation)
        if self.spec.hand_type == "parallel_gripper":
            pre = self.gripper_opening(pre, orientation, shape, result)
        grasp = GraspChoice(style, orientation, quat, pos, pre, closed)
        self.state.first_pos = pos.copy()
        result.events.append({"grasp": grasp.to_dict()})
        return grasp

    def _low_handle(self, handle, orientation: str, quat, pos, result: PlanResult):
        """The hand's own way with a handle near the floor (``hands/<name>/planner.json``): pitch the
        approach down (a horizontal bar), lift the site, keep the site above the hand's lowest."""
        hand = self.hand
        low = handle.centre[2] < self.config.grasp.low_handle_height
        pitch = float(hand.low_handle_pitch)
        if pitch and low and orientation == "horizontal":
            quat = quat_mul(axis_angle_quat((0.0, 1.0, 0.0), math.radians(pitch)), quat)
            result.events.append({"low_handle_pitch": pitch})
        lift = float(hand.low_handle_lift)
        if lift > 0.0 and low:
            pos = pos + np.array([0.0, 0.0, lift])
            result.events.append({"low_handle_lift": lift})
        floor = hand.min_grasp_height
        if floor is not None and pos[2] < floor:
            result.events.append({"min_grasp_height": [round(float(pos[2]), 4), floor]})
            pos = np.array([pos[0], pos[1], float(floor)])
        return quat, pos

    def _neighbour_above(self, shape) -> bool:
        """A horizontal bar with something close above it (a neighbour's handle seen in depth) and
        more room below: the fingers point down, the hand's body stays clear of the neighbour."""
        cfg = self.config.grasp
        clear = shape.clear
        return clear["up"] < cfg.neighbour_clear and clear["down"] > clear["up"] + cfg.more_room_below

    def gripper_opening(self, pre: np.ndarray, orientation: str, shape, result: PlanResult) -> np.ndarray:
        """A parallel gripper opens no wider than the free space beside the handle allows (a
        neighbouring handle of a double door 5-8 cm away), and never narrower than the bar."""
        cfg = self.config.grasp
        sides = ("up", "down") if orientation == "horizontal" else ("left", "right")
        room = min(shape.clear[k] for k in sides) + shape.thickness / 2
        opening = room - cfg.gripper_finger_width - cfg.neighbour_margin
        opening = max(opening, shape.thickness / 2 + cfg.gripper_min_clearance)
        if opening < float(np.max(pre)):
            result.events.append({"gripper_opening": round(opening, 4)})
        return np.minimum(pre, opening)

    def hinge_side(self, handle, obs: Observation) -> str | None:
        """The side a door hinges on ("left" = +y, "right" = -y): named by the instruction (double
        doors), else inferred from the depth image where ``infer_hinge`` (a single door's handle
        sits near its free edge), else None."""
        side = hinge_side(obs.instruction)
        if side is None and self.config.grasp.infer_hinge:
            side = infer_hinge_side(handle, obs.depth, obs.camera_view, self.config.perception)
        return side

    def hinge_from_depth(self, handle, side: str | None, obs: Observation, result: PlanResult):
        """The door's hinge line (world x, y) from the depth image: on the hinge ``side``, where the
        door's front plane ends, at the panel's depth; None where unknown or too near the handle."""
        edges = door_edges(handle, obs.depth, obs.camera_view, self.config.perception)
        if side is None or edges is None:
            return None
        y = edges[0] if side == "left" else edges[1]
        if abs(y - handle.centre[1]) < self.config.grasp.min_hinge_distance:
            return None
        point = np.array([handle.panel_x, y])
        result.events.append({"hinge_from_depth": [round(float(v), 3) for v in point]})
        return point

    def grasp_style(self, handle, shape) -> str:
        """``wrap`` round a knob; ``hook`` behind a bar where the stand-off gap lets the fingers
        through; ``pinch`` across a bar too close to its panel (or a flat pull)."""
        if handle.kind == "knob":
            return "wrap"
        if shape.gap < self.hand.pinch_gap:
            return "pinch"
        return "hook"

    def next_grasp(self, g: GraspChoice, handle, shape, state: PullState, result: PlanResult) -> GraspChoice:
        """The next try: where the grip last held (the handle moved with the part), a little deeper;
        else at the handle again, nearer then farther than the first try."""
        cfg = self.config.recovery
        deeper = cfg.regrasp_deeper * (g.attempt + 1)
        if state.last_held is not None:  # the handle slid out toward the fingertips: go deeper there
            pos, quat = state.last_held
            quat = np.asarray(quat, float)
            new = GraspChoice(g.style, g.orientation, quat, np.asarray(pos, float) + deeper * quat_axis_z(quat),
                              g.pre, g.closed, g.attempt + 1)
        else:  # nothing held yet: the bar may be nearer or farther than seen; try nearer, then farther
            steps = cfg.regrasp_offsets
            shift = steps[min(g.attempt, len(steps) - 1)]
            new = GraspChoice(g.style, g.orientation, g.quat, self.state.first_pos + shift * g.axis, g.pre,
                              g.closed, g.attempt + 1)
        result.events.append({"regrasp": new.to_dict()})
        return new
