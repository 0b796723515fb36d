"""The pull: drawers straight back along -x, doors along their handle's circle.

Each control step the target is placed along the pull direction, never more than ``lead`` ahead
of where the grasp site actually is, and the lateral error is dropped, so that the handle leads
and the hand follows it compliantly. A drawer moves straight and its direction stays -x. A door's
handle moves on a circle: about the hinge seen in depth where there is one (the pull direction is
the circle's opening tangent at the site), else along the site's observed motion (low-pass
filtered, never back into the cabinet, never turning back once the door turned). The hand's yaw
turns with the direction so that the grip does not twist.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from opend_mj.policy.planner.moves import kept_down, yawed
from opend_mj.policy.planner.records import GraspChoice, PlanResult, PullState, StageOutcome
from opend_mj.policy.planner.stage import Stage, StageContext

#: Seconds a pull may last beyond the time its remaining travel needs at the pull speed.
PULL_SLACK_TIME = 3.0


def _ended(result: PlanResult, state: PullState, outcome: StageOutcome, why: str | StageOutcome) -> StageOutcome:
    """Record why a pull ended (``{"pull_end": why, ...}``: "stall", "travel", "back_stop", "time",
    "steps", or the outcome's word: "slipped", "stuck", "wrong_kind") with its travel (m) and turn
    (deg); returns ``outcome``."""
    why = why.value if isinstance(why, StageOutcome) else why
    result.events.append({"pull_end": why, "travelled": round(state.travelled, 4), "turned": round(state.turned, 1),
                          "tilt": round(state.peak_tilt, 1)})
    return outcome


@dataclass
class PullRun:
    """The running state of one pull (one grasp's), beside the :class:`PullState` kept across
    re-grasps."""

    door: bool
    start: np.ndarray  # site position when the pull began (m)
    target: np.ndarray  # the site target (m)
    quat: np.ndarray  # the site orientation target
    grip: np.ndarray  # finger joints as they closed on the handle
    start_travel: float  # state.travelled when the pull began (m)
    history: list = field(default_factory=list)  # site positions, one per control step
    quiet: int = 0  # control steps since the hand last touched anything
    last_touch: np.ndarray | None = None  # site position when the hand last touched
    held_path: float = 0.0  # length (m) of the held path so far (the kind is judged once long enough)
    watch_kind: bool = True  # the kind is judged once per pull
    least_x: float = 0.0  # the site's smallest x so far (m)
    front_moved: bool = False  # a drawer's front was seen moving out during this pull
    yaw_turn: float | None = None  # the turn (deg) the hand's yaw is at, where its rate is bounded


class Pulling(Stage):
    """The pull (``config.pulling``, ``config.door``; the hand's ``grip_lost_change`` and
    ``yaw_rate``), with its variants: a flap's circle (``flap``) and a panel slid along its front
    (``slide``). Reads the grip through ``approach``
    (:meth:`~opend_mj.policy.planner.approach.Approach.holding`), judges the held handle's kind
    through ``kind``, looks again through ``front``."""

    def __init__(self, ctx: StageContext, approach, kind, front, flap, slide):
        super().__init__(ctx)
        self.approach = approach
        self.kind = kind
        self.front = front
        self.flap = flap
        self.slide = slide

    def pull(self, robot, g: GraspChoice, door: bool, state: PullState, result: PlanResult) -> StageOutcome:
        """Pull until the part is open or stalls (``DONE``), or the grip is lost (``SLIPPED``: the
        hand touched nothing for ``slip_time`` and moved ``slip_distance`` since it last did), or
        the held handle showed the other kind than the instruction's (``WRONG_KIND``), or a
        drawer's handle did not come along this direction (it stalled, or the hand came off it,
        within ``drawer_stuck_travel``: ``STUCK``)."""
        cfg = self.config.pulling
        self.ctx.enter(result, "pull", attempt=g.attempt)
        dt = robot.control_dt
        start = robot.site_pos()
        run = PullRun(door=door, start=start, target=start.copy(), quat=g.quat, grip=robot.finger_qpos(),
                      start_travel=state.travelled, history=[start.copy()], least_x=float(start[0]))
        travel_max = cfg.door_travel if door else cfg.drawer_travel
        stall_n = max(2, int(round(cfg.stall_time / dt)))
        max_steps = int(round((max(0.0, travel_max - state.travelled) / cfg.speed + PULL_SLACK_TIME) / dt))
        state.pull_start = len(state.track)
        if door:
            self._start_hinge_pull(state, start, result)
        for k in range(max_steps):
            if self.ctx.time_left(robot) <= 0.0:
                return _ended(result, state, StageOutcome.DONE, "time")
            site = robot.site_pos()
            lost = self._grip_check(robot, site, run, state, result)
            if lost is not None:
                return _ended(result, state, lost, lost)
            run.history.append(site.copy())
            if door:
                self._steer_door(robot, site, run, state, result)
            self._advance(robot, site, run, g, state, dt)
            why = self._pull_finished(robot, k, run, state, result, travel_max, stall_n)
            if why == "stall" and not door and cfg.drawer_slide and self._did_not_come(robot, run, state, site):
                return _ended(result, state, StageOutcome.STUCK, StageOutcome.STUCK)
            if why is not None:
                return _ended(result, state, StageOutcome.DONE, why)
        return _ended(result, state, StageOutcome.DONE, "steps")

    def _did_not_come(self, robot, run: PullRun, state: PullState, site) -> bool:
        """Whether a drawer did not come out with the hand along this direction (it slides another
        way, or not at all): the hand held it less than ``slip_distance`` (m) along the pull, and
        its front, seen again, did not move (``front.seen`` is None: too few pixels came 2 cm
        or more toward the camera; looked at once per pull, and a front seen moving is kept). A
        robot that cannot look again: the handle came out less than ``drawer_stuck_travel`` (m)
        while held."""
        cfg = self.config.pulling
        held_to = run.last_touch if run.last_touch is not None else site
        held = float((held_to - run.start) @ state.direction)
        if getattr(robot, "look", None) is None:
            return held < cfg.drawer_stuck_travel
        if held >= cfg.slip_distance or run.front_moved:
            return False
        run.front_moved = self.front.seen(robot, site) is not None
        return not run.front_moved

    # ---------------------------------------------------------------- one control step
    def _grip_check(self, robot, site, run: PullRun, state: PullState, result: PlanResult) -> StageOutcome | None:
        """``SLIPPED`` where the grip is lost (the fingers forced open, or no touch for a while and
        the hand moved away), ``STUCK`` where the hand came off a drawer that did not come with it,
        ``WRONG_KIND`` where the held path shows the other kind, else None; records the held track."""
        cfg = self.config
        tolerance = self.hand.grip_lost_change
        if tolerance is not None and float(np.max(np.abs(robot.finger_qpos() - run.grip))) > tolerance:
            # the handle forced the fingers open: the grip is lost
            result.events.append({"grip_lost_at": round(state.travelled, 4)})
            return StageOutcome.SLIPPED
        if not cfg.verify.verify_grasp:
            return None
        held, touch = self.approach.holding(robot)
        touching = held or any(v > cfg.verify.touch_min for v in touch.values())
        run.quiet = run.quiet + 1 if not touching else 0
        if touching or run.last_touch is None:
            run.last_touch = site.copy()
        away = float(np.linalg.norm(site - run.last_touch))
        slip_n = max(2, int(round(cfg.pulling.slip_time / robot.control_dt)))
        if run.quiet >= slip_n and away >= cfg.pulling.slip_distance:
            if run.door or cfg.pulling.drawer_slips:
                result.events.append({"slipped_at": round(state.travelled, 4), "turned": round(state.turned, 1)})
                return StageOutcome.SLIPPED
            if cfg.pulling.drawer_slide and self._did_not_come(robot, run, state, site):
                return StageOutcome.STUCK  # the hand came off a drawer that did not come with it
        if held:
            state.last_held = (site.copy(), run.quat.copy())
            if len(state.track) > state.pull_start:
                run.held_path += float(np.linalg.norm(site - state.track[-1]))
            state.track.append(site.copy())
            if run.watch_kind and run.held_path >= cfg.kind.check_distance - 1e-9:
                verdict = self.kind.judge_kind(robot, site, state, result)
                if verdict is not None:
                    run.watch_kind = False
                    if verdict:
                        return StageOutcome.WRONG_KIND
        return None

    def _steer_door(self, robot, site, run: PullRun, state: PullState, result: PlanResult) -> None:
        """A door's pull direction and the hand's yaw: from the observed motion (no hinge), or the
        circle about the hinge seen in depth."""
        cfg = self.config.door
        if state.flap is None and cfg.flap_pull:
            state.flap = self.flap.seen(state, result) or self.flap.looked(robot, site, run, state, result)
        if state.flap is not None:
            self.flap.steer(site, run, state)
            return
        if state.hinge is not None and cfg.hinge_look_distances:
            self._hinge_looked(robot, site, run, state, result)
        if len(run.history) > cfg.direction_window:
            self._follow_motion(site, run, state, result)
        if state.hinge is not None:
            tangent, ang = self._hinge_tangent(state, site)
            if abs(ang) <= cfg.max_turn_deg:
                state.direction = tangent
                state.turned = ang
                state.opened = max(state.opened, abs(ang))
                run.quat = yawed(self.config.door, state, ang)
        self._yaw_rate_bounded(run, state, robot.control_dt)

    def _yaw_rate_bounded(self, run: PullRun, state: PullState, dt: float) -> None:
        """Turn the hand's yaw toward the pull direction's turn at most the hand's ``yaw_rate``
        (deg/s; None: at once). The pull direction itself still changes at once: a hinge replaced
        by the one the camera sees turns it by tens of degrees in one step, and a gripper whose
        pads hold a bar, yawed as fast, twists the bar out of them."""
        rate = self.hand.yaw_rate
        if rate is None:
            return
        yaw = state.turned if run.yaw_turn is None else run.yaw_turn
        step = rate * dt
        if yaw != state.turned:  # (run.quat may still hold the last step's bounded yaw)
            yaw = state.turned if abs(state.turned - yaw) <= step else yaw + math.copysign(step, state.turned - yaw)
            run.quat = yawed(self.config.door, state, yaw)
        run.yaw_turn = yaw

    def _follow_motion(self, site, run: PullRun, state: PullState, result: PlanResult) -> None:
        """Turn the pull direction toward the site's motion over the last ``direction_window``
        steps (low-passed, in the horizontal plane); drop a hinge that the motion contradicts."""
        cfg = self.config.door
        motion = run.history[-1] - run.history[-1 - cfg.direction_window]
        motion[2] = 0.0
        norm = float(np.linalg.norm(motion))
        if norm <= cfg.direction_min_motion:
            return
        new = state.direction + cfg.direction_gain * (motion / norm - state.direction)
        new[2] = 0.0
        cand = self._turn_bounded(state.direction, new / np.linalg.norm(new), run)
        if cand[0] > cfg.max_pull_toward_cabinet:  # never pull back into the cabinet
            cand[0] = cfg.max_pull_toward_cabinet
            lateral = math.sqrt(max(1e-9, 1 - cand[0] ** 2))
            cand[1] = math.copysign(lateral, cand[1] if abs(cand[1]) > 1e-9 else 1.0)
            cand = cand / np.linalg.norm(cand)
        base_dir = state.base_dir
        ang = math.degrees(math.atan2(base_dir[0] * cand[1] - base_dir[1] * cand[0], float(base_dir @ cand)))
        if state.hinge is not None and state.sense * ang < -cfg.hinge_disagree_deg / 4 \
                and float(np.linalg.norm(site - run.start)) > cfg.hinge_check_distance:
            # the handle turns the other way round: the hinge seen in depth is wrong
            result.events.append({"hinge_pull_dropped": round(ang, 1)})
            state.hinge = None
        back = state.hinge is None and self._turned_back(state, ang)
        if back and not state.held_back:
            state.held_back = True
            result.events.append({"door_turn_held": round(ang, 1), "from": round(state.peak_turn, 1)})
        if state.hinge is None and abs(ang) <= cfg.max_turn_deg and not back:
            state.direction = cand
            state.turned = ang
            state.peak_turn = ang if abs(ang) > abs(state.peak_turn) else state.peak_turn
            run.quat = yawed(self.config.door, state, ang)

    def _turn_bounded(self, direction: np.ndarray, cand: np.ndarray, run: PullRun) -> np.ndarray:
        """``cand`` (a horizontal unit vector) turned from ``direction`` by at most the angle a
        handle's circle of radius ``min_path_radius`` (m) turns over the site's last step: the step's
        horizontal length over the radius (rad). A door's handle moves on a circle at least that
        large; a motion that turns faster is the hand sliding or twisting on the handle (on a
        narrow door, followed, it turns the pull round past the door, which then slips out)."""
        r_min = self.config.door.min_path_radius
        if r_min is None or len(run.history) < 2:
            return cand
        step = run.history[-1] - run.history[-2]
        limit = float(np.hypot(step[0], step[1])) / r_min
        cross = float(direction[0] * cand[1] - direction[1] * cand[0])
        turn = math.atan2(cross, float(direction[0] * cand[0] + direction[1] * cand[1]))
        if abs(turn) <= limit:
            return cand
        a = math.copysign(limit, turn)
        c, s = math.cos(a), math.sin(a)
        return np.array([c * direction[0] - s * direction[1], s * direction[0] + c * direction[1], 0.0])

    def _advance(self, robot, site, run: PullRun, g: GraspChoice, state: PullState, dt: float) -> None:
        """Move the target along the pull direction (biased for doors), at most ``lead`` ahead of
        the site and without lateral error; one control step; count the travel."""
        cfg = self.config
        direction = state.direction
        pull_dir = direction
        if run.door and abs(state.turned) > cfg.door.bias_after_deg and cfg.door.pull_bias_deg:
            b = math.radians(math.copysign(cfg.door.pull_bias_deg, state.turned))
            c, sn = math.cos(b), math.sin(b)
            pull_dir = np.array([c * direction[0] - sn * direction[1], sn * direction[0] + c * direction[1], 0.0])
        target = run.target + pull_dir * cfg.pulling.speed * dt
        ahead = float((target - site) @ pull_dir)
        if ahead > cfg.pulling.lead:
            target = target - pull_dir * (ahead - cfg.pulling.lead)
        lateral = (target - site) - pull_dir * float((target - site) @ pull_dir)
        run.target = target - lateral
        if g.press and state.flap is not None:  # on a flap: pressed down its front, the bar's top
            # turning with it (a press straight down would hold the flap back as it lifts)
            run.target = run.target + g.press * self.flap.press_direction(site, state)
        elif g.press:  # a hook from above never rides up over the bar: at most ``press`` below the
            # site (fingers resting on a solid bar's top drag it by friction), not below the planned height
            run.target = kept_down(robot, run.target, g.press, float(g.pos[2]))
        robot.step(run.target, run.quat, g.closed)
        if run.door:
            state.travelled += float(np.linalg.norm(run.history[-1] - run.history[-2]))
        else:
            state.travelled = max(state.travelled, run.start_travel + float(np.linalg.norm(site - run.start)))

    def _pull_finished(self, robot, k: int, run: PullRun, state: PullState, result: PlanResult,
                       travel_max: float, stall_n: int) -> str | None:
        """Why the pull is finished: "travel" once the travel is done, "back_stop" once a door
        pulled without a hinge swings back toward the cabinet (at its stop), "stall" once the site
        stalls (the part at its stop); else None."""
        cfg = self.config
        if state.travelled >= travel_max:
            return "travel"
        site = run.history[-1]
        back_stop = cfg.door.back_stop is not None and state.flap is None \
            and (state.hinge is None or cfg.door.back_stop_with_hinge)
        if run.door and back_stop:
            run.least_x = min(run.least_x, float(site[0]))
            if float(site[0]) - run.least_x > cfg.door.back_stop:
                # the handle swings back toward the cabinet: the door is at its stop (or beyond
                # 90 degrees); pulling on would drag it shut
                result.events.append({"door_back_stop": round(state.turned, 1)})
                return "back_stop"
        if k > stall_n and float(np.linalg.norm(run.history[-1] - run.history[-1 - stall_n])) \
                < cfg.pulling.stall_distance:
            return "stall"
        return None

    # ---------------------------------------------------------------- the door's circle
    def _turned_back(self, state: PullState, ang: float) -> bool:
        """Whether a pull direction turned ``ang`` (deg) comes back ``turn_back_deg`` or more from
        a farthest turn of at least ``turn_back_after_deg`` (such a direction is not taken)."""
        cfg = self.config.door
        peak = state.peak_turn
        if cfg.turn_back_deg is None or abs(peak) < cfg.turn_back_after_deg:
            return False
        return math.copysign(1.0, peak) * (peak - ang) >= cfg.turn_back_deg

    def _start_hinge_pull(self, state: PullState, site: np.ndarray, result: PlanResult) -> None:
        """Pull a door along the circle about the hinge seen in depth (kept across re-grasps)."""
        cfg = self.config.door
        seen = self.episode.hinge
        if not cfg.hinge_pull or seen is None or state.sense != 0.0:
            return
        hinge = np.asarray(seen, float)
        r = site[:2] - hinge
        radius = float(np.linalg.norm(r))
        if not (cfg.hinge_radius_range[0] <= radius <= cfg.hinge_radius_range[1]):
            return
        if abs(r[1]) / radius < 0.5:  # the handle is not beside its hinge in the door's plane (> 60 deg off)
            return
        self.turn_about(state, hinge, r)
        result.events.append({"hinge_pull": {"hinge": [round(float(v), 3) for v in seen], "radius": round(radius, 3)}})

    def _hinge_looked(self, robot, site, run: PullRun, state: PullState, result: PlanResult) -> None:
        """Check the hinge the pull turns about against the front seen turning: once per pull state
        at each of ``hinge_look_distances`` (m) the site came out, a new depth image
        (``front.seen``); a front turned about a vertical axis (its shift toward the camera
        sloped at least ``KindConfig.front_door_slope`` across it, less than half that up it) is
        hinged where that shift falls to zero: ``shift / across`` (m) from the handle, away from the
        side that came out. A front seen farther out at the handle than the hand that pulls it came
        (by more than ``hinge_look_slack``, m; the front's shift at the handle's column times the
        cosine of its angle is the handle's own) is another part's. Where that line is more than
        ``RecoveryConfig.hinge_agreement`` (m) from the hinge seen in the first image (a front plane
        that runs on past the door's own edge, a hinge inferred on the wrong side), and the handle is
        ``seen_hinge_radius`` (m) from it, the pull turns about the seen line instead (the hand's yaw
        too). A hand that slides along a horizontal bar moves where it is pulled, so its path cannot
        tell a wrong hinge; the camera can."""
        cfg = self.config.door
        looks = cfg.hinge_look_distances
        if state.hinge_looked >= len(looks) or float(np.linalg.norm(site - run.start)) < looks[state.hinge_looked]:
            return
        state.hinge_looked += 1
        handle = self.episode.handle
        front = self.front.seen(robot, site) if handle is not None else None
        if front is None or abs(front["across"]) < self.config.kind.front_door_slope \
                or abs(front["up"]) > abs(front["across"]) / 2:
            return  # no front seen turned about a vertical axis
        # at the handle's column the front came out (distance from the hinge) x tan(angle); the
        # handle on it, sin(angle): what the front says of the handle, against what the hand came
        out = float((site - run.start) @ state.base_dir)
        if front["shift"] / math.hypot(1.0, front["across"]) > out + cfg.hinge_look_slack:
            return  # a front that came out farther than the hand that pulls it
        seen = np.array([float(handle.panel_x), float(handle.centre[1]) - front["shift"] / front["across"]])
        off = float(np.linalg.norm(seen - state.hinge))
        r = run.start[:2] - seen
        radius = float(np.linalg.norm(r))
        lo, hi = cfg.seen_hinge_radius
        if off <= self.config.recovery.hinge_agreement or not lo <= radius <= hi:
            return
        result.events.append({"hinge_seen_turning": {"hinge": [round(float(v), 3) for v in seen],
                                                     "was": [round(float(v), 3) for v in state.hinge],
                                                     "radius": round(radius, 3), "across": front["across"]}})
        self.turn_about(state, seen, r)

    @staticmethod
    def turn_about(state: PullState, hinge: np.ndarray, r: np.ndarray) -> None:
        """Pull along the circle about ``hinge`` (x, y; m) through the point ``hinge + r``: the sense
        whose tangent there leaves the cabinet (-x) and the angle (rad) the circle starts at (also
        where a pull goes on about a taken-over door's hinge: :class:`~.takeover.TakeOver`)."""
        state.hinge = hinge
        state.sense = -1.0 if r[1] < 0 else 1.0  # the tangent (-r_y, r_x) / |r| that leaves the cabinet (-x)
        state.angle0 = math.atan2(r[1], r[0])

    def _hinge_tangent(self, state: PullState, site: np.ndarray) -> tuple[np.ndarray, float]:
        """The opening tangent of the circle about the hinge through the site, and the door's angle
        (deg, signed like the turn of the pull direction from -x)."""
        r = site[:2] - state.hinge
        norm = max(1e-6, float(np.linalg.norm(r)))
        t = state.sense * np.array([-r[1], r[0]]) / norm
        tangent = np.array([t[0], t[1], 0.0])
        base = state.base_dir
        ang = math.degrees(math.atan2(base[0] * t[1] - base[1] * t[0], float(base[0] * t[0] + base[1] * t[1])))
        return tangent, ang
