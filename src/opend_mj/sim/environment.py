"""The environment of one episode (`OpenDEnvironment`, what `sim.task.make_environment` builds and
`opend run` drives), and the MuJoCo instability warnings that end an episode.

composer builds, compiles and resets the scene; the control step is the task's own
(`OpenCabinetTask.control_step`: the compiled step where it loads, else the Python step, the same
numbers), not composer's loop of per-substep hooks.
"""

from __future__ import annotations

import collections
import math

import dm_env
import mujoco
import numpy as np
from dm_control import composer

#: The MuJoCo warnings that mean the simulation went unstable: they end the episode.
INSTABILITY_WARNINGS = (mujoco.mjtWarning.mjWARN_BADQACC, mujoco.mjtWarning.mjWARN_BADQPOS,
                        mujoco.mjtWarning.mjWARN_BADQVEL)
WARNING_NAMES = [w.name for w in INSTABILITY_WARNINGS]
#: their mjtWarning numbers (the compiled step's order of status bits)
WARNING_IDS = [int(w) for w in INSTABILITY_WARNINGS]
#: the counters of MjData.warning from the first instability warning to the last (a view of them),
#: and each instability warning's position in it (`INSTABILITY_WARNINGS` order)
WARNING_SLICE = slice(min(WARNING_IDS), max(WARNING_IDS) + 1)
WARNING_POSITIONS = [(name, i - min(WARNING_IDS)) for name, i in zip(WARNING_NAMES, WARNING_IDS)]

_STEP_HOOKS = ("before_step", "before_substep", "after_substep", "after_step")


def warning_names(bits: int) -> list[str]:
    """The instability warnings whose bits are set (bit k: the k-th of `INSTABILITY_WARNINGS`; the
    compiled step's status bits)."""
    return [name for k, name in enumerate(WARNING_NAMES) if bits >> k & 1] if bits else []


class OpenDEnvironment(composer.Environment):
    """A composer Environment whose control step is the task's (`OpenCabinetTask.control_step`).

    composer builds and compiles the scene and resets episodes (`reset`, through the task's and the
    entities' hooks). `step` runs the task's control step: its action handling and every substep in
    one tight loop or one compiled call, the same trajectory as composer's loop of per-substep hooks
    (`tests/sim/test_task.py` compares them), several times faster. The entities of this task have no
    step hooks of their own (checked when the environment is made). Each enabled observable is read
    once per control step; one with a buffer, a delay, an update interval or an aggregator is refused.
    With ``observations=False`` `step` returns an empty observation (for callers that read MjData
    themselves; `reset` still observes). The MJCF never changes between episodes of one task, so a
    reset does not recompile it. A MuJoCo instability warning (or a NaN in the state) is recorded in
    ``task.physics_warnings`` and ends the episode with reward and discount 0.
    """

    def __init__(self, task, *, time_limit: float = float("inf"), observations: bool = True, **kwargs):
        kwargs.setdefault("recompile_mjcf_every_episode", False)
        for entity in task.root_entity.iter_entities():
            hooked = [h for h in _STEP_HOOKS if getattr(type(entity), h) is not getattr(composer.Entity, h)]
            if hooked:
                raise ValueError(f"{type(entity).__name__} has step hooks ({', '.join(hooked)}) that "
                                 "OpenDEnvironment's step does not call: step it with composer.Environment")
        if type(task).after_step is not composer.Task.after_step:
            raise ValueError(f"{type(task).__name__}.after_step is not called by OpenDEnvironment's step")
        super().__init__(task, time_limit=time_limit, **kwargs)
        #: simulated seconds after which an episode ends
        self.time_limit = float(time_limit)
        #: False: `step` returns an empty observation
        self.step_observations = bool(observations)
        self._strip_buffer = bool(kwargs.get("strip_singleton_obs_buffer_dim", False))
        # The constructor has just compiled the model and nothing changes it per episode: the first
        # reset need not compile it again (composer's own flag for that).
        self._mjcf_never_compiled = self._recompile_mjcf_every_episode
        self._readers: list = []
        self._episode_over = True

    def reset(self) -> dm_env.TimeStep:
        timestep = super().reset()
        self._readers = self._make_readers() if self.step_observations else []
        self._episode_over = False
        return timestep

    def _make_readers(self) -> list:
        """(name, callable) of every enabled observable, each read once per control step."""
        readers = []
        for name, obs in self.task.observables.items():
            if not obs.enabled:
                continue
            if (obs.update_interval not in (None, 1) or obs.delay not in (None, 0)
                    or obs.buffer_size not in (None, 1) or obs.aggregator is not None):
                raise ValueError(f"observable {name!r} has a buffer, delay, update interval or aggregator: "
                                 "OpenDEnvironment reads each observable once per control step")
            readers.append((name, obs.observation_callable(self.physics, self.random_state)))
        return readers

    def step(self, action) -> dm_env.TimeStep:
        if self._episode_over:
            return self.reset()
        task, physics = self.task, self.physics
        warnings = task.control_step(physics, action)
        if self._strip_buffer:
            obs = collections.OrderedDict((name, np.array(read())) for name, read in self._readers)
        else:
            obs = collections.OrderedDict((name, np.array(read())[None]) for name, read in self._readers)
        data = physics.data.ptr
        if warnings or (not math.isfinite(float(data.qpos.dot(data.qpos))) and not np.isfinite(data.qpos).all()):
            task.physics_warnings.append({"time": float(data.time), "warnings": warnings or ["NaN"]})
            reward, discount, terminating = 0.0, 0.0, True
        else:
            reward = task.get_reward(physics)
            discount = task.get_discount(physics)
            terminating = task.should_terminate_episode(physics) or data.time >= self.time_limit
        if not terminating:
            return dm_env.TimeStep(dm_env.StepType.MID, reward, discount, obs)
        self._episode_over = True
        return dm_env.TimeStep(dm_env.StepType.LAST, reward, discount, obs)
