"""The Faster R-CNN handle detector (torch): configuration, input channels, backbones, building,
training targets, checkpoints, and running it on an image (`detect_handles`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np


BACKBONES = ("resnet50_fpn", "mobilenet_v3_large_fpn", "mobilenet_v3_large_320_fpn", "compact_fpn")
#: The shipped detector's file name (`opend_mj.resources.default_checkpoint` finds it).
DEFAULT_CHECKPOINT = "fasterrcnn.pt"


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
    #: How the relief channel reads a depth image's holes (0: no reading, as a real sensor reports
    #: at edges and on dark surfaces): True, as holes (:func:`depth_relief` ``holes``: left out,
    #: relief 0), for a detector trained on a sensor's depth (`opend train --depth-noise`); False, as
    #: surfaces 10 m away, as the detectors trained on exact renders read them.
    relief_holes: bool = False
    #: Noisy depth's relief soft-thresholded at its own noise (:func:`depth_relief` ``denoise``):
    #: exact depth is unchanged, so a checkpoint trained on exact renders reads noisy images as it
    #: read its training ones, panels flat. A detector trained on a sensor's depth (`opend train
    #: --depth-noise`, as ``checkpoints/fasterrcnn_sensor.pt``) learns the raw noisy relief and reads
    #: it raw (False; :func:`load_detector` for checkpoints from before this field).
    relief_denoise: bool = True

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
#: Noisy depth (a real sensor's): relief within this many sigmas of the image's own depth noise
#: (:func:`relief_noise`) is shrunk to 0, the rest by as much (a soft threshold), so that a flat
#: panel reads flat, as on the exact renders the detector learnt from, while a handle, centimetres
#: proud, keeps most of its relief. Exact depth reads no noise and is unchanged.
RELIEF_NOISE_SIGMAS = 2.0
#: Depth noise (m, one sigma) below which depth counts as exact.
RELIEF_NOISE_FLOOR = 0.001


def relief_noise(depth: np.ndarray) -> float:
    """The depth noise (m, one sigma) of ``depth`` where the camera frames the cabinet's front
    (:func:`opend_mj.policy.perception.noise.front_window`; 0 for exact depth)."""
    from opend_mj.policy.perception.noise import front_window, pixel_noise

    d = np.asarray(depth, np.float32)
    window = np.nan_to_num(d[front_window(d.shape)], nan=0.0, posinf=0.0)
    return pixel_noise(window, window > 0.05, RELIEF_NOISE_FLOOR)


def depth_relief(depth: np.ndarray, holes: bool = True, denoise: bool = True) -> np.ndarray:
    """(H, W) float32 in [-1, 1]: the local mean depth (``RELIEF_WINDOW`` px) minus the depth, over
    ``RELIEF_SCALE``; positive where a pixel stands nearer than its surroundings (a handle).

    Pixels without a reading (0 or not finite, as a real sensor reports holes at edges and on dark
    surfaces): with ``holes``, left out of the local mean, with relief 0 (a hole is not a surface
    10 m away, which would mark everything around it as standing proud); without, read as 10 m
    away (`DetectorConfig.relief_holes`). An image without holes gives the same relief either way.
    ``denoise``: noisy depth's relief soft-thresholded at ``RELIEF_NOISE_SIGMAS`` sigmas of its noise."""
    from scipy.ndimage import uniform_filter

    d = np.nan_to_num(np.asarray(depth, np.float32), nan=0.0, posinf=0.0)
    read = d > 0.05
    if not holes or read.all():
        d = np.where(read, d, 10.0).astype(np.float32)
        relief = (uniform_filter(d, RELIEF_WINDOW, mode="nearest") - d) / RELIEF_SCALE
    else:
        w = uniform_filter(read.astype(np.float32), RELIEF_WINDOW, mode="nearest")
        total = uniform_filter(np.where(read, d, 0.0).astype(np.float32), RELIEF_WINDOW, mode="nearest")
        mean = total / np.maximum(w, 1e-6)  # over the pixels with a reading
        relief = np.where(read & (w > 0), (mean - d) / RELIEF_SCALE, 0.0)
    noise = relief_noise(depth) if denoise else 0.0
    if noise > 0:
        t = RELIEF_NOISE_SIGMAS * noise / RELIEF_SCALE
        relief = np.sign(relief) * np.maximum(np.abs(relief) - t, 0.0)
    return np.clip(relief, -1.0, 1.0).astype(np.float32)


def detector_input(rgb: np.ndarray, depth: np.ndarray | None, config: "DetectorConfig"):
    """The (C, H, W) float tensor a detector reads: RGB in [0, 1], then the depth relief if
    ``config.depth`` (a detector with depth needs the depth image)."""
    import torch

    x = torch.from_numpy(np.array(rgb, copy=True)).permute(2, 0, 1).float().div(255.0)
    if config.depth:
        if depth is None:
            raise ValueError("this detector reads depth (DetectorConfig.depth): pass the depth image")
        x = torch.cat([x, torch.from_numpy(depth_relief(depth, holes=config.relief_holes,
                                                                denoise=config.relief_denoise))[None]], 0)
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
        model = _build_compact(config)
        model.detector_config = config  # what its input is (`detector_input`)
        return model
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
        # a checkpoint from before ``relief_denoise`` learnt on a sensor's raw relief if it reads holes
        # as holes (`opend train --depth-noise`), and reads it so; one of exact renders denoises
        fields = {"relief_denoise": not ckpt["config"].get("relief_holes", False), **ckpt["config"]}
        config = DetectorConfig(**fields)
        return build_detector(config), config

    return load_checkpoint(checkpoint, DEFAULT_CHECKPOINT, "detector", "opend train --solver fasterrcnn", build,
                           device)


def _input(model, rgb, depth):
    config = getattr(model, "detector_config", None) or DetectorConfig(depth=len(model.transform.image_mean) == 4)
    return detector_input(rgb, depth, config)


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
