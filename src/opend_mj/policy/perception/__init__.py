"""Perception from the one RGB-D image (depth and the camera's intrinsics and pose only).

* :mod:`.handle`: a solver's box snapped to the handle in depth, back-projected into a 3D handle
  (centre, orientation, bar or knob, the panel behind it) and measured (thickness, stand-off gap,
  free space around it).
* :mod:`.door`: where a door's front plane ends, and which side a single door hinges on.
* :mod:`.proposals`: handle candidates over the whole image (for learned solvers).
* :mod:`.front`: how a pulled front moved between two images (slid out level, or turned).
* :mod:`.watch`: the front watched while acting: its motion and the handle's place, per look.
* :mod:`.config`: :class:`PerceptionConfig`, the thresholds the planner's perception uses.
"""

from opend_mj.policy.perception.config import PerceptionConfig
from opend_mj.policy.perception.door import door_edges, door_edges_vertical, infer_hinge_side
from opend_mj.policy.perception.front import FrontMotionConfig, front_motion
from opend_mj.policy.perception.handle import (
    HandleEstimate,
    HandleShape,
    estimate_handle,
    measure_handle,
    one_of_paired_handles,
    refine_box_with_depth,
    snaps_to_depth,
)
from opend_mj.policy.perception.proposals import (
    ProposalConfig,
    ThinProposalConfig,
    handle_proposals,
    thin_proposals,
)
from opend_mj.policy.perception.watch import WATCH_DIM, WATCH_NAMES, FrontWatcher, WatchConfig, blind_vector

__all__ = [
    "FrontMotionConfig", "FrontWatcher", "HandleEstimate", "HandleShape", "PerceptionConfig", "ProposalConfig",
    "ThinProposalConfig", "door_edges", "door_edges_vertical", "estimate_handle", "front_motion",
    "handle_proposals", "infer_hinge_side", "measure_handle", "one_of_paired_handles", "refine_box_with_depth",
    "snaps_to_depth", "thin_proposals", "WATCH_DIM", "WATCH_NAMES", "WatchConfig", "blind_vector",
]
