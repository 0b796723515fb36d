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
pixels), Algorithm 1 labels them, and the detection labelled with the instruction wins. If the
detections cannot be labelled (too many levels, ties) or none matches, the detection whose
(row, column) rank is nearest the instruction's is taken.
"""

from __future__ import annotations

import math
from dataclasses import astuple, dataclass
from pathlib import Path

import numpy as np

from opend_mj.language import (
    LanguageConfig,
    LanguageInvalid,
    TargetLayout,
    describe,
    describe_instruction,
    levels,
)

BACKBONES = ("resnet50_fpn", "mobilenet_v3_large_fpn", "mobilenet_v3_large_320_fpn", "compact_fpn")
DEFAULT_CHECKPOINT = Path("checkpoints/fasterrcnn.pt")


# --------------------------------------------------------------------------------------------------
# Matching detections to an instruction (no torch needed)
# --------------------------------------------------------------------------------------------------


def _label_index(label: str, n: int, labels: dict[int, tuple[str, ...]]) -> float:
    """Where a label sits among n levels (0 = first); for an unknown count, by its meaning."""
    if n in labels and label in labels[n]:
        return float(labels[n].index(label))
    meaning = {"": (n - 1) / 2, "top": 0, "left": 0, "second top": 1, "second left": 1, "middle": (n - 1) / 2,
               "second bottom": n - 2, "second right": n - 2, "bottom": n - 1, "right": n - 1}
    return float(meaning.get(label, (n - 1) / 2))


def box_layout_points(boxes: np.ndarray, depth: np.ndarray | None = None, camera_view=None) -> np.ndarray:
    """(N, 2) positions (horizontal, vertical) of box centres: +horizontal = viewer's left, +vertical = up.

    With depth and a camera view: metres, from the world point at the box centre (the nearest depth
    inside the box, i.e. the handle's front). Otherwise: pixels (-u, -v).
    """
    boxes = np.asarray(boxes, float).reshape(-1, 4)
    uc = 0.5 * (boxes[:, 0] + boxes[:, 2])
    vc = 0.5 * (boxes[:, 1] + boxes[:, 3])
    if depth is None or camera_view is None:
        return np.stack([-uc, -vc], axis=1)
    h, w = depth.shape
    out = []
    for (u0, v0, u1, v1), u, v in zip(boxes, uc, vc):
        a, b = int(max(0, math.floor(v0))), int(min(h, math.ceil(v1)))
        c, d = int(max(0, math.floor(u0))), int(min(w, math.ceil(u1)))
        patch = depth[a:max(b, a + 1), c:max(d, c + 1)]
        patch = patch[np.isfinite(patch) & (patch > 0.05)]
        z = float(np.percentile(patch, 10)) if patch.size else float(np.median(depth[depth > 0.05]))
        p = camera_view.backproject(u, v, z)
        out.append([p[1], p[2]])
    return np.asarray(out, float)


def match_instruction(boxes, instruction: str, depth: np.ndarray | None = None, camera_view=None,
                      scores=None, config: LanguageConfig = LanguageConfig(),
                      pixel_tolerance: float = 6.0) -> int | None:
    """Index of the box that the instruction names, or None if there are no boxes.

    All boxes are taken to be handles of the instruction's kind (door/drawer). See the module doc.
    """
    boxes = np.asarray(boxes, float).reshape(-1, 4)
    if len(boxes) == 0:
        return None
    scores = np.ones(len(boxes)) if scores is None else np.asarray(scores, float)
    vertical, horizontal, kind = astuple(describe_instruction(instruction))
    pts = box_layout_points(boxes, depth, camera_view)
    metric = depth is not None and camera_view is not None
    tol = config.level_tolerance if metric else pixel_tolerance
    lang = LanguageConfig(level_tolerance=tol, vertical_labels=config.vertical_labels,
                          horizontal_labels=config.horizontal_labels)
    layout = [TargetLayout(key=str(i), kind=kind, y=float(p[0]), z=float(p[1])) for i, p in enumerate(pts)]
    try:
        desc = describe(layout, lang)
        hits = [int(k) for k, d in desc.items() if (d.vertical, d.horizontal) == (vertical, horizontal)]
        if len(hits) == 1:
            return hits[0]
    except LanguageInvalid:
        pass
    # nearest by rank: rows from the top, columns from the left within the row
    rows = levels(list(pts[:, 1]), tol, descending=True)
    n_rows = max(rows) + 1
    want_row = _label_index(vertical, n_rows, config.vertical_labels)
    best, best_cost = None, None
    for i in range(len(boxes)):
        members = [j for j in range(len(boxes)) if rows[j] == rows[i]]
        cols = levels([pts[j, 0] for j in members], tol, descending=True)
        n_cols = max(cols) + 1
        col = cols[members.index(i)]
        want_col = _label_index(horizontal, n_cols, config.horizontal_labels)
        cost = abs(rows[i] - want_row) + abs(col - want_col) - 1e-3 * scores[i]
        if best_cost is None or cost < best_cost:
            best, best_cost = i, cost
    return best


def box_orientation(box) -> str:
    u0, v0, u1, v1 = box
    return "horizontal" if (u1 - u0) >= (v1 - v0) else "vertical"


# --------------------------------------------------------------------------------------------------
# The model (torch)
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class DetectorConfig:
    backbone: str = "compact_fpn"
    box_head_dim: int = 128  # torchvision: 1024
    min_size: int | None = None  # None: the builder's (320 for the 320 variant, 800 otherwise)
    max_size: int | None = None
    small_anchors: bool = True
    rpn_train_top_n: int = 600  # torchvision: 2000 (pre- and post-NMS proposals while training)
    box_batch_per_image: int = 64  # torchvision: 512
    box_positive_fraction: float = 0.5  # torchvision: 0.25 (handles are few and small)
    box_score_thresh: float = 0.01  # torchvision: 0.05 (the solver applies its own threshold)


def compact_backbone(width: int = 32, out_channels: int = 64):
    """A small residual CNN with an FPN over its stride-4, -8 and -16 stages (``out_channels`` wide),
    as torchvision's detection backbones are: a module mapping images to an ordered dict of
    feature maps, with an ``out_channels`` attribute."""
    from collections import OrderedDict

    import torch
    from torch import nn
    from torchvision.ops import FeaturePyramidNetwork
    from torchvision.ops.feature_pyramid_network import LastLevelMaxPool

    def conv(cin, cout, stride=1):
        return nn.Sequential(nn.Conv2d(cin, cout, 3, stride, 1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True))

    class Block(nn.Module):
        def __init__(self, cin, cout, stride):
            super().__init__()
            self.a = conv(cin, cout, stride)
            self.b = nn.Sequential(nn.Conv2d(cout, cout, 3, 1, 1, bias=False), nn.BatchNorm2d(cout))
            self.skip = nn.Sequential(nn.Conv2d(cin, cout, 1, stride, bias=False), nn.BatchNorm2d(cout))

        def forward(self, x):
            return torch.relu(self.b(self.a(x)) + self.skip(x))

    class Compact(nn.Module):
        def __init__(self):
            super().__init__()
            w = width
            self.stem = nn.Sequential(conv(3, w // 2, 2), conv(w // 2, w, 1))  # stride 2
            self.s4 = nn.Sequential(Block(w, w, 2), Block(w, w, 1))
            self.s8 = nn.Sequential(Block(w, 2 * w, 2), Block(2 * w, 2 * w, 1))
            self.s16 = nn.Sequential(Block(2 * w, 4 * w, 2), Block(4 * w, 4 * w, 1))
            self.fpn = FeaturePyramidNetwork([w, 2 * w, 4 * w], out_channels, extra_blocks=LastLevelMaxPool())
            self.out_channels = out_channels

        def forward(self, x):
            c4 = self.s4(self.stem(x))
            c8 = self.s8(c4)
            c16 = self.s16(c8)
            return self.fpn(OrderedDict([("0", c4), ("1", c8), ("2", c16)]))

    return Compact()


def build_detector(config: DetectorConfig = DetectorConfig()):
    """A torchvision Faster R-CNN (2 classes) with random weights; see the module doc."""
    import torchvision
    from torchvision.models.detection import faster_rcnn as fr
    from torchvision.models.detection.anchor_utils import AnchorGenerator
    from torchvision.models.detection.rpn import RPNHead

    if config.backbone not in BACKBONES:
        raise ValueError(f"backbone must be one of {BACKBONES}, got {config.backbone!r}")
    if config.backbone == "compact_fpn":
        return _build_compact(config)
    builder = getattr(torchvision.models.detection, f"fasterrcnn_{config.backbone}")
    kwargs = {}
    if config.min_size is not None:
        kwargs["min_size"] = config.min_size
    if config.max_size is not None:
        kwargs["max_size"] = config.max_size
    model = builder(weights=None, weights_backbone=None, num_classes=2, **kwargs)
    n_levels = 5 if config.backbone == "resnet50_fpn" else 3
    if config.small_anchors:
        base = (8, 16, 32, 64, 128)[:n_levels] if n_levels == 5 else (8, 16, 32)
        sizes = tuple((s, 2 * s) for s in base) if n_levels == 3 else tuple((s,) for s in base)
        ratios = ((0.25, 0.5, 1.0, 2.0, 4.0),) * n_levels
        anchor = AnchorGenerator(sizes, ratios)
        model.rpn.anchor_generator = anchor
        model.rpn.head = RPNHead(model.backbone.out_channels, anchor.num_anchors_per_location()[0])
    model.rpn._pre_nms_top_n["training"] = config.rpn_train_top_n
    model.rpn._post_nms_top_n["training"] = config.rpn_train_top_n
    model.roi_heads.fg_bg_sampler.batch_size_per_image = config.box_batch_per_image
    model.roi_heads.fg_bg_sampler.positive_fraction = config.box_positive_fraction
    model.roi_heads.score_thresh = config.box_score_thresh
    if config.box_head_dim != 1024:
        res = model.roi_heads.box_roi_pool.output_size[0]
        model.roi_heads.box_head = fr.TwoMLPHead(model.backbone.out_channels * res * res, config.box_head_dim)
        model.roi_heads.box_predictor = fr.FastRCNNPredictor(config.box_head_dim, 2)
    return model


def _build_compact(config: "DetectorConfig"):
    """Faster R-CNN on :func:`compact_backbone`: anchors of 8-192 px from 1:10 to 10:1 (a bar seen
    along its length), RPN and box matching at IoU 0.5 / 0.3 (a thin box rarely overlaps an anchor
    by 0.7), the input kept at its own size (``min_size``, 256 by default)."""
    from torchvision.models.detection import FasterRCNN
    from torchvision.models.detection import faster_rcnn as fr
    from torchvision.models.detection.anchor_utils import AnchorGenerator
    from torchvision.ops import MultiScaleRoIAlign

    backbone = compact_backbone()
    ratios = (0.1, 0.25, 1.0, 4.0, 10.0)
    anchor = AnchorGenerator(((8, 16), (24, 40), (64, 96), (128, 192)), (ratios,) * 4)
    size = config.min_size or 256
    model = FasterRCNN(
        backbone, num_classes=None, min_size=size, max_size=config.max_size or size,
        rpn_anchor_generator=anchor,
        box_roi_pool=MultiScaleRoIAlign(["0", "1", "2"], output_size=7, sampling_ratio=2),
        rpn_fg_iou_thresh=0.5, rpn_bg_iou_thresh=0.3,
        rpn_pre_nms_top_n_train=config.rpn_train_top_n, rpn_post_nms_top_n_train=config.rpn_train_top_n,
        rpn_pre_nms_top_n_test=300, rpn_post_nms_top_n_test=300,
        box_batch_size_per_image=config.box_batch_per_image, box_positive_fraction=config.box_positive_fraction,
        box_score_thresh=config.box_score_thresh,
        box_head=fr.TwoMLPHead(backbone.out_channels * 49, config.box_head_dim),
        box_predictor=fr.FastRCNNPredictor(config.box_head_dim, 2))
    return model


def detector_targets(record: dict, device=None) -> dict:
    """torchvision targets (boxes, labels) from a data record: every visible handle box."""
    import torch

    boxes = [t["box"] for t in record["targets"] if t["box"] is not None
             and t["box"][2] - t["box"][0] >= 1.0 and t["box"][3] - t["box"][1] >= 1.0]
    b = torch.tensor(boxes, dtype=torch.float32, device=device).reshape(-1, 4)
    return {"boxes": b, "labels": torch.ones(len(b), dtype=torch.int64, device=device)}


def load_detector(checkpoint: Path | str | None = None, device: str | None = None):
    """(model in eval mode, config, checkpoint dict) from a checkpoint (cached per path and device)."""
    from opend_mj.policy.learned import load_checkpoint

    def build(ckpt):
        config = DetectorConfig(**ckpt["config"])
        return build_detector(config), config

    return load_checkpoint(checkpoint, DEFAULT_CHECKPOINT, "detector", "opend train --solver fasterrcnn", build,
                           device)


def detect(model, rgb: np.ndarray, device=None) -> tuple[np.ndarray, np.ndarray]:
    """(boxes (N, 4), scores (N,)) of one RGB image, highest score first."""
    import torch

    device = device or next(model.parameters()).device
    x = torch.from_numpy(np.array(rgb, copy=True)).permute(2, 0, 1).float().div(255.0).to(device)
    with torch.no_grad():
        out = model([x])[0]
    return out["boxes"].cpu().numpy(), out["scores"].cpu().numpy()


class FasterRCNNSolver:
    """Handle solver: Faster R-CNN detections matched to the instruction with Algorithm 1."""

    name = "fasterrcnn"
    needs_ground_truth = False

    def __init__(self, checkpoint: Path | str | None = None, threshold: float | None = None, device: str | None = None,
                 fallback_to_best: bool = False):
        """``threshold`` None: the checkpoint's ``threshold`` (0.8, the paper's, unless it says otherwise)."""
        self.model, self.config, self.checkpoint = load_detector(checkpoint, device)
        self.threshold = float(threshold if threshold is not None else self.checkpoint.get("threshold", 0.8))
        self.fallback_to_best = fallback_to_best
        self.last_detections: tuple[np.ndarray, np.ndarray] | None = None

    def solve(self, rgb, depth, instruction, camera_view):
        from opend_mj.policy.handle import HandleBox

        boxes, scores = detect(self.model, rgb)
        self.last_detections = (boxes, scores)
        keep = scores >= self.threshold
        if not keep.any() and self.fallback_to_best and len(scores):
            keep = scores >= scores.max() * 0.999
        boxes, scores = boxes[keep], scores[keep]
        i = match_instruction(boxes, instruction, depth, camera_view, scores)
        if i is None:
            return None
        b = boxes[i]
        return HandleBox(float(b[0]), float(b[1]), float(b[2]), float(b[3]), orientation=box_orientation(b),
                         score=float(scores[i]))
