"""The stage loop: locate -> perceive -> choose a grasp -> approach -> close and verify -> pull,
re-grasping where the grip is lost, pushing a lost door open, giving up a handle of the other kind.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Callable

from opend_mj.language import InstructionNotUnderstood, target_kind
from opend_mj.policy.handle_box import NO_HANDLE, HandleSolver, centres_overlap
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
from opend_mj.policy.planner.moves import hold, move
from opend_mj.policy.planner.pull import Pulling
from opend_mj.policy.planner.records import (
    EpisodeState,
    Observation,
    PartMotion,
    PlanResult,
    PullState,
    StageOutcome,
)
from opend_mj.policy.planner.recovery import PushRecovery
from opend_mj.policy.planner.robot import new_depth
from opend_mj.policy.planner.slide import PanelSliding
from opend_mj.policy.planner.stage import Stage, StageContext
from opend_mj.policy.planner.takeover import TakeOver
from opend_mj.sim.hands import HandModel, HandPlannerConfig, HandSpec, get_hand
from opend_mj.transforms import quat_axis_z

#: After a finished pull with ``release``: the fingers stay closed, then open, for these times
#: (s), and the hand backs off this far (m) along its approach axis.
RELEASE_HOLD = 0.2
RELEASE_OPEN = 0.4
RELEASE_BACKOFF = 0.08
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
    a lost door pushed open from inside), ``takeover`` (:class:`~.takeover.TakeOver`: an episode
    taken over mid-way); ``front`` (:class:`~.kind.FrontWatch`) is the camera's second look that
    several of them use. Each handle's attempt ends in a :class:`~.records.StageOutcome`.

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
        self.takeover = TakeOver(self.ctx, self.approach, self.flap, self.recovery)

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
            outcome, state, grasp = self.open_handle(robot, obs, handle, box, result, motion)
            motion = None  # a handle asked for again is approached as at an episode's start
            if outcome not in (StageOutcome.NO_HANDLE, StageOutcome.WRONG_KIND):
                break
            # this handle is given up: the episode ends not held unless the solver gives another one
            given_up, outcome = outcome, StageOutcome.NOT_HELD
            observed = observed + (self._give_up(robot, given_up, box, state, grasp, result),)
            if not self._retarget(robot, observed):
                break
            if given_up is StageOutcome.NO_HANDLE:
                result.no_handle.append([round(x, 2) for x in box.as_tuple()])
            new_handle, new_box = self.locate(robot, obs, result, observed)
            if new_handle is None or centres_overlap([new_box.as_tuple()], [b for b, _ in observed]).any():
                break
            if given_up is StageOutcome.WRONG_KIND:
                self._look_again(robot, obs)  # only where another handle is pulled
            handle, box = new_handle, new_box
        result.pulled = state.travelled
        result.turned_deg = state.turned
        result.grasp_style = grasp.style
        self._finish(robot, outcome, grasp, result)
        return result

    def _give_up(self, robot, outcome: StageOutcome, box, state: PullState, grasp, result: PlanResult) -> tuple:
        """A handle given up (``NO_HANDLE``: the fingers closed on nothing there; ``WRONG_KIND``: it
        moved as the other kind, so it is pushed back and let go, and recorded): its (box, kind) for
        the solver to leave out, a box with nothing in it grown by ``kind.empty_margin``."""
        if outcome is StageOutcome.NO_HANDLE:
            m = self.config.kind.empty_margin
            u0, v0, u1, v1 = box.as_tuple()
            return (u0 - m, v0 - m, u1 + m, v1 + m), NO_HANDLE
        seen = state.seen_kind
        result.wrong_kind.append({"box": [round(x, 2) for x in box.as_tuple()], "kind": seen,
                                  "by": state.seen_by, "turn_deg": round(state.seen_turn, 1)})
        self.kind.push_back(robot, grasp, state)
        return box.as_tuple(), seen

    def _retarget(self, robot, observed: tuple) -> bool:
        """Whether another handle may be asked for after the ``observed`` ones were given up: fewer
        than ``max_target_tries`` tried, ``retarget_time`` left, and a solver that takes them."""
        cfg = self.config.kind
        return (len(observed) < cfg.max_target_tries and self._time_left(robot) >= cfg.retarget_time
                and getattr(self.solver, "accepts_observed", False))

    def _finish(self, robot, outcome: StageOutcome, grasp, result: PlanResult) -> None:
        """Hold (closed where the pull finished, else open; released where ``release``) until
        ``min_time``, then the planner's own verdict."""
        site, squat = robot.site_pose()
        done = outcome is StageOutcome.DONE
        fingers = grasp.closed if done else self.spec.pregrasp_profile(grasp.orientation)
        if self.config.release and done:
            pre = self.spec.pregrasp_profile(grasp.orientation)
            hold(robot, site, squat, grasp.closed, RELEASE_HOLD)
            hold(robot, site, squat, pre, RELEASE_OPEN)
            move(robot, site, site - RELEASE_BACKOFF * quat_axis_z(squat), squat, pre,
                 self.config.approach.approach_speed)
            fingers = pre
        self._hold_until_min_time(robot, (robot.site_pose()[0], robot.site_pose()[1], fingers))
        self._stage(result, "check", pulled=round(result.pulled, 4), turned_deg=round(result.turned_deg, 2),
                    regrasps=result.regrasps)
        if outcome is StageOutcome.NOT_HELD and result.pulled < GRASP_FAILED_TRAVEL and not result.pushed:
            result.failed_stage = "grasp"
        elif not done and not result.pushed:
            result.failed_stage = "pull"

    def _look_again(self, robot, obs: Observation) -> None:
        """A new image for the next pulled front's motion to be measured against: a wrong handle
        pushed back may leave its part ajar (a drawer a few cm out), which the first image would
        show as the next front's motion. The solver keeps reading the first image."""
        depth = new_depth(robot)
        if depth is not None:
            self.state.first = replace(obs, depth=depth)

    def open_handle(self, robot, obs: Observation, handle, box, result: PlanResult,
                    motion: PartMotion | None = None) -> tuple[StageOutcome, PullState, object]:
        """Perceive, grasp and pull one handle, grasping again where the grip is lost: (outcome, pull
        state, last grasp). The outcome is ``DONE``, ``SLIPPED``, ``NOT_HELD``, ``NO_HANDLE`` (every
        grasp closed on air, nothing moved: no handle there) or ``WRONG_KIND`` (its motion showed the
        other kind than the instruction's). ``motion``: see :meth:`run` (:class:`~.takeover.TakeOver`)."""
        cfg = self.config
        self.state.handle = handle
        self.state.felt = False
        shape = self.perceive(handle, box, obs, result)
        grasp = self.grasping.choose_grasp(handle, shape, obs, result)
        door = result.target_kind == "door" and cfg.pull == "arc"
        state = PullState(quat0=grasp.quat)
        held = False
        if motion is not None:
            taken, grasp, held = self.takeover.resume(robot, grasp, motion, door, state, result)
            if taken is not None:
                return taken, state, grasp
        outcome = StageOutcome.NOT_HELD
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
                    outcome = StageOutcome.NOT_HELD
                    self.approach.back_off(robot, grasp)
                    grasp = self.grasping.next_grasp(grasp, handle, shape, state, result)
                    continue
            outcome = self.pulling.pull(robot, grasp, door, state, result)
            if outcome is StageOutcome.WRONG_KIND:
                return outcome, state, grasp
            if outcome is StageOutcome.STUCK:  # a drawer that did not come out: slide it along its front
                outcome = StageOutcome.SLIPPED
                if not self.slide.next_slide(state, result):
                    break
            if outcome is StageOutcome.SLIPPED and (self.recovery.swung(state) >= cfg.pulling.door_done_deg if door
                                                    else state.travelled >= cfg.pulling.drawer_done):
                outcome = StageOutcome.DONE  # lost at the end of the travel (the part's stop pulled the hand off)
            if outcome is StageOutcome.DONE:
                break
            if door and cfg.recovery.push_recovery and self._door_opened(state):
                self.approach.back_off(robot, grasp)
                break  # an opened door is pushed open from inside (below), not grasped again
            self.approach.back_off(robot, grasp)
            grasp = self.grasping.next_grasp(grasp, handle, shape, state, result)
        if door and outcome is not StageOutcome.DONE and cfg.recovery.push_recovery:
            self.recovery.recover_door(robot, state, result)
        if outcome is StageOutcome.NOT_HELD and not self.state.felt and not held and not result.pushed \
                and state.travelled < GRASP_FAILED_TRAVEL:
            return StageOutcome.NO_HANDLE, state, grasp  # every grasp closed on air: no handle in this box
        return outcome, state, grasp

    def _door_opened(self, state: PullState) -> bool:
        """Whether a lost door's held path shows it opened enough to be pushed open from inside: an
        arc of ``push_min_turn`` (deg) or more, or a flap's of ``flap_push_min_deg`` or more."""
        cfg = self.config.recovery
        arc = self.recovery.door_arc(state)
        flap = self.recovery.flap_arc(state)
        return arc is not None and math.degrees(arc[4]) >= cfg.push_min_turn \
            or flap is not None and math.degrees(flap[2]) >= cfg.flap_push_min_deg

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
