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
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from opend_mj.language import (
    Description,
    LanguageConfig,
    LanguageInvalid,
    TargetLayout,
    describe,
    describe_instruction,
    levels,
)
from opend_mj.policy.handle import centres_overlap

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


def _layout_language(depth, camera_view, config: LanguageConfig, pixel_tolerance: float) -> LanguageConfig:
    """Algorithm 1's labels with the level tolerance of the frame the box layout is in (metres with
    depth and a camera view, else pixels)."""
    metric = depth is not None and camera_view is not None
    return LanguageConfig(level_tolerance=config.level_tolerance if metric else pixel_tolerance,
                          vertical_labels=config.vertical_labels, horizontal_labels=config.horizontal_labels)


def _named_member(pts: np.ndarray, members, named: Description, lang: LanguageConfig) -> int | None:
    """The one of ``members`` (indices into ``pts``, taken as handles of the ``named`` kind) that
    Algorithm 1 describes as ``named``; None if they cannot all be described, or if none or several
    read so."""
    layout = [TargetLayout(key=str(i), kind=named.kind, y=float(pts[i, 0]), z=float(pts[i, 1])) for i in members]
    try:
        desc = describe(layout, lang)
    except LanguageInvalid:
        return None
    hits = [int(k) for k, d in desc.items() if (d.vertical, d.horizontal) == (named.vertical, named.horizontal)]
    return hits[0] if len(hits) == 1 else None


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
    named = describe_instruction(instruction)
    vertical, horizontal = named.vertical, named.horizontal
    pts = box_layout_points(boxes, depth, camera_view)
    lang = _layout_language(depth, camera_view, config, pixel_tolerance)
    tol = lang.level_tolerance
    hit = _named_member(pts, range(len(boxes)), named, lang)
    if hit is not None:
        return hit
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


def consistent_choice(boxes, probability, instruction: str, depth: np.ndarray | None = None, camera_view=None,
                      config: LanguageConfig = LanguageConfig(), max_flips: int = 3, max_uncertain: int = 12,
                      certain: float = 0.98, pixel_tolerance: float = 6.0) -> int | None:
    """Index of the named handle when the kind calls are read together with the instruction.

    ``probability`` (N,) is each candidate's probability of being a handle of the instructed kind.
    The instruction says something of the whole set: "door" means one door in view, "left door"
    two or more side by side with the named one leftmost, and so on (Algorithm 1's labels). The
    most probable set of the instructed kind (sum of log-odds kept) whose Algorithm 1 description
    names exactly one member as the instruction does is chosen, changing at most ``max_flips``
    of the ``max_uncertain`` least certain calls (none surer than ``certain`` either way); that
    member's index, or None if no such set.
    """
    from itertools import combinations

    boxes = np.asarray(boxes, float).reshape(-1, 4)
    if not len(boxes):
        return None
    named = describe_instruction(instruction)
    pts = box_layout_points(boxes, depth, camera_view)
    lang = _layout_language(depth, camera_view, config, pixel_tolerance)
    p = np.clip(np.asarray(probability, float), 1e-4, 1 - 1e-4)
    base = p >= 0.5
    cost = np.abs(np.log(p / (1 - p)))
    limit = math.log(certain / (1 - certain))
    uncertain = [int(i) for i in np.argsort(cost, kind="stable")[:max_uncertain] if cost[i] <= limit]
    flips = [c for k in range(max_flips + 1) for c in combinations(uncertain, k)]
    flips.sort(key=lambda c: float(sum(cost[i] for i in c)))
    for flip in flips:
        members = base.copy()
        members[list(flip)] ^= True
        idx = np.nonzero(members)[0]
        hit = _named_member(pts, idx, named, lang) if len(idx) else None
        if hit is not None:
            return hit
    return None


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
    #: Two handle classes, drawer and door (``KIND_LABELS``), instead of one: the solver then keeps
    #: the handles of the instructed kind before Algorithm 1 (a "top drawer" is ranked among drawers).
    kinds: bool = False
    #: A fourth input channel, the depth relief (:func:`depth_relief`: how far each pixel stands
    #: proud of its neighbourhood): a handle's shape in depth is the same on real and generated
    #: cabinets where its colour and texture are not. ``compact_fpn`` only.
    depth: bool = False
    #: The box head also reads the box's surroundings (:class:`ContextRoIPool`): a horizontal bar
    #: looks the same on a drawer and along a door's top edge; the panel around it (a seam just
    #: above and a tall front below, or seams above and below) tells them apart. ``compact_fpn`` only.
    context: bool = False

    @property
    def num_classes(self) -> int:
        return 3 if self.kinds else 2

    @property
    def in_channels(self) -> int:
        return 4 if self.depth else 3


#: Window (pixels) of the local mean depth that the relief channel is measured against, and the
#: relief that maps to 1 (metres; handles stand 1.2-9 cm proud of their panel).
RELIEF_WINDOW = 25
RELIEF_SCALE = 0.05


def depth_relief(depth: np.ndarray) -> np.ndarray:
    """(H, W) float32 in [-1, 1]: the local mean depth (``RELIEF_WINDOW`` px) minus the depth, over
    ``RELIEF_SCALE``; positive where a pixel stands nearer than its surroundings (a handle)."""
    from scipy.ndimage import uniform_filter

    d = np.nan_to_num(np.asarray(depth, np.float32), nan=0.0, posinf=0.0)
    d = np.where(d > 0.05, d, 10.0).astype(np.float32)
    return np.clip((uniform_filter(d, RELIEF_WINDOW, mode="nearest") - d) / RELIEF_SCALE, -1.0, 1.0)


def detector_input(rgb: np.ndarray, depth: np.ndarray | None, config: "DetectorConfig"):
    """The (C, H, W) float tensor a detector reads: RGB in [0, 1], then the depth relief if
    ``config.depth`` (a detector with depth needs the depth image)."""
    import torch

    x = torch.from_numpy(np.array(rgb, copy=True)).permute(2, 0, 1).float().div(255.0)
    if config.depth:
        if depth is None:
            raise ValueError("this detector reads depth (DetectorConfig.depth): pass the depth image")
        x = torch.cat([x, torch.from_numpy(depth_relief(depth))[None]], 0)
    return x


#: Class labels of a detector with ``kinds``: 0 is background.
KIND_LABELS = {"drawer": 1, "door": 2}


def compact_backbone(width: int = 32, out_channels: int = 64, in_channels: int = 3):
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
            self.stem = nn.Sequential(conv(in_channels, w // 2, 2), conv(w // 2, w, 1))  # stride 2
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


#: How far (pixels) the context window reaches beyond a box: a fixed margin plus a share of the
#: box's own size, per axis (horizontal, vertical); drawer fronts are 25-50 px tall at 256 px.
CONTEXT_MARGIN = (24.0, 40.0)
CONTEXT_SHARE = (0.25, 0.5)


def context_boxes(boxes, image_size: tuple[int, int]):
    """Each box (x0, y0, x1, y1) grown by ``CONTEXT_MARGIN`` + ``CONTEXT_SHARE`` of its size, clipped
    to the image (``image_size`` = (H, W))."""
    import torch

    w, h = boxes[:, 2] - boxes[:, 0], boxes[:, 3] - boxes[:, 1]
    dx, dy = CONTEXT_MARGIN[0] + CONTEXT_SHARE[0] * w, CONTEXT_MARGIN[1] + CONTEXT_SHARE[1] * h
    H, W = image_size
    return torch.stack([(boxes[:, 0] - dx).clamp(0, W), (boxes[:, 1] - dy).clamp(0, H),
                        (boxes[:, 2] + dx).clamp(0, W), (boxes[:, 3] + dy).clamp(0, H)], 1)


def _context_pool(pool):
    """A box RoI pool that returns, per box, the box's features and its context window's
    (:func:`context_boxes`), stacked along the channels (the box head is twice as wide)."""
    import torch
    from torch import nn

    class ContextRoIPool(nn.Module):
        def __init__(self):
            super().__init__()
            self.pool = pool

        @property
        def output_size(self):
            return self.pool.output_size

        def forward(self, features, proposals, image_shapes):
            own = self.pool(features, proposals, image_shapes)
            around = self.pool(features, [context_boxes(b, s) for b, s in zip(proposals, image_shapes)],
                               image_shapes)
            return torch.cat([own, around], 1)

    return ContextRoIPool()


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
    if config.depth or config.context:
        raise ValueError(f"the depth channel and the context window need the compact_fpn backbone, "
                         f"not {config.backbone!r}")
    builder = getattr(torchvision.models.detection, f"fasterrcnn_{config.backbone}")
    kwargs = {}
    if config.min_size is not None:
        kwargs["min_size"] = config.min_size
    if config.max_size is not None:
        kwargs["max_size"] = config.max_size
    model = builder(weights=None, weights_backbone=None, num_classes=config.num_classes, **kwargs)
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
        model.roi_heads.box_predictor = fr.FastRCNNPredictor(config.box_head_dim, config.num_classes)
    return model


def _build_compact(config: "DetectorConfig"):
    """Faster R-CNN on :func:`compact_backbone`: anchors of 8-192 px from 1:10 to 10:1 (a bar seen
    along its length), RPN and box matching at IoU 0.5 / 0.3 (a thin box rarely overlaps an anchor
    by 0.7), the input kept at its own size (``min_size``, 256 by default)."""
    from torchvision.models.detection import FasterRCNN
    from torchvision.models.detection import faster_rcnn as fr
    from torchvision.models.detection.anchor_utils import AnchorGenerator
    from torchvision.ops import MultiScaleRoIAlign

    backbone = compact_backbone(in_channels=config.in_channels)
    mean, std = [0.485, 0.456, 0.406], [0.229, 0.224, 0.225]  # torchvision's; relief is already in [-1, 1]
    if config.depth:
        mean, std = mean + [0.0], std + [0.5]
    ratios = (0.1, 0.25, 1.0, 4.0, 10.0)
    anchor = AnchorGenerator(((8, 16), (24, 40), (64, 96), (128, 192)), (ratios,) * 4)
    size = config.min_size or 256
    pool = MultiScaleRoIAlign(["0", "1", "2"], output_size=7, sampling_ratio=2)
    pooled = backbone.out_channels * 49
    if config.context:
        pooled = 2 * pooled
    model = FasterRCNN(
        backbone, num_classes=None, min_size=size, max_size=config.max_size or size, image_mean=mean, image_std=std,
        rpn_anchor_generator=anchor,
        box_roi_pool=pool,
        rpn_fg_iou_thresh=0.5, rpn_bg_iou_thresh=0.3,
        rpn_pre_nms_top_n_train=config.rpn_train_top_n, rpn_post_nms_top_n_train=config.rpn_train_top_n,
        rpn_pre_nms_top_n_test=300, rpn_post_nms_top_n_test=300,
        box_batch_size_per_image=config.box_batch_per_image, box_positive_fraction=config.box_positive_fraction,
        box_score_thresh=config.box_score_thresh,
        box_head=fr.TwoMLPHead(pooled, config.box_head_dim),
        box_predictor=fr.FastRCNNPredictor(config.box_head_dim, config.num_classes))
    if config.context:  # (torchvision's constructor accepts only its own pool class)
        model.roi_heads.box_roi_pool = _context_pool(pool)
    return model


def detector_targets(record: dict, device=None, kinds: bool = False) -> dict:
    """torchvision targets (boxes, labels) from a data record: every visible handle box, labelled 1
    (handle) or, with ``kinds``, by its target type (``KIND_LABELS``)."""
    import torch

    visible = [t for t in record["targets"] if t["box"] is not None
               and t["box"][2] - t["box"][0] >= 1.0 and t["box"][3] - t["box"][1] >= 1.0]
    b = torch.tensor([t["box"] for t in visible], dtype=torch.float32, device=device).reshape(-1, 4)
    labels = [KIND_LABELS[t["type"]] if kinds else 1 for t in visible]
    return {"boxes": b, "labels": torch.tensor(labels, dtype=torch.int64, device=device)}


def init_from_detector(model, checkpoint: Path | str, log=print) -> int:
    """Start a detector from another detector checkpoint's weights (fine-tuning): every tensor whose
    shape fits; a one-class checkpoint's handle row seeds each kind row of a two-kind model (class
    scores and box regression), so a kinds model starts as good a detector as its parent. Returns
    the tensors loaded."""
    import torch

    from opend_mj.policy.learned import checkpoint_tensors

    src = checkpoint_tensors(checkpoint)
    own = model.state_dict()
    loaded = {}
    for k, v in src.items():
        if k not in own:
            continue
        if own[k].shape == v.shape:
            loaded[k] = v
        elif v.ndim in (2, 4) and own[k].shape[1] > v.shape[1] and own[k].shape[0] == v.shape[0]:
            # a first conv given more input channels, a box head given the context window's features:
            # the new inputs start at zero weight
            w = torch.zeros_like(own[k])
            w[:, :v.shape[1]] = v
            loaded[k] = w
        elif k.endswith("cls_score.weight") or k.endswith("cls_score.bias"):
            rows = [0] + [1] * (own[k].shape[0] - 1)  # background, then the handle row per kind
            loaded[k] = v[rows].clone()
        elif k.endswith("bbox_pred.weight") or k.endswith("bbox_pred.bias"):
            n = own[k].shape[0] // 4
            loaded[k] = torch.cat([v[0:4]] + [v[4:8]] * (n - 1)).clone()
    model.load_state_dict(loaded, strict=False)
    log(f"init: {len(loaded)} of {len(own)} tensors from {checkpoint}")
    return len(loaded)


def load_detector(checkpoint: Path | str | None = None, device: str | None = None):
    """(model in eval mode, config, checkpoint dict) from a checkpoint (cached per path and device)."""
    from opend_mj.policy.learned import load_checkpoint

    def build(ckpt):
        config = DetectorConfig(**ckpt["config"])
        return build_detector(config), config

    return load_checkpoint(checkpoint, DEFAULT_CHECKPOINT, "detector", "opend train --solver fasterrcnn", build,
                           device)


def _input(model, rgb, depth):
    return detector_input(rgb, depth, DetectorConfig(depth=len(model.transform.image_mean) == 4))


@dataclass
class Detections:
    """Handles in one image: ``boxes`` (N, 4) in pixels, ``handle`` (N,) the probability that the box
    is a handle (1 - background), ``kind`` (N, K) the class probabilities among handles (K = 1 for a
    one-class detector; else drawer, door as in ``KIND_LABELS``)."""

    boxes: np.ndarray
    handle: np.ndarray
    kind: np.ndarray

    def kind_probability(self, kind: str) -> np.ndarray:
        if self.kind.shape[1] == 1:
            return np.ones(len(self.boxes))
        return self.kind[:, KIND_LABELS[kind] - 1]


def detect_handles(model, rgb: np.ndarray, extra_boxes=None, nms_iou: float = 0.5,
                   min_score: float = 0.05, depth: np.ndarray | None = None) -> tuple[Detections, Detections]:
    """One box per handle, class-agnostic: (detections, the ``extra_boxes`` scored).

    The RPN proposes, the box head scores each proposal (handle = 1 - background; kind = the class
    probabilities renormalised among the handle classes) and regresses its box by the most likely
    kind; boxes are then suppressed across classes (``nms_iou``), so a handle the head half calls a
    drawer and half a door is one detection with its whole handle probability. ``extra_boxes``
    (M, 4), e.g. handles that depth proposes, are scored by the same head as they are (no
    regression): the detector says which of them are handles and of which kind."""
    import torch
    from torchvision.ops import batched_nms, clip_boxes_to_image, remove_small_boxes

    device = next(model.parameters()).device
    x = _input(model, rgb, depth).to(device)
    h, w = rgb.shape[:2]
    with torch.no_grad():
        images, _ = model.transform([x])
        features = model.backbone(images.tensors)
        proposals, _ = model.rpn(images, features)
        scale_x = images.image_sizes[0][1] / w
        scale_y = images.image_sizes[0][0] / h
        scale = torch.tensor([scale_x, scale_y, scale_x, scale_y], device=device)
        extra = torch.as_tensor(np.asarray(extra_boxes if extra_boxes is not None else np.zeros((0, 4))),
                                dtype=torch.float32, device=device).reshape(-1, 4) * scale
        heads = model.roi_heads

        def head(boxes):
            """(class probabilities, kind probabilities among the handle classes, box regression).
            The kind is a softmax over the handle classes' logits, not the handle classes'
            probabilities divided by 1 - background: where the head is sure a box is background,
            that division is noise over noise in float32 (kinds of 0.0 or 55.8 on real proposals)."""
            feats = heads.box_head(heads.box_roi_pool(features, [boxes], images.image_sizes))
            logits, regression = heads.box_predictor(feats)
            return torch.softmax(logits, -1), torch.softmax(logits[:, 1:], -1), regression

        probs, kind_p, regression = head(proposals[0])
        handle = 1.0 - probs[:, 0]
        best = probs[:, 1:].argmax(1) + 1
        decoded = heads.box_coder.decode(regression, [proposals[0]]).reshape(len(proposals[0]), -1, 4)
        boxes = decoded[torch.arange(len(best), device=device), best]
        boxes = clip_boxes_to_image(boxes, images.image_sizes[0])
        keep = handle >= min_score
        boxes, handle, kind_p = boxes[keep], handle[keep], kind_p[keep]
        keep = remove_small_boxes(boxes, 1e-2)
        boxes, handle, kind_p = boxes[keep], handle[keep], kind_p[keep]
        keep = batched_nms(boxes, handle, torch.zeros(len(boxes), dtype=torch.int64, device=device), nms_iou)
        boxes, handle, kind_p = boxes[keep] / scale, handle[keep], kind_p[keep]
        if len(extra):
            eprobs, ekind, _ = head(extra)
            ehandle = 1.0 - eprobs[:, 0]
        else:
            ehandle, ekind = torch.zeros(0, device=device), torch.zeros((0, probs.shape[1] - 1), device=device)
    found = Detections(boxes.cpu().numpy().reshape(-1, 4), handle.cpu().numpy(), kind_p.cpu().numpy())
    scored = Detections((extra / scale).cpu().numpy().reshape(-1, 4), ehandle.cpu().numpy(), ekind.cpu().numpy())
    return found, scored


@dataclass(frozen=True)
class MatchConfig:
    """How the solver turns detections (and depth proposals) into the named handle."""

    threshold: float = 0.8  # handle probability of a detection (the paper's 0.8)
    #: Depth proposals (handles standing proud of a panel) that no detection covers join the
    #: candidates when the detector's head calls them a handle with this probability: depth says
    #: where a handle is, the head says whether it is one and of which kind.
    proposal_threshold: float = 0.0
    use_proposals: bool = True
    #: With a kinds detector, candidates of the instructed kind (probability among handle classes).
    kind_threshold: float = 0.5
    #: Only what depth confirms: the candidates are the depth proposals, each scored by the best
    #: detection covering it (else by the head on the proposal's own box), so an edge or a seam the
    #: detector takes for a handle is not one unless it stands proud of a panel like a handle.
    #: Tuned on the real train part of the OpenD training cabinets and the procedural train split:
    #: the detector's own handle probability rejects many real handles (it learnt generated ones),
    #: while its drawer / door call on a depth proposal holds (real train part: 80.6 % located
    #: without kinds, 85.9 % with them; 42.9 % on the detections alone).
    depth_verified: bool = True
    #: With a kinds detector, read the kind calls together with the instruction
    #: (:func:`consistent_choice`) before falling back to the kind threshold and Algorithm 1's
    #: nearest rank. ``handle_weight``: the exponent of the handle probability in the probability
    #: that a candidate is a handle of the instructed kind (0: the kind call alone).
    consistent: bool = True
    handle_weight: float = 0.0
    certain: float = 0.98
    #: Prior odds door : drawer of a vertical bar (a candidate box at least ``vertical_aspect`` times
    #: taller than wide), multiplied into the detector's kind odds. Real cabinets put vertical bars on
    #: doors: 56 of the 59 vertical bars of the real train part's 191 targets (horizontal bars:
    #: 38 doors, 78 drawers; no prior there). 1: no prior.
    vertical_door_odds: float = 56.0 / 3.0
    vertical_aspect: float = 2.5
    #: Thin pulls (:func:`opend_mj.policy.perception.thin_proposals`: a few millimetres proud, which
    #: depth alone cannot tell from a front's moulding, while the detector alone calls seams handles
    #: on real images) join the candidates where a detection of handle probability
    #: ``thin_threshold`` or more covers them: both must agree.
    thin: bool = True
    thin_threshold: float = 0.9


def observed_members(boxes: np.ndarray, observed: tuple) -> list[tuple[int, str]]:
    """(candidate index, kind) for each candidate box that an observed box (u0, v0, u1, v1) covers
    (either holds the other's centre): the handles the robot has moved and seen the kind of."""
    boxes = np.asarray(boxes, float).reshape(-1, 4)
    out = []
    for box, kind in observed:
        if len(boxes):
            hit = centres_overlap(boxes, np.asarray(box, float).reshape(1, 4))[:, 0]
            out.extend((int(i), kind) for i in np.nonzero(hit)[0])
    return out


def apply_observed_kinds(boxes: np.ndarray, kind: np.ndarray, observed: tuple) -> np.ndarray:
    """The kind probabilities (N, K) with the calls of observed handles made certain: a handle that
    slid out is a drawer's, one that swung about a hinge a door's, whatever the image said."""
    if not observed or kind.shape[1] < 2:
        return kind
    kind = kind.copy()
    for i, k in observed_members(boxes, observed):
        if k in KIND_LABELS:
            kind[i] = 1e-4
            kind[i, KIND_LABELS[k] - 1] = 1.0 - 1e-4 * (kind.shape[1] - 1)
    return kind


def vertical_bar_prior(boxes: np.ndarray, kind: np.ndarray, door_odds: float, aspect: float = 2.5) -> np.ndarray:
    """The kind probabilities (N, K; drawer, door) with the door : drawer odds of every vertical bar
    (box height >= ``aspect`` x width) multiplied by ``door_odds``: a handle's orientation is the
    same on real and generated images, where the detector's kind call, learnt on generated ones,
    is not."""
    boxes = np.asarray(boxes, float).reshape(-1, 4)
    if door_odds == 1.0 or kind.shape[1] < 2 or not len(boxes):
        return kind
    vertical = (boxes[:, 3] - boxes[:, 1]) >= aspect * np.maximum(boxes[:, 2] - boxes[:, 0], 1e-6)
    if not vertical.any():
        return kind
    kind = kind.copy()
    d, r = KIND_LABELS["door"] - 1, KIND_LABELS["drawer"] - 1
    door = kind[vertical, d] * door_odds
    total = door + kind[vertical, r]
    kind[vertical, d], kind[vertical, r] = door / np.maximum(total, 1e-12), kind[vertical, r] / np.maximum(total, 1e-12)
    return kind


def select_handle(found: Detections, proposals: Detections | None, instruction: str, depth=None,
                  camera_view=None, config: MatchConfig = MatchConfig(),
                  observed: tuple = ()) -> tuple[np.ndarray, float] | None:
    """(box, handle probability) of the handle the instruction names, or None without candidates.

    Candidates: detections above ``threshold``, plus depth proposals no detection covers that the
    head calls handles; with a kinds detector, those of the instructed kind (all of them where none
    is); Algorithm 1 (:func:`match_instruction`) picks among them. ``observed``: (box, kind) pairs
    of handles whose kind the robot saw by moving them (:func:`apply_observed_kinds`); their calls
    are certain."""
    keep = found.handle >= config.threshold
    boxes, handle, kind = found.boxes[keep], found.handle[keep], found.kind[keep]
    if config.depth_verified and proposals is not None and len(proposals.boxes):
        covering, covering_handle, covering_kind = boxes, handle, kind
        handle, kind = proposals.handle.copy(), proposals.kind.copy()
        if len(covering):
            cover = centres_overlap(proposals.boxes, covering)
            for i in np.nonzero(cover.any(1))[0]:
                j = np.nonzero(cover[i])[0]
                j = j[np.argmax(covering_handle[j])]
                handle[i], kind[i] = max(handle[i], covering_handle[j]), covering_kind[j]
        add = handle >= config.proposal_threshold
        boxes, handle, kind = proposals.boxes[add], handle[add], kind[add]
    elif config.use_proposals and proposals is not None and len(proposals.boxes):
        add = proposals.handle >= config.proposal_threshold
        if len(boxes):
            add &= ~centres_overlap(proposals.boxes, boxes).any(1)
        boxes = np.concatenate([boxes, proposals.boxes[add]])
        handle = np.concatenate([handle, proposals.handle[add]])
        kind = np.concatenate([kind, proposals.kind[add]])
    if not len(boxes):
        return None
    kind = vertical_bar_prior(boxes, kind, config.vertical_door_odds, config.vertical_aspect)
    kind = apply_observed_kinds(boxes, kind, observed)
    named = describe_instruction(instruction)
    if config.consistent and kind.shape[1] > 1 and named.kind in KIND_LABELS:
        p = kind[:, KIND_LABELS[named.kind] - 1] * np.clip(handle, 1e-4, 1.0) ** config.handle_weight
        i = consistent_choice(boxes, p, instruction, depth, camera_view, certain=config.certain)
        if i is not None:
            return boxes[i], float(handle[i])
    if kind.shape[1] > 1 and named.kind in KIND_LABELS:
        of_kind = kind[:, KIND_LABELS[named.kind] - 1] >= config.kind_threshold
        if of_kind.any():
            boxes, handle = boxes[of_kind], handle[of_kind]
    if not named.vertical and not named.horizontal:  # "drawer", "door": the one most like a handle
        i = int(np.argmax(handle))
        return boxes[i], float(handle[i])
    i = match_instruction(boxes, instruction, depth, camera_view, handle)
    return (boxes[i], float(handle[i])) if i is not None else None


def confirmed(boxes: np.ndarray, found: Detections, threshold: float) -> np.ndarray:
    """(N,) bool: which ``boxes`` a detection of handle probability ``threshold`` or more covers
    (either holds the other's centre)."""
    boxes = np.asarray(boxes, float).reshape(-1, 4)
    sure = found.boxes[found.handle >= threshold]
    if not len(boxes) or not len(sure):
        return np.zeros(len(boxes), bool)
    return centres_overlap(boxes, sure).any(1)


class FasterRCNNSolver:
    """Handle solver: Faster R-CNN detections (and the depth proposals its head accepts) matched
    to the instruction with Algorithm 1; see :func:`select_handle`."""

    name = "fasterrcnn"
    needs_ground_truth = False

    def __init__(self, checkpoint: Path | str | None = None, threshold: float | None = None, device: str | None = None,
                 proposals: bool = True, canonical: bool = True, **match):
        """``threshold`` None: the checkpoint's ``threshold`` (0.8, the paper's, unless it says
        otherwise); ``match``: other :class:`MatchConfig` fields."""
        self.model, self.config, self.checkpoint = load_detector(checkpoint, device)
        threshold = float(threshold if threshold is not None else self.checkpoint.get("threshold", 0.8))
        self.match = MatchConfig(threshold=threshold, use_proposals=proposals, **match)
        #: Read the instruction through Algorithm 1's parser first, so reworded instructions name
        #: the same position and kind.
        self.canonical = canonical
        self.last_detections: Detections | None = None

    #: :meth:`solve` takes ``observed``: handles whose kind the robot saw by moving them.
    accepts_observed = True

    def solve(self, rgb, depth, instruction, camera_view, observed: tuple = ()):
        """The named handle's box; ``observed``: ((u0, v0, u1, v1), "drawer" | "door") pairs of
        handles the robot moved and saw the kind of (a retry after a wrong handle)."""
        from opend_mj.language import canonical_instruction
        from opend_mj.policy.handle import HandleBox

        if self.canonical:
            instruction = canonical_instruction(instruction)
        extra = thin = None
        if self.match.use_proposals and depth is not None and camera_view is not None:
            from opend_mj.policy.perception import handle_proposals, thin_proposals

            main = handle_proposals(depth, camera_view)
            extra = np.array([box for box, _ in main], float).reshape(-1, 4)
            thin = np.array([box for box, _ in (thin_proposals(depth, camera_view, main) if self.match.thin else [])],
                            float).reshape(-1, 4)
        found, scored = detect_handles(self.model, rgb, None if extra is None else np.concatenate([extra, thin]),
                                       depth=depth)
        self.last_detections = found
        if thin is not None and len(thin):
            held = np.concatenate([np.ones(len(extra), bool), confirmed(thin, found, self.match.thin_threshold)])
            scored = Detections(scored.boxes[held], scored.handle[held], scored.kind[held])
            extra = scored.boxes
        chosen = select_handle(found, scored if extra is not None else None, instruction, depth, camera_view,
                               self.match, observed=tuple(observed))
        if chosen is None:
            return None
        b, score = chosen
        from_depth = self.match.depth_verified and extra is not None and len(extra) > 0
        return HandleBox(float(b[0]), float(b[1]), float(b[2]), float(b[3]), orientation=box_orientation(b),
                         score=score, from_depth=from_depth)
