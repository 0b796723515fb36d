"""Agents: anything that maps the benchmark's observations to actions, one control step at a time.

The interface `opend run --policy module:Class` evaluates (docs/evaluation.md, "Agent reference")::

    class MyAgent:
        name = "my-agent"          # the results' `solver` column (default: the class name)
        control = "absolute"       # or "delta": the gymnasium environment's normalised action
        images = "first"           # or "every_step": RGB-D on every observation, not only the first
        image_every = 1            # with "every_step": on every image_every-th step only (read after reset)

        def reset(self, episode: EpisodeInfo) -> None: ...
        def act(self, obs: dict) -> np.ndarray | None: ...   # None: done, score the state as it is

``obs`` holds exactly what the paper allows: ``instruction`` (text), the front camera's ``camera_K``
(3 x 3) and ``camera_pose`` (4 x 4, camera to world; columns right, up, backward), ``rgb`` (H x W x 3
uint8) and ``depth`` (H x W float32, metres) on the first step (every step with ``images =
"every_step"``; under a depth sensor the first step's depth fuses ``TaskConfig.depth_frames`` frames
of the still scene, as the planner's first image does), and the hand's own state: ``hand_qpos``,
``hand_qvel`` (finger joints, in ``hand_spec.joint_names`` order), ``root_pos``, ``root_quat``, ``root_vel`` (the free joint's
velocity), ``grasp_site_pos``, ``grasp_site_quat``, ``mocap_pos``, ``mocap_quat`` (the root pose
being commanded) and ``time`` (s). No cabinet joint, handle pose or target type is in it.

`PlannerAgent` is the benchmark's own planner as such an agent: a learned handle solver (CLIPort,
Faster R-CNN) or any solver object finds the handle in the first image; the planner then runs as a
coroutine (a thread that hands over one action per step), reading the hand's state from ``obs`` only.
"""

from __future__ import annotations

import queue
import threading
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from opend_mj.sim.hands import (
    HandSpec,
    grasp_pose_to_root_pose,
    touch_dict,
    touch_parts,
)

AGENT_CONTROLS = ("absolute", "delta")
AGENT_IMAGES = ("first", "every_step")


@dataclass(frozen=True)
class EpisodeInfo:
    """What an agent is told at the start of an episode (no ground truth)."""

    instruction: str
    hand: str
    hand_spec: HandSpec  # joint and actuator names, open pose, grasp profiles: the hand's own description
    camera_view: Any  # opend_mj.sim.camera.CameraView: intrinsics and pose of the front camera
    control_dt: float  # s per step (1/60)
    time_limit: float  # s of simulated time
    action_names: tuple[str, ...]
    action_low: np.ndarray = field(repr=False)
    action_high: np.ndarray = field(repr=False)
    seed: int = 0


class Agent(Protocol):
    name: str

    def reset(self, episode: EpisodeInfo) -> None:
        ...

    def act(self, obs: dict) -> np.ndarray | None:
        ...


def agent_name(agent) -> str:
    return str(getattr(agent, "name", None) or type(agent).__name__)


def agent_control(agent) -> str:
    control = getattr(agent, "control", "absolute")
    if control not in AGENT_CONTROLS:
        raise ValueError(f"agent {agent_name(agent)}: control must be one of {AGENT_CONTROLS}, not {control!r}")
    return control


def agent_images(agent) -> str:
    images = getattr(agent, "images", "first")
    if images not in AGENT_IMAGES:
        raise ValueError(f"agent {agent_name(agent)}: images must be one of {AGENT_IMAGES}, not {images!r}")
    return images


def agent_image_every(agent) -> int:
    """Control steps between the images of an ``images = "every_step"`` agent (its ``image_every``,
    default 1; read after each reset, so that an agent may set it from what it loaded)."""
    every = getattr(agent, "image_every", 1)
    if isinstance(every, bool) or not isinstance(every, (int, np.integer)) or every < 1:
        raise ValueError(f"agent {agent_name(agent)}: image_every must be an integer >= 1, not {every!r}")
    return int(every)


def wants_image(agent, step: int) -> bool:
    """Whether control step ``step`` (0: the first observation, which always has one) brings the agent RGB-D."""
    return step == 0 or (agent_images(agent) == "every_step" and step % agent_image_every(agent) == 0)


# --------------------------------------------------------------------------------------------------
# The planner as an agent
# --------------------------------------------------------------------------------------------------
class _Stop(BaseException):
    """Raised inside the planner's thread to end it (the episode was cut short)."""


class _ObservedRobot:
    """The planner's `Robot` interface over observations: reads ``obs``, hands actions to `act`."""

    def __init__(self, spec: HandSpec, control_dt: float, inbox: queue.Queue, outbox: queue.Queue):
        self.spec = spec
        self.control_dt = control_dt
        self.obs: dict = {}
        self.n_steps = 0
        self._inbox, self._outbox = inbox, outbox

    def look(self):
        """A depth image of this step where the observation carries one (``images = "every_step"``), else None."""
        depth = self.obs.get("depth")
        return None if depth is None else np.asarray(depth)

    @property
    def time(self) -> float:
        return float(self.obs["time"][0])

    def site_pose(self) -> tuple[np.ndarray, np.ndarray]:
        return self.obs["grasp_site_pos"].copy(), self.obs["grasp_site_quat"].copy()

    def site_pos(self) -> np.ndarray:
        return self.obs["grasp_site_pos"].copy()

    def finger_qpos(self) -> np.ndarray:
        return self.obs["hand_qpos"]

    def contact_touch(self) -> dict[str, float]:
        """What the hand feels per part (the ``touch`` observation; `opend_mj.sim.hands.HandTouch`).
        The observation does not say where a part is pressed, so a press on the floor counts here
        (the planner's own `Robot` leaves those out)."""
        return touch_dict(touch_parts(self.spec), self.obs["touch"])

    def step(self, site_pos, site_quat, fingers) -> None:
        root_pos, root_quat = grasp_pose_to_root_pose(self.spec, site_pos, site_quat)
        action = np.concatenate([np.asarray(root_pos, float), np.asarray(root_quat, float), np.asarray(fingers, float)])
        self._outbox.put(("action", action))
        message = self._inbox.get()
        if message is None:
            raise _Stop()
        self.obs = message
        self.n_steps += 1


class PlannerAgent:
    """The OpenD planner (locate, approach, close, pull) behind the agent interface.

    ``solver``: a registered handle solver that needs no ground truth (``cliport``, ``fasterrcnn``)
    or an object with ``solve(rgb, depth, instruction, camera_view)``. The oracle reads the
    simulator, so it is not an agent: run it with ``opend run --solver oracle``.
    """

    control = "absolute"
    images = "first"

    def __init__(self, solver: Any = "cliport", pull: str = "arc", use_grasp_file: bool = True,
                 name: str | None = None, **solver_options):
        if isinstance(solver, str):
            from opend_mj.policy.factory import agent_solver

            self._factory = agent_solver(solver, **solver_options)
            self._solver_name, self._solver = solver, None
        else:
            self._solver_name, self._solver = getattr(solver, "name", type(solver).__name__), solver
        self.pull = pull
        self.use_grasp_file = use_grasp_file
        self.name = name or f"planner-{self._solver_name}"
        self.result = None  # the planner's PlanResult of the last episode
        self._thread = None

    @property
    def solver(self):
        if self._solver is None:
            self._solver = self._factory()
        return self._solver

    def reset(self, episode: EpisodeInfo) -> None:
        from opend_mj.policy.factory import build_planner

        self._stop_thread()
        self._planner = build_planner(self.solver, episode.hand, pull=self.pull, use_grasp_file=self.use_grasp_file)
        self._episode = episode
        self.result = None

    def act(self, obs: dict) -> np.ndarray | None:
        if self._thread is None:
            if self.result is not None:
                return None  # the planner has finished
            self._start(obs)
        else:
            self._inbox.put(obs)
        kind, value = self._outbox.get()
        if kind == "action":
            return value
        self._thread.join()
        self._thread = None
        if kind == "error":
            raise value
        self.result = value
        return None

    def _start(self, obs: dict) -> None:
        from opend_mj.policy.planner import Observation

        self._inbox, self._outbox = queue.Queue(), queue.Queue()
        robot = _ObservedRobot(self._episode.hand_spec, self._episode.control_dt, self._inbox, self._outbox)
        robot.obs = obs
        first = Observation(rgb=obs["rgb"], depth=obs["depth"], instruction=obs["instruction"],
                            camera_view=self._episode.camera_view)

        def run():
            try:
                self._outbox.put(("done", self._planner.run(robot, first)))
            except _Stop:
                pass
            except Exception as exc:  # noqa: BLE001 (handed to the caller of act)
                self._outbox.put(("error", exc))

        self._thread = threading.Thread(target=run, name="planner-agent", daemon=True)
        self._thread.start()

    def _stop_thread(self) -> None:
        if self._thread is not None:
            self._inbox.put(None)
            self._thread.join()
            self._thread = None

    def episode_info(self) -> dict:
        """Extra fields for the episode's record (the planner's own view of what happened)."""
        r = self.result
        if r is None:
            return {"planner_failed_stage": "time_limit"}
        return {"planner_failed_stage": r.failed_stage, "box": r.box["box"] if r.box else None,
                "pulled": round(r.pulled, 4), "turned_deg": round(r.turned_deg, 2)}

    def close(self) -> None:
        self._stop_thread()
