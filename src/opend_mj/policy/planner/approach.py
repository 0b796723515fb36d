"""Approach, close and verify: the open hand to the pre-grasp and in, the fingers closed, and a
short pull back that tells from touch whether the hand holds the handle; backing off again."""

from __future__ import annotations

import math

import numpy as np

from opend_mj.policy.planner.moves import hold, kept_down, move, pressed
from opend_mj.policy.planner.records import GraspChoice, PlanResult
from opend_mj.policy.planner.stage import Stage
from opend_mj.transforms import quat_axis_z


class Approach(Stage):
    """The approach and the grasp's close: the open hand in to the grasp chosen by
    :class:`~opend_mj.policy.planner.grasp.Grasping`, the fingers closed and the hold checked by
    touch (``config.approach``, ``config.grasp``, ``config.verify``; the hand's ``hold_parts``), and
    the hand backed off again (``config.recovery``)."""

    def holding(self, robot) -> tuple[bool, dict]:
        """Whether the hand holds something, from touch: at least the hand's ``hold_parts`` parts
        (not those in ``load_excludes``: the palm) press on something other than the hand."""
        cfg = self.config.verify
        touch = robot.contact_touch()
        parts = [k for k, v in touch.items() if v > cfg.touch_min and k not in cfg.load_excludes]
        return len(parts) >= self.hand.hold_parts, touch

    def holds(self, robot, g: GraspChoice, reach: float = 0.03) -> bool:
        """Whether the hand holds the handle as ``g`` would: its fingers at least half way from
        ``g``'s open pose to its closed one (a hand that only leans on the handle, fingers open, does
        not), and touch says it holds (:meth:`holding`) or the grasp site is within ``reach`` (m) of
        ``g``'s (contacts on a held bar come and go from step to step)."""
        near = float(np.linalg.norm(robot.site_pos() - g.pos)) <= reach
        if not (near or self.holding(robot)[0]):
            return False
        span = np.asarray(g.closed, float) - np.asarray(g.pre, float)
        moving = np.abs(span) > 1e-3
        if not moving.any():
            return True
        share = (np.asarray(robot.finger_qpos(), float) - g.pre)[moving] / span[moving]
        return float(np.mean(share)) >= 0.5

    def approach(self, robot, g: GraspChoice, result: PlanResult, first: bool = True, from_here: bool = False) -> float:
        """Open hand to the pre-grasp in front of the handle (along the approach axis), then in;
        returns how far (m) the site ended from its target. ``from_here``: an episode taken over
        mid-way: no wait before the move, and a hand nearer the cabinet than the pre-grasp first
        backs straight out to it (it may be in front of the handle, or on it with its fingers open)."""
        cfg = self.config.approach
        target = g.pos.copy()
        if first and cfg.first_grasp_offset is not None:  # a deliberate miss (tests)
            target = target + np.asarray(cfg.first_grasp_offset, float)
        axis = g.axis
        pre_pos = target - cfg.pregrasp_distance * axis
        self.ctx.enter(result, "approach", site_target=target.tolist(), attempt=g.attempt, style=g.style)
        site0, _ = robot.site_pose()
        if from_here:
            ahead = float((site0 - pre_pos) @ axis)
            if ahead > 0.0:
                out = site0 - ahead * axis
                move(robot, site0, out, g.quat, g.pre, cfg.move_speed)
                site0 = out
        else:
            hold(robot, site0, g.quat, g.pre, cfg.first_wait if first else cfg.again_wait)
        if first:  # move at the start depth, then to the pre-grasp
            waypoint = np.array([min(site0[0], pre_pos[0]), pre_pos[1], pre_pos[2]])
            move(robot, site0, waypoint, g.quat, g.pre, cfg.move_speed)
            move(robot, waypoint, pre_pos, g.quat, g.pre, cfg.move_speed)
        else:
            move(robot, site0, pre_pos, g.quat, g.pre, cfg.move_speed)
        hold(robot, pre_pos, g.quat, g.pre, cfg.pregrasp_wait)
        move(robot, pre_pos, target, g.quat, g.pre, cfg.approach_speed, press=g.on_top_press)
        hold(robot, target, g.quat, g.pre, cfg.grasp_wait, press=g.on_top_press)
        err = float(np.linalg.norm(robot.site_pos() - target))
        if err > cfg.blocked_error:  # blocked on the way in (the hand's own state says so)
            result.events.append({"approach_error": round(err, 4)})
        self.episode.approach_target = target
        return err

    def close_and_verify(self, robot, g: GraspChoice, result: PlanResult) -> bool:
        """Close the fingers, then pull a little: a held handle pushes back on the fingers (the touch
        sensors' load rises); a hand that closed on air or on the panel feels nothing more."""
        cfg = self.config.verify
        self.ctx.enter(result, "grasp", attempt=g.attempt)
        target = self.episode.approach_target
        grasp = self.config.grasp
        close_time = grasp.close_time if grasp.close_time is not None else self.spec.close_time
        n = max(1, int(round(close_time / robot.control_dt)))
        for i in range(1, n + 1):
            robot.step(pressed(robot, target, g.on_top_press), g.quat, g.pre + (g.closed - g.pre) * i / n)
        hold(robot, target, g.quat, g.closed, grasp.settle_time, press=g.on_top_press)
        if not cfg.verify_grasp:
            return True
        # pull back up to ``probe_distance``: a bar loose in a curled hand engages within a few cm
        start = robot.site_pos()
        n = max(1, int(math.ceil(cfg.probe_distance / (cfg.probe_speed * robot.control_dt))))
        back = -g.axis if g.probe is None else np.asarray(g.probe, float)
        # contacts on a held bar come and go from step to step: judge over a window of steps
        window = max(1, int(round(cfg.touch_window / robot.control_dt)))
        recent: list[bool] = []
        touch: dict = {}
        held = False
        for i in range(1, n + 1):
            step = start + back * cfg.probe_distance * i / n
            if g.press:  # a hook from above stays down on the bar (the pull does the same)
                step = kept_down(robot, step, g.press, float(g.pos[2]))
            robot.step(step, g.quat, g.closed)
            if cfg.probe_distance * i / n >= cfg.probe_min:
                now, t = self.holding(robot)
                touch = t if now or not touch else touch
                recent = (recent + [now])[-window:]
                if sum(recent) >= cfg.touch_hits:
                    held = True
                    break
        if not held:
            held = sum(recent) >= 1
        self.episode.felt |= held or any(v >= cfg.touch_min for v in touch.values())
        result.events.append({"verify": {"attempt": g.attempt, "held": held,
                                         "touch": {k: round(v, 1) for k, v in touch.items() if v > 0.1}}})
        return held

    def back_off(self, robot, g: GraspChoice) -> None:
        """Open the fingers and move back ``backoff_distance`` along the approach axis, at twice the
        approach speed."""
        cfg = self.config.recovery
        site, squat = robot.site_pose()
        pre = g.pre
        hold(robot, site, squat, pre, cfg.open_time)
        move(robot, site, site - cfg.backoff_distance * quat_axis_z(squat), squat, pre,
             self.config.approach.approach_speed * 2)
