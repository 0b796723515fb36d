"""The stage loop: locate -> perceive -> choose a grasp -> approach -> close and verify -> pull,
re-grasping where the grip is lost, pushing a lost door open, giving up a handle of the other kind.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Callable

import numpy as np

from opend_mj.language import InstructionNotUnderstood, target_kind
from opend_mj.policy.handle import NO_HANDLE, HandleSolver, centres_overlap
from opend_mj.policy.perception import (
    estimate_handle,
    measure_handle,
    one_of_paired_handles,
    refine_box_with_depth,
    snaps_to_depth,
)
from opend_mj.policy.planner.approach import Approach
from opend_mj.policy.planner.config import PlannerConfig
from opend_mj.policy.planner.flap import FlapSteering
from opend_mj.policy.planner.grasp import Grasping
from opend_mj.policy.planner.kind import FrontWatch, KindCheck
from opend_mj.policy.planner.moves import hold, move, unyawed
from opend_mj.policy.planner.pull import Pulling
from opend_mj.policy.planner.records import (
    EpisodeState,
    Flap,
    GraspChoice,
    Observation,
    PartMotion,
    PlanResult,
    PullState,
)
from opend_mj.policy.planner.recovery import PushRecovery
from opend_mj.policy.planner.robot import new_depth
from opend_mj.policy.planner.slide import PanelSliding
from opend_mj.policy.planner.stage import Stage, StageContext
from opend_mj.sim.hands import HandModel, HandPlannerConfig, HandSpec, get_hand
from opend_mj.transforms import quat_axis_z

#: After a finished pull with ``release``: the fingers stay closed, then open, for these times
#: (s), and the hand backs off this far (m) along its approach axis.
RELEASE_HOLD = 0.2
RELEASE_OPEN = 0.4
RELEASE_BACKOFF = 0.08
#: An episode taken over with its part open this share of its range or more is done (the benchmark's
#: second criterion already holds; pulling on from a wide angle, near its stop, would drag a door shut).
TAKEN_OVER_OPEN = 0.75
#: A grip never held beyond this much pull travel (m) is the grasp's failure, not the pull's.
GRASP_FAILED_TRAVEL = 0.03


def _registered_numbers(spec: HandSpec | None) -> HandPlannerConfig:
    """The planner's numbers of the registered hand ``spec`` names, else the defaults of its type
    (None: the defaults)."""
    if spec is None:
        return HandPlannerConfig()
    try:
        return get_hand(spec.name).planner
    except KeyError:
        return HandPlannerConfig.for_type(spec.hand_type)


def settle_box(solver, box, depth, view, config) -> tuple:
    """A solver's box as the planner acts on it: a learned solver's box snapped to the handle standing
    out of the panel in depth, a box over a pair of pulls narrowed to the nearer one (``config``: a
    :class:`PlannerConfig`). Returns (box or None, events: the boxes replaced, for the record)."""
    events = []
    if config.locate.refine_with_depth and snaps_to_depth(solver, box):
        events.append({"solver_box": box.to_dict()})
        box = refine_box_with_depth(box, depth, view, config.perception)
    if box is not None and config.locate.one_of_paired_handles:
        single = one_of_paired_handles(box, depth, config.perception)
        if single is not None:  # a pair of pulls under one box: take the nearer one
            events.append({"paired_handles_box": box.to_dict()})
            box = single
    return box, events


class Planner(Stage):
    """Deterministic open-the-handle controller around a handle solver: a short loop over its stages.

    Stages (each an object over one :class:`~opend_mj.policy.planner.stage.StageContext`):
    :meth:`locate` and :meth:`perceive` (here: solver box -> 3D handle -> shape from depth),
    ``grasping`` (:class:`~.grasp.Grasping`: where and how to grasp, and again after a lost grip),
    ``approach`` (:class:`~.approach.Approach`: in, close, verify by touch, back off), ``pulling``
    (:class:`~.pull.Pulling`, with its ``flap`` and ``slide`` variants), ``kind``
    (:class:`~.kind.KindCheck`: a handle whose pull shows the other kind than the instruction's is
    taken back, let go, and the solver asked again), ``recovery`` (:class:`~.recovery.PushRecovery`:
    a lost door pushed open from inside); ``front`` (:class:`~.kind.FrontWatch`) is the camera's
    second look that several of them use.

    ``hand``: the hand (a :class:`~opend_mj.sim.hands.HandModel`, or a bare
    :class:`~opend_mj.sim.hands.HandSpec` whose registered hand supplies the planner's numbers);
    ``config``: the planner's configuration as it will be used (the hand's grasp tuning already
    applied: :func:`opend_mj.policy.factory.build_planner` does that); ``numbers``: the planner's
    numbers for the hand, instead of the hand's own (``planner.json``); ``on_stage``: called with
    (stage name, info) as each stage starts."""

    def __init__(self, solver: HandleSolver, hand: HandModel | HandSpec | None, config: PlannerConfig = PlannerConfig(),
                 *, numbers: HandPlannerConfig | None = None, on_stage: Callable[[str, dict], None] | None = None):
        spec = hand.spec if isinstance(hand, HandModel) else hand
        if numbers is None:
            numbers = hand.planner if isinstance(hand, HandModel) else _registered_numbers(spec)
        super().__init__(StageContext(config=config, spec=spec, hand=numbers, on_stage=on_stage))
        self.solver = solver
        self.front = FrontWatch(self.ctx)
        self.grasping = Grasping(self.ctx)
        self.approach = Approach(self.ctx)
        self.kind = KindCheck(self.ctx, solver, self.front, self.approach)
        self.flap = FlapSteering(self.ctx, self.front)
        self.slide = PanelSliding(self.ctx)
        self.pulling = Pulling(self.ctx, self.approach, self.kind, self.front, self.flap, self.slide)
        self.recovery = PushRecovery(self.ctx, self.grasping, self.front)

    @Stage.config.setter
    def config(self, config: PlannerConfig) -> None:
        self.ctx.config = config

    @property
    def state(self) -> EpisodeState:
        """The state of the episode being run (every stage reads this one)."""
        return self.ctx.episode

    @state.setter
    def state(self, state: EpisodeState) -> None:
        self.ctx.episode = state

    # ---------------------------------------------------------------- helpers
    def _stage(self, result: PlanResult, name: str, **info) -> None:
        self.ctx.enter(result, name, **info)

    def _time_left(self, robot) -> float:
        return self.ctx.time_left(robot)

    def _hold_until_min_time(self, robot, pose) -> None:
        """Keep ``pose`` (site position, orientation, fingers; None: where the hand is, open) until
        the episode lasted ``min_time``."""
        if pose is None:
            pos, quat = robot.site_pose()
            fingers = self.spec.open_pose
        else:
            pos, quat, fingers = pose
        while robot.time < self.config.min_time - 1e-9:
            robot.step(pos, quat, fingers)

    # ---------------------------------------------------------------- the episode
    def run(self, robot, obs: Observation, motion: PartMotion | None = None) -> PlanResult:
        """One episode from its one observation: open the handle the instruction names.

        ``motion``: an episode taken over mid-way (the planner as an interactive expert,
        :mod:`opend_mj.policy.expert`): ``obs`` is still the episode's first image, the hand is
        wherever another agent left it, and the instructed part has moved by ``motion`` since that
        image. The grasp chosen in the image moves with its part; a hand that already holds the
        handle goes on pulling it, any other approaches it from where it is."""
        cfg = self.config
        result = PlanResult(stage_reached="locate", failed_stage=None)
        self.state = EpisodeState(first=obs)  # the image a pulled front's motion is measured against
        try:
            result.target_kind = target_kind(obs.instruction)
        except InstructionNotUnderstood as exc:  # refused, never guessed: the robot does not move
            result.stage_reached = result.failed_stage = "language"
            result.events.append({"language": exc.reason})
            self._hold_until_min_time(robot, None)
            return result
        observed: tuple = ()
        handle, box = self.locate(robot, obs, result)
        if handle is None:
            result.failed_stage = "locate"
            self._hold_until_min_time(robot, None)
            return result
        while True:
            status, state, grasp = self.open_handle(robot, obs, handle, box, result, motion)
            motion = None  # a handle asked for again is approached as at an episode's start
            if status == "no_handle":  # the fingers closed on nothing there: ask for another box
                m = cfg.kind.empty_margin
                u0, v0, u1, v1 = box.as_tuple()
                observed = observed + (((u0 - m, v0 - m, u1 + m, v1 + m), NO_HANDLE),)
                status = "not_held"
                if not self._retarget(robot, observed):
                    break
                result.no_handle.append([round(x, 2) for x in box.as_tuple()])
                new_handle, new_box = self.locate(robot, obs, result, observed)
                if new_handle is None or centres_overlap([new_box.as_tuple()], [b for b, _ in observed]).any():
                    break
                handle, box = new_handle, new_box
                continue
            if status != "wrong_kind":
                break
            # the handle moved as the other kind: push it back, let go, ask the solver again
            seen = state.seen_kind
            observed = observed + ((box.as_tuple(), seen),)
            result.wrong_kind.append({"box": [round(x, 2) for x in box.as_tuple()], "kind": seen,
                                      "by": state.seen_by, "turn_deg": round(state.seen_turn, 1)})
            self.kind.push_back(robot, grasp, state)
            if not self._retarget(robot, observed):
                status = "not_held"
                break
            new_handle, new_box = self.locate(robot, obs, result, observed)
            if new_handle is None or centres_overlap([new_box.as_tuple()], [b for b, _ in observed]).any():
                status = "not_held"
                break
            self._look_again(robot, obs)  # only where another handle is pulled
            handle, box = new_handle, new_box
        result.pulled = state.travelled
        result.turned_deg = state.turned
        result.grasp_style = grasp.style
        self._finish(robot, status, grasp, result)
        return result

    def _retarget(self, robot, observed: tuple) -> bool:
        """Whether another handle may be asked for after the ``observed`` ones were given up: fewer
        than ``max_target_tries`` tried, ``retarget_time`` left, and a solver that takes them."""
        cfg = self.config.kind
        return (len(observed) < cfg.max_target_tries and self._time_left(robot) >= cfg.retarget_time
                and getattr(self.solver, "accepts_observed", False))

    def _finish(self, robot, status: str, grasp, result: PlanResult) -> None:
        """Hold (closed where the pull finished, else open; released where ``release``) until
        ``min_time``, then the planner's own verdict."""
        site, squat = robot.site_pose()
        fingers = grasp.closed if status == "done" else self.spec.pregrasp_profile(grasp.orientation)
        if self.config.release and status == "done":
            pre = self.spec.pregrasp_profile(grasp.orientation)
            hold(robot, site, squat, grasp.closed, RELEASE_HOLD)
            hold(robot, site, squat, pre, RELEASE_OPEN)
            move(robot, site, site - RELEASE_BACKOFF * quat_axis_z(squat), squat, pre,
                 self.config.approach.approach_speed)
            fingers = pre
        self._hold_until_min_time(robot, (robot.site_pose()[0], robot.site_pose()[1], fingers))
        self._stage(result, "check", pulled=round(result.pulled, 4), turned_deg=round(result.turned_deg, 2),
                    regrasps=result.regrasps)
        if status == "not_held" and result.pulled < GRASP_FAILED_TRAVEL and not result.pushed:
            result.failed_stage = "grasp"
        elif status != "done" and not result.pushed:
            result.failed_stage = "pull"

    def _look_again(self, robot, obs: Observation) -> None:
        """A new image for the next pulled front's motion to be measured against: a wrong handle
        pushed back may leave its part ajar (a drawer a few cm out), which the first image would
        show as the next front's motion. The solver keeps reading the first image."""
        depth = new_depth(robot)
        if depth is not None:
            self.state.first = replace(obs, depth=depth)

    def open_handle(self, robot, obs: Observation, handle, box, result: PlanResult, motion: PartMotion | None = None):
        """Perceive, grasp and pull one handle, grasping again where the grip is lost: (status,
        pull state, last grasp); status "done", "slipped", "not_held", "no_handle" (every grasp closed
        on air, nothing moved: no handle there) or "wrong_kind" (its motion
        showed the other kind than the instruction's). ``motion``: see :meth:`run`."""
        cfg = self.config
        self.state.handle = handle
        self.state.felt = False
        shape = self.perceive(handle, box, obs, result)
        grasp = self.grasping.choose_grasp(handle, shape, obs, result)
        door = result.target_kind == "door" and cfg.pull == "arc"
        state = PullState(quat0=grasp.quat)
        held = False
        if motion is not None:
            start = grasp.pos
            grasp, held = self._taken_over(robot, grasp, motion, state, result)
            if (motion.angle_deg >= cfg.pulling.door_done_deg if door else state.travelled >= cfg.pulling.drawer_done) \
                    or (motion.share is not None and motion.share >= TAKEN_OVER_OPEN):
                return "done", state, grasp  # the part is as open as a finished pull leaves it
            if door and not held and cfg.recovery.push_recovery and self._door_turned(motion, start, state) \
                    and self.recovery.recover_door(robot, state, result):
                return "not_held", state, grasp  # a door left ajar is pushed open from inside, as a lost one
        status = "not_held"
        for attempt in range(cfg.recovery.max_grasp_tries):
            if attempt > 0 and self._time_left(robot) < cfg.recovery.attempt_time:
                break
            grasp.attempt = attempt
            if attempt > 0:
                result.regrasps += 1
            if not (attempt == 0 and held):  # (a hand taken over on the handle pulls on)
                self.approach.approach(robot, grasp, result, first=attempt == 0 and not result.wrong_kind,
                                       from_here=attempt == 0 and motion is not None)
                if not self.approach.close_and_verify(robot, grasp, result):
                    status = "not_held"
                    self.approach.back_off(robot, grasp)
                    grasp = self.grasping.next_grasp(grasp, handle, shape, state, result)
                    continue
            status = self.pulling.pull(robot, grasp, door, state, result)
            if status == "wrong_kind":
                return status, state, grasp
            if status == "stuck":  # a drawer that did not come out: slide it along its front
                status = "slipped"
                if not self.slide.next_slide(state, result):
                    break
            if status == "slipped" and (self.recovery.swung(state) >= cfg.pulling.door_done_deg if door
                                        else state.travelled >= cfg.pulling.drawer_done):
                status = "done"  # lost at the end of the travel (the part's stop pulled the hand off)
            if status == "done":
                break
            if door and cfg.recovery.push_recovery:
                arc = self.recovery.door_arc(state)
                flap = self.recovery.flap_arc(state)
                if arc is not None and math.degrees(arc[4]) >= cfg.recovery.push_min_turn \
                        or flap is not None and math.degrees(flap[2]) >= cfg.recovery.flap_push_min_deg:
                    self.approach.back_off(robot, grasp)
                    break  # an opened door is pushed open from inside (below), not grasped again
            self.approach.back_off(robot, grasp)
            grasp = self.grasping.next_grasp(grasp, handle, shape, state, result)
        if door and status != "done" and cfg.recovery.push_recovery:
            self.recovery.recover_door(robot, state, result)
        if status == "not_held" and not self.state.felt and not held and not result.pushed \
                and state.travelled < GRASP_FAILED_TRAVEL:
            return "no_handle", state, grasp  # every grasp closed on air: no handle in this box
        return status, state, grasp

    def _taken_over(self, robot, grasp: GraspChoice, motion: PartMotion, state: PullState, result: PlanResult):
        """An episode taken over mid-way: the grasp chosen in the first image moved with its part
        (``motion``), the pull's travel so far (m) taken from the part's slide or the grasp point's
        path, and whether the hand already holds the handle (:meth:`Approach.holds`). Returns
        (the moved grasp, held)."""
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
                    self.state.hinge = hinge
                    Pulling._turn_about(state, hinge, np.asarray(grasp.pos[:2], float) - hinge)
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
        self.state.taken_over = {"turned_deg": round(motion.angle_deg, 1), "slid": round(motion.distance, 4),
                                 "held": held, "style": moved.style}
        result.events.append({"taken_over": self.state.taken_over})
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

    def locate(self, robot, obs: Observation, result: PlanResult, observed: tuple = ()):
        """The solver's box (snapped to the handle in depth for learned solvers) -> 3D handle;
        ``observed``: (box, kind) of handles whose motion showed their kind (a solver that takes them)."""
        cfg = self.config
        self._stage(result, "locate")
        if observed:
            box = self.solver.solve(obs.rgb, obs.depth, obs.instruction, obs.camera_view, observed=observed)
        else:
            box = self.solver.solve(obs.rgb, obs.depth, obs.instruction, obs.camera_view)
        box, events = settle_box(self.solver, box, obs.depth, obs.camera_view, cfg)
        result.events.extend(events)
        result.box = box.to_dict() if box is not None else None
        handle = estimate_handle(box, obs.depth, obs.camera_view, cfg.perception) if box is not None else None
        if handle is not None:
            result.handle = handle.to_dict()
        return handle, box

    def perceive(self, handle, box, obs: Observation, result: PlanResult):
        """Thickness, length, stand-off gap and free space around the handle, measured in depth."""
        shape = measure_handle(handle, box, obs.depth, obs.camera_view, self.config.perception)
        result.shape = shape.to_dict()
        return shape
