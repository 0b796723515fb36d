"""Reference implementations: the straightforward ways of doing what the production code does
faster, kept only so that tests can compare the two, bit for bit.

The production step of the environments over the dataset (`sim.envs.OpenDCore.step`) runs in
compiled code (`sim.fast`) where it loads, else in the Python step that gives the same numbers
(`tests/sim/test_compiled_step.py` compares the two). `ReferenceStep` (``EnvConfig(lean_step=False)``)
is the step as one would first write it: the task's action from the delta action written out with
numpy (`ActionAdapter.from_delta_reference`), the episode's dm_env environment's step
(`environment.OpenDEnvironment.step`), and every observation and reward term read on its own
(`SceneReader.proprio`, `RewardProbe.terms`); `tests/sim/test_lean_step.py` compares the production
step with it. The smaller references sit beside what they check and are named for it:
`mocap_path.plan_reference`, `RewardProbe.distance_reference`, `RewardProbe.handle_box_reference`,
the touch sensor's `vector_reference`.
"""

from __future__ import annotations

import numpy as np

from opend_mj.language.onehot import instruction_onehot
from opend_mj.sim.rewards import RewardTerms


class ReferenceStep:
    """The reference step and observation of an `OpenDCore` (its current scene and episode)."""

    def __init__(self, core):
        self.core = core

    def native_action(self, action) -> np.ndarray:
        """The task's own action for ``action`` in the environment's control mode."""
        core = self.core
        if core.config.control == "absolute":
            return np.asarray(action, dtype=np.float64)
        d, mid = core.scene._data, core.scene._mocap
        return core.adapter.from_delta_reference(action, d.mocap_pos[mid], d.mocap_quat[mid])

    def step(self, action) -> tuple[bool, RewardTerms]:
        """One control step through the episode's dm_env environment: (the time ran out, reward terms)."""
        scene = self.core.scene
        last = scene.env.step(self.native_action(action)).last()
        return last, scene.probe.terms()

    def terms(self) -> RewardTerms:
        return self.core.scene.probe.terms()

    def observe(self, dtype) -> dict:
        """Every float observation read on its own (the images and the text instruction aside)."""
        core = self.core
        c, scene = core.config, core.scene
        obs = {key: np.asarray(v, dtype=dtype) for key, v in scene.proprio().items()}
        if c.instruction == "onehot":
            obs["instruction"] = instruction_onehot(core.episode.instruction).astype(dtype)
        if c.obs_mode != "state":
            obs.update({k: v.astype(dtype) for k, v in scene.camera_arrays().items()})
        if c.privileged:
            obs.update({k: np.asarray(v, dtype=dtype) for k, v in scene.privileged().items()})
        return obs
