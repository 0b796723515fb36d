"""The OpenD planner: locate -> perceive -> grasp -> approach -> close and verify -> pull -> check.

Inputs the planner may use (nothing else): one RGB-D image of the front camera and its intrinsics
and pose (:class:`~opend_mj.sim.camera.CameraView`), the instruction, and the hand's own state (its
grasp-site and root pose, its finger joints, its touch sensors). It never reads the cabinet's
joints, the target's kind or handle from ``cabinet.json``: door vs drawer comes from the
instruction's last word, the handle from the handle solver's box and the depth image. The hand
root moves only through the task action (a mocap target that follows at bounded speed); the
fingers hold the handle by contact and friction. Everything but the handle solver is deterministic.

Pull modes (``PlannerConfig.pull``): ``"straight"`` (the paper's) pulls every part straight back
along -x (the approach axis). ``"arc"`` (default) pulls drawers straight along -x and doors along
their handle's circle: about the hinge seen in depth (``DoorConfig.hinge_pull``) where one is
seen, else along the direction the handle is observed to move; the hand's yaw turns with the
pull so that the grip does not twist (:mod:`.pull`).

Modules: :mod:`.config` (the configuration), :mod:`.hand` (per-hand files), :mod:`.records`,
:mod:`.robot` (the environment adapter), :mod:`.loop` (the stage loop, :class:`Planner`),
:mod:`.grasp` (grasp geometry), :mod:`.approach` (approach, close, verify), :mod:`.pull`,
:mod:`.kind` (the kind check), :mod:`.recovery` (push recovery).
"""

from opend_mj.policy.planner.config import (
    ApproachConfig,
    DoorConfig,
    GraspConfig,
    KindConfig,
    LocateConfig,
    PlannerConfig,
    PullConfig,
    RecoveryConfig,
    VerifyConfig,
)
from opend_mj.policy.planner.hand import GRASP_FILE, PLANNER_FILE, GraspProfile, HandPlannerConfig
from opend_mj.policy.planner.loop import Planner
from opend_mj.policy.planner.records import (
    STAGES,
    EpisodeState,
    GraspChoice,
    Observation,
    PlanResult,
    PullState,
)
from opend_mj.policy.planner.recovery import fit_circle_xy
from opend_mj.policy.planner.robot import Robot

__all__ = [
    "GRASP_FILE", "PLANNER_FILE", "STAGES", "ApproachConfig", "DoorConfig", "EpisodeState", "GraspChoice",
    "GraspConfig", "GraspProfile", "HandPlannerConfig", "KindConfig", "LocateConfig", "Observation",
    "PlanResult", "Planner", "PlannerConfig", "PullConfig", "PullState", "RecoveryConfig", "Robot",
    "VerifyConfig", "fit_circle_xy",
]
