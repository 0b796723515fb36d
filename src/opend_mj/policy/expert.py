"""The planner as an interactive expert: the planner's action at any state of an episode, whoever acted before.

DAgger (Ross et al. 2011) labels the states a learner's own policy reaches with an expert's
actions, so the expert must answer at states it did not lead to. :class:`PlannerExpert` runs the
benchmark's planner (around its handle solver, the oracle by default) as a coroutine beside the
scene: every control step :meth:`PlannerExpert.action` gives the action the planner would send now
(the label), and whatever action is then stepped, :meth:`PlannerExpert.action` of the next step
reads the state that action led to.

The planner's plan holds while the hand stays near it. It starts again from the state as it is
where the grasp site is more than ``drift`` (m) from the plan's own site target, or where the hand
holds something while the plan still approaches with the fingers open: the planner's
:meth:`~opend_mj.policy.planner.Planner.run` with the instructed part's motion since the first
image (:class:`~opend_mj.policy.planner.PartMotion`), so that a hand on the handle goes on pulling
it, and any other approaches it from where it is. The expert reads that motion from the simulator
(the part's joint), as the oracle solver reads the handle's box: it is a teacher for training,
never an agent under evaluation.

A state it cannot label gets None (:attr:`PlannerExpert.why` says why): the grasp site inside the
cabinet (behind the front's plane in the first image by more than ``inside``, m), or the plan
finished (the planner's episode ended: the part is open, or the planner gave up).
"""

from __future__ import annotations

import queue
import threading
from dataclasses import dataclass

import numpy as np

from opend_mj.policy.planner import Observation, PartMotion, Robot
from opend_mj.sim.hands import grasp_pose_to_root_pose
from opend_mj.transforms import axis_angle_quat, quat_to_mat


@dataclass(frozen=True)
class ExpertConfig:
    """When the expert's plan starts again, and what it cannot label."""

    #: m: grasp site farther than this from the plan's site target: plan again from here (the site
    #: lags the target by up to about 0.2 m where the plan's own moves outrun the hand's speed limit)
    drift: float = 0.3
    #: m (a drawer) or deg (a door): the part opened this much further while the plan approaches it
    #: (another agent pulled it): plan again
    part_moved: float = 0.01
    part_moved_deg: float = 3.0
    inside: float = 0.03  # m: grasp site this far behind the front's plane of the first image: no label
    cooldown: int = 6  # control steps a new plan runs before it may be started again
    solver: str = "oracle"
    pull: str = "arc"


class _Stop(BaseException):
    """Raised inside the plan's thread to end it (the plan is replaced, or the episode ended)."""


class _HandoverRobot(Robot):
    """The planner's robot over the real scene, except that a step hands the action to the expert
    (which returns it as its label) and waits until the scene was stepped, by whoever."""

    def __init__(self, env, expert: "PlannerExpert"):
        super().__init__(env, look=self._look)
        self._expert = expert

    def step(self, site_pos, site_quat, fingers) -> None:
        root_pos, root_quat = grasp_pose_to_root_pose(self.spec, site_pos, site_quat)
        self._expert._hand_over(("action", self.task.make_action(root_pos, root_quat, fingers),
                                 np.array(site_pos, float)))
        self.n_steps += 1

    def _look(self) -> np.ndarray:
        return self._expert._hand_over(("look",))


def part_motion(task, physics) -> PartMotion:
    """How the instructed part moved since the episode began (every part starts closed): its joint's
    turn about its axis through its anchor, or its slide along its axis (world frame)."""
    target = task.target
    bound = physics.bind(task.cabinet.joint_element(target.joint))
    delta = float(bound.qpos[0]) - float(target.closed)
    axis = np.array(bound.xaxis, float)
    axis = axis / max(1e-12, float(np.linalg.norm(axis)))
    share = float(target.range_ratio(float(bound.qpos[0])))
    if int(physics.model.jnt_type[int(bound.element_id)]) == 3:  # mjJNT_HINGE
        return PartMotion(rot=quat_to_mat(axis_angle_quat(axis, delta)), pivot=np.array(bound.xanchor, float),
                          share=share)
    return PartMotion(shift=axis * delta, share=share)


class PlannerExpert:
    """The planner's action at any state of an episode of ``env`` (a scene of
    :func:`opend_mj.evaluation.runner.make_episode_env`, reset, its target set).

    ``first``: the episode's first observation (the image the planner locates the handle in, taken
    before any part moved); ``camera``: the episode's :class:`~opend_mj.sim.camera.RGBDCamera`
    (the planner's looks while the hand moves). Call :meth:`action` once per control step, before
    the step; :meth:`close` at the end. ``restarts``: how many times the plan started again from
    the state as it was; ``unlabelled``: steps answered with None; ``taken_over``: how the first
    plan started mid-way found the part and the hand (:attr:`EpisodeState.taken_over`), None where
    the expert began with the episode."""

    def __init__(self, env, first: Observation, camera, config: ExpertConfig = ExpertConfig(), hand=None):
        self.env = env
        self.task, self.physics = env.task, env.physics
        self.first = first
        self.camera = camera
        self.config = config
        self.hand = hand or self.task.hand.spec.name
        self.why: str | None = None
        self.result = None  # the PlanResult of the plan that ran last to its end
        self.restarts = 0
        self.unlabelled = 0
        self.taken_over: dict | None = None  # the first plan's view of the state it took over
        self.stage = ""
        self.style = ""  # the grasp style the plan holds or approaches with ("" before it chose one)
        self._thread = None
        self._waiting = False  # the plan waits for the scene to be stepped
        self._label = None  # (action, site target) of the plan's latest step
        self._age = 0  # steps the current plan has run
        self._panel_x: float | None = None
        self._reader = Robot(env)  # reads the hand's state for the expert's own checks
        spec = env.action_spec()
        self._finger_span = np.maximum(spec.maximum[7:] - spec.minimum[7:], 1e-9)  # actuator ranges
        bound = self.physics.bind(self.task.cabinet.joint_element(self.task.target.joint))
        hinge = int(self.physics.model.jnt_type[int(bound.element_id)]) == 3  # mjJNT_HINGE
        #: ``part_moved`` in the part's joint units (m, or rad for a hinge)
        self._open_step = float(np.radians(config.part_moved_deg)) if hinge else config.part_moved

    # ---------------------------------------------------------------- the coroutine
    def _hand_over(self, message):
        """Thread side: send ``message`` to the expert and wait for its reply."""
        self._outbox.put(message)
        reply = self._inbox.get()
        if reply is _STOP:
            raise _Stop()
        return reply

    def _start(self, motion: PartMotion | None) -> None:
        from opend_mj.policy.factory import build_planner

        self._stop()
        task, physics = self.task, self.physics
        planner = build_planner(self.config.solver, self.hand, pull=self.config.pull,
                                ground_truth=lambda: task.handle_boxes(physics)[task.target.joint],
                                on_stage=self._on_stage)
        self._planner = planner
        self._inbox, self._outbox = queue.Queue(), queue.Queue()
        robot = _HandoverRobot(self.env, self)

        def run():
            try:
                self._outbox.put(("done", planner.run(robot, self.first, motion)))
            except _Stop:
                pass
            except Exception as exc:  # noqa: BLE001 (handed to the caller of action)
                self._outbox.put(("error", exc))

        self.stage = ""
        self._opened_at_start = self._opened()
        self._age = 0
        self._waiting = False
        self._thread = threading.Thread(target=run, name="planner-expert", daemon=True)
        self._thread.start()

    def _on_stage(self, name: str, info: dict) -> None:
        """A stage of the plan starts: its name, and an approach's grasp style."""
        self.stage = name
        if name == "approach" and "style" in info:
            self.style = str(info["style"])

    def _stop(self) -> None:
        if self._thread is not None:
            if self._waiting or self._thread.is_alive():
                self._inbox.put(_STOP)
            self._thread.join()
            self._thread = None
            self._waiting = False

    def _next(self) -> tuple | None:
        """The plan's next action (action, site target), serving its looks; None where it ended."""
        if self._waiting:
            self._inbox.put(None)  # the scene was stepped: the plan goes on
            self._waiting = False
        while True:
            message = self._outbox.get()
            if message[0] == "look":
                rgb, depth = self.camera.render()
                self._inbox.put(self.task.sense_depth(rgb, depth))
                continue
            if message[0] == "action":
                self._waiting = True
                self._age += 1
                return message[1], message[2]
            self._thread.join()
            self._thread = None
            if message[0] == "error":
                raise message[1]
            self.result = message[1]
            return None

    # ---------------------------------------------------------------- the expert
    def _panel(self) -> float | None:
        """World x of the front's plane in the first image (the panel the handle stands on)."""
        if self._panel_x is None and self.result is None and self._thread is not None:
            handle = self._planner.state.handle
            self._panel_x = None if handle is None else float(handle.panel_x)
        return self._panel_x

    def _off_plan(self, site, label) -> bool:
        """Whether the state left the plan: the site far from the plan's site target; or, while the
        plan approaches the handle, the part moved since the plan began, or the hand holding
        something with its fingers closed (a quarter of their range or more from the plan's
        targets) where the plan has them open."""
        if self._age <= self.config.cooldown:
            return False
        action, target = label
        if float(np.linalg.norm(site - target)) > self.config.drift:
            return True
        if self.stage != "approach":
            return False
        if self._opened() - self._opened_at_start > self._open_step:
            return True  # the part the plan approaches was opened further (by another agent)
        robot = self._robot_view()
        apart = np.abs(np.asarray(robot.finger_qpos(), float) - action[7:]) / self._finger_span
        return float(np.mean(apart)) > 0.25 and self._planner.approach.holding(robot)[0]

    def _opened(self) -> float:
        """How far the instructed part is open (m for a drawer, rad for a door: the joint from closed)."""
        target = self.task.target
        return float(target.open_sign * (self.task.cabinet.joint_values(self.physics)[target.joint] - target.closed))

    def _robot_view(self) -> Robot:
        """The hand's own state, read as the planner reads it (site, fingers, touch)."""
        return self._reader

    def action(self) -> np.ndarray | None:
        """The planner's action at the scene's current state (the task action: root position,
        quaternion w x y z, finger targets), or None where it cannot label this state (``why``)."""
        if self._thread is None and self.result is None:
            self._start(None if self.restarts == 0 and self._fresh() else part_motion(self.task, self.physics))
        label = self._next() if self._thread is not None else None
        site = self._robot_view().site_pos()
        panel = self._panel()
        if panel is not None and float(site[0]) > panel + self.config.inside:
            return self._none("inside")
        if label is not None and self._off_plan(site, label):
            self.restarts += 1
            self.result = None
            self._start(part_motion(self.task, self.physics))
            label = self._next()
        taken = self._planner.state.taken_over
        if taken is not None and self.taken_over is None:
            self.taken_over = dict(taken)
        if taken is not None and self.stage in ("", "locate", "pull"):  # a held handle: the plan's grasp
            self.style = taken.get("style", self.style)
        if label is None:
            return self._none("finished")
        self.why = None
        return label[0]

    def _fresh(self) -> bool:
        """Whether the episode is at its start (no part moved, the hand where the task put it)."""
        motion = part_motion(self.task, self.physics)
        return motion.angle_deg < 0.5 and motion.distance < 0.002 and float(self.physics.data.time) < 1e-9

    def _none(self, why: str) -> None:
        self.why = why
        self.unlabelled += 1
        return None

    def close(self) -> None:
        self._stop()


_STOP = object()

__all__ = ["ExpertConfig", "PlannerExpert", "part_motion"]
