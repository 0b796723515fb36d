"""The project's physics options: one definition for the task, the rooms and the hand scenes.

Starting points known to work for friction grasps with dexterous hands in MuJoCo: implicitfast
integration, elliptic friction cones, impratio 10, and a step of 1/480 s (eight substeps per 60 Hz
control step). noslip is off (dm_control's base arena turns on 5 iterations).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class PhysicsOptions:
    """MJCF ``<option>`` values shared by every scene the project builds."""

    timestep: float = 1.0 / 480.0
    integrator: str = "implicitfast"
    cone: str = "elliptic"
    impratio: float = 10.0
    noslip_iterations: int = 0

    def apply(self, mjcf_root) -> None:
        """Write the options into an mjcf RootElement (or anything with an ``option`` element)."""
        option = mjcf_root.option
        option.timestep = self.timestep
        option.integrator = self.integrator
        option.cone = self.cone
        option.impratio = self.impratio
        option.noslip_iterations = int(self.noslip_iterations)


#: The defaults, for scenes that take no options of their own.
PHYSICS = PhysicsOptions()
