"""Teleoperation of the hand: a headless controller that turns key presses into task actions.

The window (``opend_mj.apps.viewer``) only forwards key codes and gamepad axes to a
:class:`TeleopController` and draws :meth:`TeleopController.status_lines`; everything else lives here,
so tests drive a whole episode with scripted key events and no display.

Key map (keys are case-insensitive; GLFW key codes from ``mujoco.viewer`` are accepted too)::

    W / S        hand forward / back       (+x / -x world: toward / away from the cabinet)
    A / D        hand left / right         (+y / -y world: "left" in the camera image is +y)
    R / F        hand up / down            (+z / -z world)
    Q / E        yaw left / right          (about world z)
    UP / DOWN    pitch                     (about world y)
    LEFT / RIGHT roll                      (about world x, the approach axis)
    SPACE        grip: toggle close / open (the grip ramps over the hand's close_time)
    G            grasp profile: toggle horizontal / vertical (the hand turns to match)
    [ / ]        step size: halve / double (translation and rotation together)
    ENTER        end the episode (the success check is read)
    BACKSPACE    reset the episode

The grip is a scalar in [0, 1]: finger targets = open_pose + grip * (grasp_profile - open_pose), with
the grasp profile of the current orientation (``spec.grasp_profiles["horizontal" | "vertical"]``).
Each key press moves the root *target* by one step; the task's mocap follows at bounded speed.

A gamepad (see :func:`gamepad_motion`) moves the target continuously: left stick x/y, right stick
z/yaw, triggers or shoulder buttons pitch; button A = SPACE, B = G, START = ENTER, BACK = BACKSPACE.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from typing import Callable, Iterable

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402

# opend_mj.sim.hands (dm_control) is imported where used: `opend teleop --help` stays light.

#: key name -> command. Several keys may map to one command.
KEYMAP: dict[str, str] = {
    "w": "forward", "s": "back", "a": "left", "d": "right", "r": "up", "f": "down",
    "q": "yaw_left", "e": "yaw_right",
    "up": "pitch_up", "down": "pitch_down", "left": "roll_left", "right": "roll_right",
    "space": "grip", "g": "profile", "[": "step_down", "]": "step_up",
    "enter": "done", "backspace": "reset",
}

#: human-readable key map (used by ``opend teleop --help`` and the on-screen help).
KEY_HELP = (
    ("W / S", "forward / back (x)"),
    ("A / D", "left / right (y)"),
    ("R / F", "up / down (z)"),
    ("Q / E", "yaw"),
    ("UP / DOWN", "pitch"),
    ("LEFT / RIGHT", "roll"),
    ("SPACE", "grip close / open (ramps)"),
    ("G", "toggle horizontal / vertical grasp profile"),
    ("[ / ]", "step size smaller / larger"),
    ("ENTER", "end episode (success check)"),
    ("BACKSPACE", "reset episode"),
)

#: GLFW key codes (what ``mujoco.viewer``'s key_callback receives) for the non-printable keys.
GLFW_KEYS: dict[int, str] = {32: "space", 257: "enter", 335: "enter", 259: "backspace", 262: "right",
                             263: "left", 264: "down", 265: "up"}

_ALIASES = {" ": "space", "return": "enter", "kp_enter": "enter", "\n": "enter", "\r": "enter",
            "back_space": "backspace", "\b": "backspace", "arrowup": "up", "arrowdown": "down",
            "arrowleft": "left", "arrowright": "right"}

#: translation direction (world) per command, and rotation axis (world) and sign per command.
_TRANSLATE = {"forward": (1, 0, 0), "back": (-1, 0, 0), "left": (0, 1, 0), "right": (0, -1, 0),
              "up": (0, 0, 1), "down": (0, 0, -1)}
_ROTATE = {"yaw_left": ((0, 0, 1), 1), "yaw_right": ((0, 0, 1), -1),
           "pitch_up": ((0, 1, 0), -1), "pitch_down": ((0, 1, 0), 1),
           "roll_left": ((1, 0, 0), -1), "roll_right": ((1, 0, 0), 1)}


def key_name(key) -> str | None:
    """Normalise a key: a GLFW key code (int) or a name ("w", "SPACE", "Up") -> a KEYMAP name."""
    if isinstance(key, (int, np.integer)):
        key = int(key)
        if key in GLFW_KEYS:
            return GLFW_KEYS[key]
        if 33 <= key <= 126:
            return chr(key).lower()
        return None
    if not isinstance(key, str) or not key:
        return None
    name = key if key in _ALIASES else key.strip().lower()
    return _ALIASES.get(name, name)


@dataclass
class TeleopConfig:
    """Step sizes of the controller."""

    step: float = 0.01  # m per key press
    rot_step: float = np.deg2rad(5.0)  # rad per key press (scales with ``step``)
    min_step: float = 0.00125
    max_step: float = 0.08
    profile: str = "horizontal"  # grasp profile at reset
    #: gamepad: full stick deflection moves this fast (m/s, rad/s); deflections under dead_zone count as 0.
    pad_speed: float = 0.25
    pad_angular_speed: float = 1.0
    dead_zone: float = 0.15


class TeleopController:
    """Keys -> hand root target, grip and episode events; :meth:`step` advances the environment.

    ``env`` is a composer Environment from :func:`opend_mj.sim.task.make_environment`. ``recorder`` (a
    :class:`opend_mj.apps.demos.DemoRecorder` or anything with ``start(env, timestep)``,
    ``add(action, timestep_before)``) records every step taken through :meth:`step`.
    """

    def __init__(self, env, config: TeleopConfig | None = None, recorder=None):
        self.env = env
        self.config = config or TeleopConfig()
        self.recorder = recorder
        self.timestep = None
        self.reset()

    # ------------------------------------------------------------------ state
    @property
    def task(self):
        return self.env.task

    @property
    def physics(self):
        return self.env.physics

    @property
    def spec(self):
        return self.task.hand.spec

    @property
    def control_dt(self) -> float:
        return 1.0 / self.task.config.control_hz

    def reset(self) -> None:
        """Reset the environment and the controller (start pose, grip open, default profile)."""
        self.timestep = self.env.reset()
        pos, quat = self.task.start_pose
        self.target_pos = np.array(pos, float)
        self.target_quat = np.array(quat, float)
        self.grip = 0.0
        self.grip_goal = 0.0
        self.profile = self.config.profile
        self.step_size = self.config.step
        self.done = False
        self.steps = 0
        self.started = time.perf_counter()
        self.last_command: str | None = None
        if self.recorder is not None:
            self.recorder.start(self.env, self.timestep)

    # ------------------------------------------------------------------ input
    def handle_key(self, key) -> str | None:
        """Apply one key press; returns the command it triggered (None for an unmapped key)."""
        command = KEYMAP.get(key_name(key) or "")
        if command is None:
            return None
        self.last_command = command
        rot_step = self.config.rot_step * self.step_size / self.config.step
        if command in _TRANSLATE:
            self.target_pos = self.target_pos + self.step_size * np.asarray(_TRANSLATE[command], float)
        elif command in _ROTATE:
            axis, sign = _ROTATE[command]
            self.rotate(axis, sign * rot_step)
        elif command == "grip":
            self.grip_goal = 0.0 if self.grip_goal > 0.5 else 1.0
        elif command == "profile":
            from opend_mj.sim.hands import orientation_for_handle

            self.profile = "vertical" if self.profile == "horizontal" else "horizontal"
            self.target_quat = orientation_for_handle(self.profile)
        elif command == "step_down":
            self.step_size = max(self.config.min_step, self.step_size / 2)
        elif command == "step_up":
            self.step_size = min(self.config.max_step, self.step_size * 2)
        elif command == "done":
            self.done = True
        elif command == "reset":
            self.reset()
        return command

    def rotate(self, axis, angle: float) -> None:
        """Turn the root target by ``angle`` about a world axis (through the root)."""
        from opend_mj.transforms import axis_angle_quat, quat_mul

        q = quat_mul(axis_angle_quat(axis, angle), self.target_quat)
        self.target_quat = q / np.linalg.norm(q)

    def move(self, dpos=(0.0, 0.0, 0.0), drot=(0.0, 0.0, 0.0)) -> None:
        """Continuous input (gamepad): translate by ``dpos`` (m), rotate by ``drot`` (rad about world x, y, z)."""
        self.target_pos = self.target_pos + np.asarray(dpos, float)
        drot = np.asarray(drot, float)
        angle = float(np.linalg.norm(drot))
        if angle > 1e-12:
            self.rotate(drot / angle, angle)

    # ------------------------------------------------------------------ output
    def finger_targets(self, grip: float | None = None) -> np.ndarray:
        grip = self.grip if grip is None else grip
        open_pose = np.asarray(self.spec.open_pose, float)
        return open_pose + float(np.clip(grip, 0, 1)) * (self.spec.grasp_profile(self.profile) - open_pose)

    def action(self) -> np.ndarray:
        """The task action for the current state (root target pose + finger targets)."""
        lo, hi = self.task._workspace
        self.target_pos = np.clip(self.target_pos, lo, hi)  # never let the target run off the workspace
        return self.task.make_action(self.target_pos, self.target_quat, self.finger_targets())

    def _ramp_grip(self) -> None:
        rate = self.control_dt / max(float(self.spec.close_time), 1e-6)
        self.grip = float(np.clip(self.grip + np.clip(self.grip_goal - self.grip, -rate, rate), 0.0, 1.0))

    def step(self, n: int = 1):
        """Advance ``n`` control steps (the grip ramps one increment per step). Returns the last timestep."""
        for _ in range(int(n)):
            self._ramp_grip()
            action = self.action()
            before = self.timestep
            self.timestep = self.env.step(action)
            self.steps += 1
            if self.recorder is not None:
                self.recorder.add(action, before)
            if self.timestep.last():  # time limit: the episode ends by itself
                self.done = True
                break
        return self.timestep

    def apply(self, events: Iterable) -> list:
        """Run a script: keys (names or GLFW codes) are pressed, ``("step", n)`` / ``("wait", n)``
        advances n control steps, ``("wait_s", seconds)`` advances by simulated seconds.
        Stops at ENTER (or the time limit). Returns the command of each event (None for steps)."""
        out = []
        for ev in events:
            if isinstance(ev, tuple):
                kind, n = ev
                if kind == "wait_s":
                    n = int(round(n / self.control_dt))
                elif kind not in ("step", "wait"):
                    raise ValueError(f"unknown event {ev!r}")
                self.step(n)
                out.append(None)
            else:
                out.append(self.handle_key(ev))
            if self.done:
                break
        return out

    def outcome(self):
        return self.task.outcome(self.physics)

    def status_lines(self) -> list[tuple[str, str]]:
        """(label, value) rows for the on-screen overlay."""
        o = self.outcome()
        return [
            ("instruction", self.task.instruction),
            ("open ratio", f"{o.open_ratio:.1%}" + ("  SUCCESS" if o.success else "")),
            ("grip", f"{self.grip:.2f} -> {self.grip_goal:.0f} ({self.profile})"),
            ("step", f"{self.step_size * 100:.2g} cm"),
            ("time", f"{self.physics.data.time:.1f} s"),
        ]


def steps(n: int) -> tuple[str, int]:
    """Script event: advance n control steps."""
    return ("step", int(n))


def presses(key: str, n: int) -> list[str]:
    """Script events: press ``key`` n times (negative n: nothing)."""
    return [key] * max(0, int(n))


# --------------------------------------------------------------------------------------------------
# Gamepad (axes/buttons as pygame reports them for an Xbox-style pad)
# --------------------------------------------------------------------------------------------------
PAD_BUTTONS = {0: "space", 1: "g", 7: "enter", 6: "backspace", 4: "[", 5: "]"}


def gamepad_motion(axes, dt: float, config: TeleopConfig = TeleopConfig()) -> tuple[np.ndarray, np.ndarray]:
    """Gamepad axes -> (dpos, drot) for one control step of ``dt`` seconds.

    Axes (pygame, Xbox layout): 0 left x, 1 left y (down +), 2 left trigger, 3 right x, 4 right y,
    5 right trigger (triggers rest at -1). Left stick: forward/back (x) and left/right (y); right
    stick: up/down (z) and yaw; triggers: pitch."""
    a = np.zeros(6)
    a[: min(6, len(axes))] = np.asarray(axes, float)[:6]

    def dz(v):
        return 0.0 if abs(v) < config.dead_zone else float(v)

    v, w = config.pad_speed * dt, config.pad_angular_speed * dt
    dpos = np.array([-dz(a[1]) * v, -dz(a[0]) * v, -dz(a[4]) * v])
    lt, rt = (a[2] + 1) / 2 if len(axes) > 2 else 0.0, (a[5] + 1) / 2 if len(axes) > 5 else 0.0
    drot = np.array([0.0, dz(rt - lt) * w, -dz(a[3]) * w])
    return dpos, drot


class Gamepad:
    """The first joystick pygame finds, or None from :meth:`open` (pygame is an optional import)."""

    def __init__(self, joystick, pygame_module):
        self._js = joystick
        self._pg = pygame_module
        self._pressed: set[int] = set()

    @classmethod
    def open(cls) -> "Gamepad | None":
        try:
            os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
            import pygame
        except ImportError:
            return None
        try:
            pygame.init()
            pygame.joystick.init()
            if pygame.joystick.get_count() == 0:
                return None
            js = pygame.joystick.Joystick(0)
            js.init()
            return cls(js, pygame)
        except Exception:  # noqa: BLE001 (no usable device: keyboard only)
            return None

    @property
    def name(self) -> str:
        return self._js.get_name()

    def poll(self) -> tuple[list[float], list[str]]:
        """Current axes and the keys of buttons newly pressed since the last poll."""
        self._pg.event.pump()
        axes = [self._js.get_axis(i) for i in range(self._js.get_numaxes())]
        keys = []
        now = {i for i in range(self._js.get_numbuttons()) if self._js.get_button(i)}
        for b in sorted(now - self._pressed):
            if b in PAD_BUTTONS:
                keys.append(PAD_BUTTONS[b])
        self._pressed = now
        return axes, keys


# --------------------------------------------------------------------------------------------------
# The human study (`opend teleop --study N`)
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class StudyTask:
    cabinet: str
    cabinet_dir: str
    joint: str
    type: str
    split: str
    seed: int


def sample_study(cabinets_dir, n: int, seed: int = 0, split: str = "test") -> list[StudyTask]:
    """N (cabinet, target) pairs drawn at random from a split of the manifest, seeded (as the
    paper's human study: random cabinets and targets of the test split). Without replacement while
    the split has enough targets."""
    from pathlib import Path

    from opend_mj.assets.layout import load_manifest

    cabinets_dir = Path(cabinets_dir)
    pairs = load_manifest(cabinets_dir).targets(split)
    if not pairs:
        raise ValueError(f"{cabinets_dir}: no targets in split {split!r}")
    rng = np.random.default_rng([seed, 8])
    idx = rng.choice(len(pairs), size=n, replace=n > len(pairs))
    tasks = []
    for i, k in enumerate(idx):
        cab, tgt = pairs[int(k)]
        cab_dir = cabinets_dir / cab.get("path", cab["id"])
        tasks.append(StudyTask(cabinet=cab["id"], cabinet_dir=str(cab_dir), joint=tgt["joint"],
                               type=tgt["type"], split=cab["split"], seed=seed + i))
    return tasks


def episode_record(controller: TeleopController, *, cabinet: str, split: str, solver: str = "human",
                   wall_seconds: float | None = None) -> dict:
    """One results line in the `opend run` format (solver ``human``), from a finished episode."""
    task, physics = controller.task, controller.physics
    o = task.outcome(physics)
    ep = task.episode
    return {
        "cabinet": cabinet, "joint": task.target.joint, "type": task.target.kind,
        "target_type": task.target.kind, "instruction": task.instruction, "hand": ep.hand,
        "solver": solver, "split": split, "seed": int(ep.seed), "light_scale": float(task.config.light_scale),
        "room": int(ep.room_index()), "success": bool(o.success), "open_ratio": float(o.open_ratio),
        "range_ratio": float(o.range_ratio), "joint_value": float(o.joint_value),
        "others_moved": list(o.others_moved), "failed_stage": None if o.success else "pull",
        "sim_seconds": round(float(physics.data.time), 3),
        "wall_seconds": round(float(wall_seconds if wall_seconds is not None
                                    else time.perf_counter() - controller.started), 3),
        "cabinet_dir": str(ep.cabinet_dir),
    }


def teleop_config(**overrides):
    """The task config for teleoperation: no camera observables (the viewer draws the scene), no
    practical time limit (the person ends the episode with ENTER)."""
    from opend_mj.sim.task import TaskConfig

    return TaskConfig(**{"enable_rgbd": False, "time_limit": 1e6, **overrides})


def run_study(tasks: list[StudyTask], hand: str, play: Callable[[TeleopController], None], out,
              *, task_config=None, teleop: TeleopConfig | None = None, recorder_factory=None,
              room: int | None = None) -> list[dict]:
    """Run each study task: build the env, let ``play(controller)`` drive it (a window loop, or a
    script in tests) until it returns, then append the `opend run` record to ``out`` (JSONL)."""
    from pathlib import Path

    from opend_mj.sim.task import EpisodeSpec, make_environment

    records = []
    config = task_config or teleop_config()
    for t in tasks:
        env = make_environment(EpisodeSpec(Path(t.cabinet_dir), t.joint, hand, seed=t.seed, room=room), config)
        try:
            recorder = recorder_factory() if recorder_factory else None
            ctl = TeleopController(env, teleop, recorder=recorder)
            play(ctl)
            rec = episode_record(ctl, cabinet=t.cabinet, split=t.split)
            if recorder is not None and hasattr(recorder, "finish"):
                recorder.finish(ctl)
        finally:
            env.close()
        write_record(out, rec)
        records.append(rec)
    return records


def write_record(out, record: dict) -> None:
    """Append one JSON line (the results writer of `opend run` when available)."""
    from pathlib import Path

    try:
        from opend_mj.evaluation.results import ResultsWriter
    except ImportError:  # evaluation not available: same format, written here
        ResultsWriter = None
    if ResultsWriter is not None:
        with ResultsWriter(Path(out)) as w:
            w.write(record)
        return
    import json

    path = Path(out)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a") as f:
        f.write(json.dumps(record) + "\n")
        f.flush()
        os.fsync(f.fileno())


__all__ = ["GLFW_KEYS", "Gamepad", "KEYMAP", "KEY_HELP", "StudyTask", "TeleopConfig", "TeleopController",
           "episode_record", "gamepad_motion", "key_name", "presses", "run_study", "sample_study", "steps",
           "teleop_config", "write_record"]
