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

Modules: :mod:`.config` (the configuration, one section per stage), :mod:`.records` (what the
planner sees, chooses and keeps), :mod:`.robot` (the environment adapter), :mod:`.stage` (what
every stage is given), :mod:`.loop` (:class:`Planner`: the short loop over the stages), the stages
:mod:`.grasp` (:class:`Grasping`), :mod:`.approach` (:class:`Approach`: approach, close, verify),
:mod:`.pull` (:class:`Pulling`) with :mod:`.flap` and :mod:`.slide` (its variants), :mod:`.kind`
(:class:`KindCheck`, :class:`FrontWatch`), :mod:`.recovery` (:class:`PushRecovery`), :mod:`.takeover`
(:class:`TakeOver`: an episode taken over mid-way), and the helpers :mod:`.moves` and :mod:`.clearance`. A hand's own numbers (``planner.json``,
``grasp.json``) come with its :class:`~opend_mj.sim.hands.HandModel`.
"""

from opend_mj.policy.planner.approach import Approach
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
from opend_mj.policy.planner.flap import FlapSteering
from opend_mj.policy.planner.grasp import Grasping
from opend_mj.policy.planner.kind import FrontWatch, KindCheck
from opend_mj.policy.planner.loop import Planner
from opend_mj.policy.planner.pull import Pulling
from opend_mj.policy.planner.records import (
    STAGES,
    EpisodeState,
    GraspChoice,
    Observation,
    PartMotion,
    PlanResult,
    PullState,
    StageOutcome,
)
from opend_mj.policy.planner.recovery import PushRecovery, fit_circle_xy
from opend_mj.policy.planner.robot import Robot
from opend_mj.policy.planner.slide import PanelSliding
from opend_mj.policy.planner.stage import Stage, StageContext
from opend_mj.policy.planner.takeover import TakeOver
from opend_mj.sim.hands import GRASP_FILE, PLANNER_FILE, GraspProfile, HandPlannerConfig

__all__ = [
    "GRASP_FILE", "PLANNER_FILE", "STAGES", "Approach", "ApproachConfig", "DoorConfig", "EpisodeState",
    "FlapSteering", "FrontWatch", "GraspChoice", "GraspConfig", "GraspProfile", "Grasping", "HandPlannerConfig",
    "KindCheck", "KindConfig", "LocateConfig", "Observation", "PanelSliding", "PartMotion", "PlanResult", "Planner",
    "PlannerConfig", "PullConfig", "PullState", "Pulling", "PushRecovery", "RecoveryConfig", "Robot", "Stage",
    "StageContext", "StageOutcome", "TakeOver", "VerifyConfig", "fit_circle_xy",
]
