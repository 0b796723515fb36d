"""The ``fasterrcnn`` handle solver: detect every handle, describe the detections with Algorithm 1,
and return the one whose description matches the instruction.

Detector: torchvision Faster R-CNN (2 classes: background, handle), trained from scratch
(``weights=None, weights_backbone=None``) with one of the paper's three backbones:

* ``resnet50_fpn`` (``fasterrcnn_resnet50_fpn``),
* ``mobilenet_v3_large_fpn`` (``fasterrcnn_mobilenet_v3_large_fpn``),
* ``mobilenet_v3_large_320_fpn`` (``fasterrcnn_mobilenet_v3_large_320_fpn``),

or this project's ``compact_fpn`` (the shipped one): a small residual CNN whose FPN levels are at
strides 4, 8 and 16 (the torchvision MobileNet FPNs start at 16, where a bar 3 px thick is less than
a feature cell), with the torchvision FPN, RPN and RoI heads. It trains on a CPU in under an hour.

Handles are small (a bar is often 3 x 25 px in a 256 x 256 image), so the anchors are smaller and
more elongated than torchvision's defaults (sizes from 8 px, aspect ratios 1:4 to 4:1); the box head
width is configurable (``box_head_dim``; 1024 in torchvision, smaller for a checkpoint that fits in
the repository). The models are otherwise the torchvision ones (same backbone, FPN, RPN, RoI heads).

Matching: detections above the threshold (0.8 as in the paper) are treated as handles of the
instructed kind (door or drawer, read from the instruction's last word), their centres are turned
into a :class:`opend_mj.language.TargetLayout` (with depth and camera: the world point on the
handle, +y = viewer's left, z up, the same frame and tolerance as the dataset's instructions;
without them: image u -> horizontal (image-left = viewer's left), v -> vertical, tolerance in
pixels), Algorithm 1 labels them, and the detection labelled with the instruction wins. With a
kinds detector the door / drawer calls are read together with the instruction
(:func:`consistent_choice`): the instruction says how the named kind is laid out ("door": one door
in view; "right door": several side by side), so unsure calls that contradict it are overturned. If
the detections cannot be labelled (too many levels, ties) or none matches, the detection whose
(row, column) rank is nearest the instruction's is taken.

Modules: `matching` (instruction matching, no torch), `model` (the torch detector and running it)
and `solver` (`FasterRCNNSolver`, `select_handle`); everything public is importable from here.
"""

from opend_mj.policy.learned.detector.matching import (
    box_layout_points,
    box_orientation,
    consistent_choice,
    match_instruction,
)
from opend_mj.policy.learned.detector.model import (
    BACKBONES,
    CONTEXT_MARGIN,
    CONTEXT_SHARE,
    DEFAULT_CHECKPOINT,
    KIND_LABELS,
    RELIEF_SCALE,
    RELIEF_WINDOW,
    Detections,
    DetectorConfig,
    build_detector,
    compact_backbone,
    context_boxes,
    depth_relief,
    detect_handles,
    detector_input,
    detector_targets,
    init_from_detector,
    load_detector,
)
from opend_mj.policy.learned.detector.solver import (
    SENSOR_CHECKPOINT,
    FasterRCNNSolver,
    MatchConfig,
    SensorFasterRCNNSolver,
    apply_observed_kinds,
    confirmed,
    observed_members,
    select_handle,
    vertical_bar_prior,
)

__all__ = [
    "BACKBONES",
    "CONTEXT_MARGIN",
    "CONTEXT_SHARE",
    "DEFAULT_CHECKPOINT",
    "Detections",
    "DetectorConfig",
    "FasterRCNNSolver",
    "KIND_LABELS",
    "SENSOR_CHECKPOINT",
    "SensorFasterRCNNSolver",
    "MatchConfig",
    "RELIEF_SCALE",
    "RELIEF_WINDOW",
    "apply_observed_kinds",
    "box_layout_points",
    "box_orientation",
    "build_detector",
    "compact_backbone",
    "confirmed",
    "consistent_choice",
    "context_boxes",
    "depth_relief",
    "detect_handles",
    "detector_input",
    "detector_targets",
    "init_from_detector",
    "load_detector",
    "match_instruction",
    "observed_members",
    "select_handle",
    "vertical_bar_prior",
]
