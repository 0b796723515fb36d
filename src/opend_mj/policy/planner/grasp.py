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
from opend_mj.policy.planner.clearance import clearances, outline_for
from opend_mj.policy.planner.records import (
    GraspChoice,
    Observation,
    PlanResult,
    PullState,
)
from opend_mj.policy.planner.stage import Stage
from opend_mj.sim.hands import orientation_for_handle
from opend_mj.transforms import (
    axis_angle_quat,
    quat_axis_z,
    quat_mul,
    quat_to_mat,
    yaw_quat,
)


class _Events:
    """Where a pose's events go: a PlanResult's list, or a list that is dropped."""

    def __init__(self, events: list):
        self.events = events


#: the grasp-depth key of each style (``GraspConfig.depth[style]`` wins where it has one)
STYLE_KIND = {"hook": "bar", "pinch": "bar", "wrap": "knob", "hook_down": "bar", "press_down": "bar"}
#: styles that come down on a low bar from above (:meth:`Grasping.hook_down_pose`)
FROM_ABOVE = ("hook_down", "press_down")


class Grasping(Stage):
    """The grasp choice: where and how the hand grasps the located handle, and where it grasps again
    after a lost grip (``config.grasp``, ``config.recovery``; the hand's numbers). Keeps the hinge
    seen in depth and the first grasp's site in the episode's state."""

    def closed_profile(self, orientation: str) -> np.ndarray:
        """Finger targets when closed: ``close_scale`` of the way from the pre-grasp to the spec's grasp."""
        pre = self.spec.pregrasp_profile(orientation)
        closed = self.spec.grasp_profile(orientation)
        return pre + self.config.grasp.close_scale * (closed - pre)

    def choose_grasp(self, handle, shape, obs: Observation, result: PlanResult) -> GraspChoice:
        """Orientation from the handle and the instruction; style from the measured shape; the site
        at the handle (lifted, pitched or raised for a handle near the floor, per hand). A knob
        whose pose would put the open hand into the floor or the door is taken with the hand
        turned a quarter about the approach axis where that pose has more room (:meth:`clears`)."""
        cfg = self.config.grasp
        door = result.target_kind == "door"
        orientation = handle.orientation
        if handle.kind == "knob":
            orientation = self.config.grasp.knob_orientation
        side = self.hinge_side(handle, obs) if door else None
        self.episode.hinge = self.hinge_from_depth(handle, side, obs, result) if door else None
        style = self.grasp_style(handle, shape)
        depth = float(cfg.depth.get(style, cfg.depth.get(STYLE_KIND[style], 0.0)))
        centre = handle.centre + np.array([depth, 0.0, 0.0])
        quat, pos, pre, level = self._pose(orientation, handle, shape, door, side, centre, result.events)
        clear = self.clears(handle, shape, quat, pos, pre)
        if clear is not None and not clear[0] and handle.kind == "knob" and self.hand.clearance_knob_turn:
            other = "vertical" if orientation == "horizontal" else "horizontal"
            q, p, f, lv = self._pose(other, handle, shape, door, side, centre, [])
            # the fingers either way round (a knob has no side to favour); the first on a tie
            options = [(q, p, f, lv), (quat_mul(q, yaw_quat(math.pi)), p, f, quat_mul(lv, yaw_quat(math.pi)))]
            rooms = [self.clears(handle, shape, *o[:3]) for o in options]
            best = max(range(2), key=lambda i: (min(rooms[i][1:]), -i))
            if min(rooms[best][1:]) > min(clear[1:]):  # a knob is round: turned a quarter, it holds it as well
                result.events.append({"knob_turned": [other, *clear[1:], *rooms[best][1:]]})
                orientation, (quat, pos, pre, level), clear = other, options[best], rooms[best]
        probe, press = None, 0.0
        if clear is not None and not clear[0] and orientation == "horizontal":
            quat, pre, cleared = self.clear_pose(handle, shape, level, quat, pos, pre, result)
            # from above only where the floor is in the way (a bar higher up whose fingers only
            # touch the panel behind it is grasped level: they stop on the panel)
            near_floor = clear[1] < self.hand.clearance_margin - self.hand.floor_give
            down = self.hook_down_pose(handle, shape, result) if handle.kind == "bar" and near_floor and not cleared else None
            if down is not None:
                (quat, pos, pre, on_top), press = down, self.hand.press_depth
                style = "press_down" if on_top else "hook_down"
                probe = np.array([-1.0, 0.0, 0.0])  # out of the panel: the hook pulls the bar's back
        if style == "hook" and door and self.hand.hook_slide:
            # a door's bar at the fingers' middle segments, where their curl closes behind it (at the
            # proximal ones the tips curl past a thin bar onto the panel, and the bar slips out as the
            # door turns; a drawer's straight pull holds a bar anywhere in the curl); a site already
            # moved back along the fingers (a low handle's lift) moves only the rest of the way
            fingers = quat_to_mat(quat)[:, 1]
            along = float((pos - centre) @ fingers)
            slide = max(0.0, along + self.hand.hook_slide)
            side = self._side_toward(-fingers)
            if side in ("left", "right") and shape.clear[side] < cfg.neighbour_clear:
                # not toward a neighbour beside a vertical bar (a double door's other handle 5-8 cm
                # away): the hand would push that door
                result.events.append({"hook_slide_blocked": [side, shape.clear[side]]})
                slide = 0.0
            if slide > 0.0:
                pos = pos - slide * fingers
                result.events.append({"hook_slide": round(slide, 4)})
        closed = pre if style in FROM_ABOVE else self.closed_profile(orientation)
        grasp = GraspChoice(style, orientation, quat, pos, pre, closed, probe=probe, press=press)
        self.episode.first_pos = pos.copy()
        result.events.append({"grasp": grasp.to_dict()})
        return grasp

    @staticmethod
    def _side_toward(direction) -> str:
        """The side of the handle ("left" = +y, "right" = -y, "up", "down") a world direction mostly
        points to (the sides of the handle's measured ``clear`` space)."""
        d = np.asarray(direction, float)
        if abs(d[1]) >= abs(d[2]):
            return "left" if d[1] > 0 else "right"
        return "up" if d[2] > 0 else "down"

    def _pose(self, orientation: str, handle, shape, door: bool, side, centre, events: list):
        """The grasp-site orientation and position and the open fingers for a handle grasped in
        ``orientation``, and the orientation before a low handle's pitch; the choices logged to
        ``events``."""
        cfg = self.config.grasp
        quat = orientation_for_handle(orientation)
        neighbour_above = door and self._neighbour_above(shape)
        if orientation == "horizontal" and (handle.centre[2] < cfg.flip_below or neighbour_above):
            quat = quat_mul(quat, yaw_quat(math.pi))  # fingers down (site frame: rotate about +z)
        flip_doors = cfg.flip_right_doors and (orientation == "vertical" or not cfg.horizontal_doors_unflipped)
        if door and flip_doors and self.spec.hand_type != "parallel_gripper":
            # fingers toward the hinge: the door's pull presses the handle into the finger curl
            events.append({"hinge_side": side})
            if side == "right":
                quat = quat_mul(quat, yaw_quat(math.pi))
        level = quat
        sink = _Events(events)
        quat, pos = self._low_handle(handle, orientation, quat, centre, sink)
        pre = self.spec.pregrasp_profile(orientation)
        if self.spec.hand_type == "parallel_gripper":
            pre = self.gripper_opening(pre, orientation, shape, sink)
        return quat, pos, pre, level

    def clears(self, handle, shape, quat, pos, pre):
        """(whether the open hand at this pose keeps ``clearance_margin`` from the floor and from the
        panel behind the handle, floor clearance (m), panel clearance (m)); None where the hand does
        not check (``clearance_margin`` null in its ``planner.json``)."""
        margin = self.hand.clearance_margin
        if margin is None:
            return None
        panel_x = float(handle.front_x + shape.protrusion)
        floor, door = clearances(outline_for(self.spec, pre), pos, quat, panel_x)
        return min(floor, door) >= margin, round(floor, 4), round(door, 4)

    def clear_pose(self, handle, shape, level, quat, pos, pre, result: PlanResult):
        """A horizontal handle whose pose does not clear the floor and the panel: the first of the
        hand's ``clearance_pitches`` (deg, from the level pose ``level``) at which it does, a
        gripper's fingers opened no wider than they must (down to the bar's half thickness plus
        ``clearance_bar_margin``); else the pose unchanged (event ``no_clear_pose``). The third value
        says whether a pitch cleared."""
        hand = self.hand
        gripper = self.spec.hand_type == "parallel_gripper"
        narrowest = shape.thickness / 2 + hand.clearance_bar_margin
        for pitch in hand.clearance_pitches:
            q = quat_mul(axis_angle_quat((0.0, 1.0, 0.0), math.radians(pitch)), level)
            widths = np.arange(float(np.max(pre)), narrowest - 1e-9, -0.002) if gripper else [None]
            for width in widths:  # a gripper: from its chosen opening down, 2 mm at a time
                fingers = pre if width is None else np.minimum(pre, width)
                clear = self.clears(handle, shape, q, pos, fingers)
                if clear[0]:
                    result.events.append({"clearance_pitch": [pitch, *clear[1:]]})
                    return q, fingers, True
        result.events.append({"no_clear_pose": list(self.clears(handle, shape, quat, pos, pre)[1:])})
        return quat, pre, False

    def hook_down_pose(self, handle, shape, result: PlanResult):
        """(site orientation, position, finger targets, on the bar's top) of a hook from above into the stand-off
        gap behind a horizontal bar (``hook_down_pitches`` in the hand's ``planner.json``): the
        fingers closed (one hook, the closing axis along the bar) and pointing down, the site
        ``hook_down_depth`` below the bar's centre. A bar seen from the front may be deeper than
        it is tall (the gap is measured as if it were square), so the fingers go as near the panel
        as the hand allows: ``hook_down_margin`` in front of it, the hand's body (above the bar)
        not into it, ``clearance_margin`` above the floor; of the pitches at which the closed
        fingers fit the measured gap, the one that puts their front farthest behind the bar's
        front. None where none fits (event ``hook_down``).

        Where the gap takes no fingers and the hand has a ``press_depth``, the same pose comes down
        on the bar's top instead ("press_down": the closed fingers pressed on it; checked against
        the floor and the panel where the hand's lowest point meets the bar's top; the last value
        returned says so)."""
        hand = self.hand
        if not hand.hook_down_pitches or hand.hook_down_width <= 0.0:
            return None
        panel_x = float(handle.front_x + shape.protrusion)
        fingers = self.spec.grasp_profile("vertical")
        outline = outline_for(self.spec, fingers)
        along_bar = orientation_for_handle("vertical")  # the closing axis along world y
        z = handle.centre[2] - hand.hook_down_depth
        bar_top = float(handle.centre[2] + shape.thickness / 2)
        best, tried = None, []
        for pitch in hand.hook_down_pitches:
            across = hand.hook_down_width / max(1e-6, math.sin(math.radians(pitch)))  # at one height (m)
            press = shape.gap < across + 2 * hand.hook_down_margin
            if press and hand.press_depth <= 0.0:
                tried.append([pitch, "gap"])
                continue
            quat = quat_mul(axis_angle_quat((0.0, 1.0, 0.0), math.radians(pitch)), along_bar)
            x = panel_x - across / 2 - hand.hook_down_margin  # the fingers' back at the margin
            _, door = clearances(outline, np.array([x, handle.centre[1], z]), quat, panel_x)
            x_bar = panel_x - shape.gap + across / 2 + hand.hook_down_margin  # the fingers against the bar
            x = x + min(0.0, door) if press else max(x_bar, x + min(0.0, door))  # linear in x
            floor, door = clearances(outline, np.array([x, handle.centre[1], z]), quat, panel_x)
            if press:  # the hand stops where its lowest point meets the bar's top: checked there
                floor, door = clearances(outline, np.array([x, handle.centre[1], z + bar_top - floor]), quat, panel_x)
            tried.append([pitch, round(floor, 4), round(door, 4)] + (["press"] if press else []))
            if floor < (hand.clearance_margin or 0.0) or door < -1e-6:
                continue
            behind = x - across / 2  # the fingers' front, world x
            # a hook behind the bar first; else the press whose fingers reach farthest back
            key = (not press, behind)
            if best is None or key[0] > best[0][0] or (key[0] == best[0][0] and behind > best[0][1] + 1e-6):
                best = (key, pitch, quat, np.array([x, handle.centre[1], z]))
        if best is None:
            result.events.append({"hook_down": None, "tried": tried})
            return None
        on_top = not best[0][0]
        result.events.append({"hook_down": [best[1], round(best[0][1] - (panel_x - shape.gap), 4)],
                              "on_top": on_top, "tried": tried})
        return best[2], best[3], fingers, on_top

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
        else at the handle again, nearer then farther than the first try. A panel slid along its
        front: at the depth the handle was seen; where the grasp that just failed had a dexterous hand's
        fingers pointing along the slide, the hand turned half a turn (:meth:`_turned_for_slide`).
        A try after a turned one that fails again goes where the grip last held, as it held."""
        cfg = self.config.recovery
        deeper = cfg.regrasp_deeper * (g.attempt + 1)
        turn = state.slides is not None and g.style not in FROM_ABOVE and self._fingers_along(g, state.direction)
        if g.style in FROM_ABOVE:  # from above again at the planned height (deeper is the floor): where
            # the bar was last held (a part that came out part way); a hook that never held found no
            # gap behind the bar (a solid profile seen as a bar): the fingers press on its top instead
            pos = self.episode.first_pos.copy()
            style = g.style
            if state.last_held is not None:
                pos[:2] = np.asarray(state.last_held[0], float)[:2]
                if state.slides is not None:  # a panel that did not come out: its bar is as deep as seen
                    pos[0] = self.episode.first_pos[0]
            elif g.press:
                style = "press_down"
            new = GraspChoice(style, g.orientation, g.quat, pos, g.pre, g.closed,
                              g.attempt + 1, probe=g.probe, press=g.press)
        elif state.last_held is not None:  # the handle slid out toward the fingertips: go deeper there
            pos, quat = np.asarray(state.last_held[0], float), np.asarray(state.last_held[1], float)
            axis = quat_axis_z(quat)
            if state.slides is not None:
                # a panel that did not come out: its handle is as deep as it was seen (the touch last
                # felt may be a hand sliding off it, cm out), across the approach where it was last
                # held (a panel drawn a little along its front)
                pos = pos + float((self.episode.first_pos - pos) @ axis) * axis
            new = GraspChoice(g.style, g.orientation, quat, pos + deeper * axis, g.pre, g.closed, g.attempt + 1)
        else:  # nothing held yet: the bar may be nearer or farther than seen; try nearer, then farther
            steps = cfg.regrasp_offsets
            shift = steps[min(g.attempt, len(steps) - 1)]
            new = GraspChoice(g.style, g.orientation, g.quat, self.episode.first_pos + shift * g.axis, g.pre,
                              g.closed, g.attempt + 1)
        if turn:
            new = self._turned_for_slide(new, state.direction, result)
        result.events.append({"regrasp": new.to_dict()})
        return new

    def _fingers_along(self, g: GraspChoice, direction) -> bool:
        """Whether a dexterous hand's fingers point along ``direction`` (world unit vector; within 60
        degrees)."""
        fingers = quat_to_mat(g.quat)[:, 1]
        return self.spec.hand_type != "parallel_gripper" and float(fingers @ np.asarray(direction, float)) > 0.5

    def _turned_for_slide(self, g: GraspChoice, direction, result: PlanResult) -> GraspChoice:
        """A panel slid along its front is pushed by the curled fingers: the hook round a bar is
        closed on the fingers' side (their middle segments) and open on the palm's, so the hand
        turns half a turn about its approach axis and its fingers point against the slide
        ``direction``; a hooked bar then lies in the fingers' curl (``hook_slide``, as on a door)."""
        fingers = quat_to_mat(g.quat)[:, 1]
        quat = quat_mul(g.quat, yaw_quat(math.pi))
        pos = g.pos
        if g.style == "hook" and self.hand.hook_slide:
            pos = pos + self.hand.hook_slide * fingers  # back along the turned fingers (-fingers)
        result.events.append({"slide_fingers_turned": [round(float(v), 3) for v in direction]})
        return GraspChoice(g.style, g.orientation, quat, pos, g.pre, g.closed, g.attempt, probe=g.probe,
                           press=g.press)
