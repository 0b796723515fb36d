"""Thin window glue: MuJoCo's passive viewer around a task environment (needs a display).

All logic is in :mod:`opend_mj.apps.teleop` (tested headless); this module only opens
``mujoco.viewer.launch_passive`` on the environment's MjModel/MjData, forwards key codes (and
gamepad input, when pygame finds one) to the controller, steps it in real time and draws the
instruction and live open ratio as overlay text.

The viewer needs an on-screen GL context: run with ``MUJOCO_GL`` unset or ``glfw`` (the package
defaults to ``egl`` for headless rendering; :func:`require_display` switches it back before
mujoco is imported by the command).

MuJoCo's viewer has its own single-key shortcuts (W wireframe, S shadow, R reflection, E equality,
F contact force, ...). Where ``launch_passive`` accepts ``handle_keyboard=False`` (newer MuJoCo)
they are switched off; otherwise the visualisation flags (``opt.flags`` and the scene's render
flags) are restored after every key press, so teleop keys do not leave them toggled.
"""

from __future__ import annotations

import inspect
import os
import queue
import sys
import time


def require_display() -> None:
    """Make the next ``import mujoco`` use an on-screen context (call before any mujoco import)."""
    # The viewer makes its own GLFW window whatever MUJOCO_GL says; MUJOCO_GL only picks the
    # off-screen backend of dm_control, which must then match the window's (GLFW) on import.
    if os.environ.get("MUJOCO_GL", "").lower() in ("egl", "osmesa") and "mujoco" not in sys.modules:
        os.environ["MUJOCO_GL"] = "glfw"
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise RuntimeError("no display (DISPLAY / WAYLAND_DISPLAY unset): the interactive viewer needs a window")


class _FlagGuard:
    """Snapshot of the viewer's visualisation flags, restored after teleop key presses."""

    def __init__(self, handle):
        self.handle = handle
        self.opt = handle.opt.flags.copy()
        sim = handle._get_sim() if hasattr(handle, "_get_sim") else None
        scn = getattr(sim, "scn", None)
        self.scn = scn
        self.render = scn.flags.copy() if scn is not None else None

    def restore(self) -> None:
        self.handle.opt.flags[:] = self.opt
        if self.scn is not None and self.render is not None:
            try:
                self.scn.flags[:] = self.render
            except Exception:  # noqa: BLE001 (best effort)
                pass


def launch(physics, key_callback=None):
    """``launch_passive`` on a dm_control Physics; built-in key shortcuts off where supported."""
    import mujoco.viewer

    kwargs = {}
    params = inspect.signature(mujoco.viewer.launch_passive).parameters
    if key_callback is not None and "handle_keyboard" in params:
        kwargs["handle_keyboard"] = False
    return mujoco.viewer.launch_passive(physics.model.ptr, physics.data.ptr, key_callback=key_callback, **kwargs)


def _set_texts(handle, rows) -> None:
    import mujoco

    if not hasattr(handle, "set_texts"):
        return
    left = "\n".join(r[0] for r in rows)
    right = "\n".join(r[1] for r in rows)
    handle.set_texts([(mujoco.mjtFontScale.mjFONTSCALE_150, mujoco.mjtGridPos.mjGRID_TOPLEFT, left, right)])


def _pace(t_wall0: float, sim_elapsed: float) -> None:
    ahead = sim_elapsed - (time.perf_counter() - t_wall0)
    if ahead > 0:
        time.sleep(min(ahead, 0.1))


def view(env) -> None:
    """Show a task scene: the hand holds its start pose, the instruction in the overlay."""
    task = env.task
    env.reset()
    print(f"instruction: {task.instruction}", flush=True)
    handle = launch(env.physics)
    action = task.make_action(*task.start_pose, task.hand.spec.open_pose)
    dt = 1.0 / task.config.control_hz
    t0, n = time.perf_counter(), 0
    try:
        while handle.is_running():
            with handle.lock():
                env.step(action)
            n += 1
            o = task.outcome(env.physics)
            _set_texts(handle, [("instruction", task.instruction), ("open ratio", f"{o.open_ratio:.1%}")])
            handle.sync()
            _pace(t0, n * dt)
    finally:
        handle.close()


def teleop(controller, gamepad: bool = True) -> bool:
    """Run one episode interactively until ENTER or the window closes.

    Returns False if the window was closed before ENTER (episode aborted). A reset (BACKSPACE)
    recompiles the model (composer does so on every reset), so the window is reopened on it."""
    from opend_mj.apps.teleop import KEY_HELP, Gamepad, gamepad_motion

    pad = Gamepad.open() if gamepad else None
    if pad is not None:
        print(f"gamepad: {pad.name}", flush=True)
    print(f"instruction: {controller.task.instruction}", flush=True)
    print("keys: " + "; ".join(f"{k} {v}" for k, v in KEY_HELP), flush=True)
    dt = controller.control_dt
    while not controller.done:
        keys: queue.SimpleQueue = queue.SimpleQueue()
        physics = controller.physics
        handle = launch(physics, key_callback=keys.put)
        guard = _FlagGuard(handle)
        t0, n, last_ratio = time.perf_counter(), 0, -1.0
        try:
            while not controller.done and controller.physics is physics:
                if not handle.is_running():
                    return False
                pressed = []
                while True:
                    try:
                        pressed.append(keys.get_nowait())
                    except queue.Empty:
                        break
                if pad is not None:
                    axes, pad_keys = pad.poll()
                    pressed += pad_keys
                    controller.move(*gamepad_motion(axes, dt, controller.config))
                with handle.lock():
                    for k in pressed:
                        controller.handle_key(k)
                    if controller.done or controller.physics is not physics:
                        break
                    controller.step()
                if pressed:
                    guard.restore()
                n += 1
                _set_texts(handle, controller.status_lines())
                ratio = controller.outcome().open_ratio
                if abs(ratio - last_ratio) > 0.01:
                    print(f"\ropen ratio {ratio:6.1%}", end="", flush=True)
                    last_ratio = ratio
                handle.sync()
                _pace(t0, n * dt)
        finally:
            print("", flush=True)
            try:
                handle.close()
            except Exception:  # noqa: BLE001
                pass
    return True
