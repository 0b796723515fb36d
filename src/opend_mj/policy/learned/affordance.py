"""The ``cliport`` handle solver: a language-conditioned per-pixel affordance map (CLIPort-style).

Model (:class:`AffordanceNet`):

* image stream: torchvision ``resnet18(weights=None)`` (conv1 widened to RGB + depth + two
  coordinate channels) up to ``layer3`` (stride 16; ``depth=4`` adds ``layer4``, stride 32);
* language stream: a frozen text encoder (:mod:`opend_mj.policy.learned.text`, MiniLM by default) whose
  sentence embedding is projected by a small MLP per fusion layer;
* decoder: upsampling blocks with skip connections from the ResNet stages back to 1/2 resolution;
  the text is fused into the first ``fusion_layers`` (2, 3 or 4) decoder stages, counted from the
  bottleneck, either FiLM (``x * (1 + gamma(t)) + beta(t)``) or CLIPort's elementwise product with
  projected text features (``x * p(t)``);
* head: one logit per pixel at 1/2 resolution, upsampled to the input size. Trained with binary
  cross-entropy (positive weight for the rare handle pixels) against the instructed target's handle
  mask (from the training renders, dilated by one pixel).

Inference (:class:`CLIPortSolver`): by default the map chooses among the handles that depth
proposes (:func:`opend_mj.policy.perception.handle_proposals`: groups standing 1.2-9 cm proud of a
panel, handle-sized): each proposal scores the map's peak over its pixels (the map smoothed by
``heat_sigma`` px); the proposals scoring at least ``plausible_fraction`` of the best are the
plausible ones, and where the instruction names a position Algorithm 1's matching
(:func:`opend_mj.policy.learned.detector.match_instruction`) picks among them, else the best
scoring one is taken. For a drawer, the plausible set takes in the rest of each plausible
handle's stack (`drawer_stack`): drawers stacked in a column carry the same handle, and a position
such as "middle" or "second bottom" is only right among the whole stack, which the map's scores
alone often cut short. The map says which handle is meant, depth where it is exactly. Under a
noisy depth sensor the proposals also come from the depth averaged along bars and over knobs
(``noise_windows``), and the map reads the sensor's missing pixels as their nearest reading
(:attr:`AffordanceConfig.fill_holes`); exact depth reads as without. Without
proposals (``proposals=False``, or none found) the handle centre is the probability-weighted
centroid of the connected region above half the peak around the arg-max; the box is that region's
bounding box (at least ``min_box`` px on each side); the orientation comes from the region's
principal axis.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

#: The shipped model's file name (`opend_mj.resources.default_checkpoint` finds it).
DEFAULT_CHECKPOINT = "cliport.pt"
DEPTH_MEAN, DEPTH_SCALE = 2.5, 1.0


@dataclass(frozen=True)
class AffordanceConfig:
    fusion_layers: int = 3  # 2, 3 or 4
    fusion: str = "film"  # "film" | "product"
    depth: int = 3  # ResNet-18 stages used (3: up to layer3, 4: all)
    text_encoder: str = "minilm"
    text_dim: int = 384
    image_size: int = 256  # input resolution (renders are resized to it)
    decoder_width: int = 1  # multiplier of the decoder widths (1: 128, 64, 32)
    #: Training only: the chance that a training target's instruction is replaced by a grammar
    #: rewording of it (`opend_mj.language.rewordings`), for a model that reads words as people say
    #: them (a solver with ``canonical=False``); 0: Algorithm 1's templates only.
    reword: float = 0.0
    #: The map reads a sensor's missing pixels (depth 0) as their nearest reading
    #: (:func:`opend_mj.policy.perception.noise.fill_holes`), as on exact training renders, which have
    #: none. A model trained on a sensor's depth (`opend train --solver cliport --depth-noise`) learnt
    #: holes as 0 m and reads them so (False). Depth without holes reads the same either way.
    fill_holes: bool = True


def _torch():
    import torch
    import torch.nn as nn
    import torch.nn.functional as F

    return torch, nn, F


def build_model(config: AffordanceConfig = AffordanceConfig()):
    torch, nn, F = _torch()
    import torchvision

    if config.fusion_layers not in (2, 3, 4):
        raise ValueError("fusion_layers must be 2, 3 or 4")
    if config.fusion not in ("film", "product"):
        raise ValueError("fusion must be 'film' or 'product'")

    class Up(nn.Module):
        def __init__(self, cin, cskip, cout):
            super().__init__()
            self.conv = nn.Sequential(
                nn.Conv2d(cin + cskip, cout, 3, padding=1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True),
                nn.Conv2d(cout, cout, 3, padding=1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True))

        def forward(self, x, skip):
            x = F.interpolate(x, size=skip.shape[-2:], mode="bilinear", align_corners=False)
            return self.conv(torch.cat([x, skip], 1))

    class Fuse(nn.Module):
        def __init__(self, text_dim, channels, mode):
            super().__init__()
            self.mode = mode
            out = 2 * channels if mode == "film" else channels
            self.proj = nn.Sequential(nn.Linear(text_dim, 256), nn.ReLU(inplace=True), nn.Linear(256, out))
            nn.init.zeros_(self.proj[-1].weight)
            nn.init.zeros_(self.proj[-1].bias)
            if mode == "product":
                nn.init.ones_(self.proj[-1].bias)

        def forward(self, x, t):
            p = self.proj(t)[:, :, None, None]
            if self.mode == "film":
                gamma, beta = p.chunk(2, dim=1)
                return x * (1 + gamma) + beta
            return x * p

    class AffordanceNet(nn.Module):
        def __init__(self, cfg: AffordanceConfig):
            super().__init__()
            self.cfg = cfg
            r = torchvision.models.resnet18(weights=None)
            r.conv1 = nn.Conv2d(6, 64, 7, stride=2, padding=3, bias=False)  # RGB, depth, u, v
            self.stem = nn.Sequential(r.conv1, r.bn1, r.relu)  # 1/2, 64
            self.pool = r.maxpool
            self.layer1, self.layer2, self.layer3 = r.layer1, r.layer2, r.layer3  # 1/4 64, 1/8 128, 1/16 256
            self.layer4 = r.layer4 if cfg.depth == 4 else None  # 1/32 512
            w = cfg.decoder_width
            chans = []
            if self.layer4 is not None:
                self.up4 = Up(512, 256, 256 * w)
                bottom = 256 * w
            else:
                self.up4 = None
                bottom = 256
            self.up3 = Up(bottom, 128, 128 * w)
            self.up2 = Up(128 * w, 64, 64 * w)
            self.up1 = Up(64 * w, 64, 32 * w)
            chans = [bottom, 128 * w, 64 * w, 32 * w]  # fusion points, from the bottleneck up
            self.fuse = nn.ModuleList(Fuse(cfg.text_dim, c, cfg.fusion) for c in chans[: cfg.fusion_layers])
            self.head = nn.Conv2d(32 * w, 1, 1)
            nn.init.constant_(self.head.bias, -4.0)

        def forward(self, image, text):
            """image (B, 6, H, W) normalised; text (B, text_dim) -> logits (B, 1, H, W)."""
            s1 = self.stem(image)
            s2 = self.layer1(self.pool(s1))
            s3 = self.layer2(s2)
            x = self.layer3(s3)
            if self.layer4 is not None:
                x = self.up4(self.layer4(x), x)
            feats = []
            stages = [lambda y: y, lambda y: self.up3(y, s3), lambda y: self.up2(y, s2), lambda y: self.up1(y, s1)]
            for k, stage in enumerate(stages):
                x = stage(x)
                if k < len(self.fuse):
                    x = self.fuse[k](x, text)
                feats.append(x)
            logits = self.head(x)
            return F.interpolate(logits, size=image.shape[-2:], mode="bilinear", align_corners=False)

    return AffordanceNet(config)


def prepare_image(rgb: np.ndarray, depth: np.ndarray, size: int | None = None):
    """(6, H, W) float tensor: RGB in [0, 1] minus 0.5, normalised depth, u and v in [-1, 1]."""
    torch, _, F = _torch()
    h, w = depth.shape
    x = torch.empty(6, h, w)
    x[:3] = torch.from_numpy(np.array(rgb, copy=True)).permute(2, 0, 1).float().div(255.0) - 0.5
    d = np.nan_to_num(np.asarray(depth, np.float32), nan=0.0, posinf=0.0)
    x[3] = (torch.from_numpy(d).clamp(0, 10) - DEPTH_MEAN) / DEPTH_SCALE
    x[4] = torch.linspace(-1, 1, w)[None, :].expand(h, w)
    x[5] = torch.linspace(-1, 1, h)[:, None].expand(h, w)
    if size is not None and size != h:
        x = F.interpolate(x[None], size=(size, size), mode="bilinear", align_corners=False)[0]
    return x


def target_mask(mask: np.ndarray, value: int, dilate: int = 1) -> np.ndarray:
    m = mask == value
    if dilate > 0 and m.any():
        from scipy.ndimage import binary_dilation

        m = binary_dilation(m, iterations=dilate)
    return m.astype(np.float32)


# --------------------------------------------------------------------------------------------------
# From an affordance map to a handle box
# --------------------------------------------------------------------------------------------------


def drawer_stack(boxes: np.ndarray, members: set[int], column_px: float = 3.0, size_tolerance: float = 0.15) -> set[int]:
    """``members`` and every box in the same image column as one of them (centres within
    ``column_px``) with a handle of the same size (width and height within ``size_tolerance``, at
    least 2 px): a stack of drawers with one handle design."""
    boxes = np.asarray(boxes, float).reshape(-1, 4)
    cu = (boxes[:, 0] + boxes[:, 2]) / 2
    w, h = boxes[:, 2] - boxes[:, 0], boxes[:, 3] - boxes[:, 1]
    stack = set(members)
    for p in members:
        same = (np.abs(cu - cu[p]) <= column_px) & (np.abs(w - w[p]) <= size_tolerance * np.maximum(w, w[p])) \
            & (np.abs(h - h[p]) <= np.maximum(2.0, size_tolerance * np.maximum(h, h[p])))
        stack.update(np.nonzero(same)[0].tolist())
    return stack


def choose_proposal(prob: np.ndarray, proposals: list, instruction: str, depth: np.ndarray, view,
                    plausible_fraction: float = 0.05, heat_sigma: float = 6.0,
                    stack_drawers: bool = True, observed: tuple = ()) -> tuple | None:
    """The box of the proposal the affordance map and the instruction name (see the module doc), or
    None without proposals. ``proposals``: [(box (u0, v0, u1, v1), mask over the box), ...].
    ``observed``: (box, kind) pairs of handles the robot moved and saw the kind of, or of boxes it
    found empty (``NO_HANDLE``); those of the other kind than the instruction's, and the empty ones,
    are not candidates (nor part of the named kind's layout)."""
    from scipy.ndimage import gaussian_filter

    from opend_mj.language import describe_instruction
    from opend_mj.policy.learned.detector import match_instruction, observed_members

    if observed and proposals:
        named_kind = describe_instruction(instruction).kind
        other = {i for i, k in observed_members(np.array([b for b, _ in proposals], float), observed)
                 if k != named_kind}
        proposals = [p for i, p in enumerate(proposals) if i not in other]
    if not proposals:
        return None
    heat = gaussian_filter(prob.astype(np.float32), heat_sigma) if heat_sigma > 0 else prob
    scores = np.array([float(heat[v0:v1, u0:u1][mask].max()) for (u0, v0, u1, v1), mask in proposals])
    boxes = np.array([box for box, _ in proposals], float)
    best = int(np.argmax(scores))
    named = describe_instruction(instruction)
    if not named.vertical and not named.horizontal:
        return tuple(boxes[best])
    plausible = np.nonzero(scores >= plausible_fraction * scores[best])[0]
    if stack_drawers and named.kind == "drawer":
        plausible = np.array(sorted(drawer_stack(boxes, set(plausible.tolist()))))
    i = match_instruction(boxes[plausible], instruction, depth, view, scores=scores[plausible])
    return tuple(boxes[plausible[i]]) if i is not None else tuple(boxes[best])


def map_to_box(prob: np.ndarray, rel: float = 0.5, min_box: float = 4.0):
    """(centre (u, v), box (u0, v0, u1, v1), orientation, peak) from a probability map (H, W)."""
    from scipy.ndimage import label

    h, w = prob.shape
    r, c = np.unravel_index(int(np.argmax(prob)), prob.shape)
    peak = float(prob[r, c])
    region, _ = label(prob >= rel * peak)
    sel = region == region[r, c]
    rr, cc = np.nonzero(sel)
    wts = prob[rr, cc].astype(np.float64)
    wts = wts / max(wts.sum(), 1e-12)
    uc, vc = float((cc + 0.5) @ wts), float((rr + 0.5) @ wts)
    u0, u1 = cc.min(), cc.max() + 1.0
    v0, v1 = rr.min(), rr.max() + 1.0
    if len(rr) >= 3:
        cov = np.cov(np.stack([cc, rr]).astype(float), aweights=wts + 1e-12)
        evals, evecs = np.linalg.eigh(cov)
        major = evecs[:, -1]
        elong = float(evals[-1] / max(evals[0], 1e-6))
        orientation = ("horizontal" if abs(major[0]) >= abs(major[1]) else "vertical") if elong > 2.0 else None
    else:
        orientation = None
    half = min_box / 2
    u0, u1 = min(u0, uc - half), max(u1, uc + half)
    v0, v1 = min(v0, vc - half), max(v1, vc + half)
    box = (float(max(0, u0)), float(max(0, v0)), float(min(w, u1)), float(min(h, v1)))
    return (uc, vc), box, orientation, peak


# --------------------------------------------------------------------------------------------------
# Checkpoints and the solver
# --------------------------------------------------------------------------------------------------

_TEXT_ENCODERS: dict = {}


def load_affordance(checkpoint: Path | str | None = None, device: str | None = None):
    """(model in eval mode, config, text encoder, checkpoint dict), cached per path and device."""
    from opend_mj.policy.learned import load_checkpoint
    from opend_mj.policy.learned.text import CachedEncoder

    def build(ckpt):
        config = AffordanceConfig(**ckpt["config"])
        return build_model(config), config

    model, config, ckpt = load_checkpoint(checkpoint, DEFAULT_CHECKPOINT, "CLIPort",
                                          "opend train --solver cliport", build, device)
    if id(ckpt) not in _TEXT_ENCODERS:  # one encoder per loaded (and kept) checkpoint
        _TEXT_ENCODERS[id(ckpt)] = CachedEncoder.from_state(ckpt["text"])
    return model, config, _TEXT_ENCODERS[id(ckpt)], ckpt


def predict(model, config: AffordanceConfig, text, rgb, depth, instruction: str) -> np.ndarray:
    """Probability map (H, W) at the image's resolution."""
    from opend_mj.policy.perception.noise import fill_holes

    torch, _, F = _torch()
    device = next(model.parameters()).device
    x = prepare_image(rgb, fill_holes(depth) if config.fill_holes else depth, config.image_size)[None].to(device)
    t = torch.from_numpy(text.encode([instruction])).to(device)
    with torch.no_grad():
        logits = model(x, t)
        h, w = depth.shape
        if logits.shape[-1] != w or logits.shape[-2] != h:
            logits = F.interpolate(logits, size=(h, w), mode="bilinear", align_corners=False)
    return torch.sigmoid(logits)[0, 0].cpu().numpy()


class CLIPortSolver:
    """Handle solver: language-conditioned affordance map -> handle centre, box and orientation."""

    name = "cliport"
    needs_ground_truth = False

    def __init__(self, checkpoint: Path | str | None = None, device: str | None = None, min_box: float = 4.0,
                 canonical: bool = True, proposals: bool = True, plausible_fraction: float = 0.05,
                 heat_sigma: float = 6.0, thin: bool = True, thin_fraction: float = 0.5, thin_stack: bool = True,
                 noise_windows: bool = True):
        self.model, self.config, self.text, self.checkpoint = load_affordance(checkpoint, device)
        self.min_box = min_box
        #: Read the instruction through Algorithm 1's parser first (`language.canonical_instruction`),
        #: so reworded instructions reach the model in the wording it was trained on.
        self.canonical = canonical
        #: Choose among the handles depth proposes (see the module doc); tuned on the real train part
        #: of the OpenD cabinets and the procedural train split.
        self.proposals = proposals
        self.plausible_fraction = plausible_fraction
        self.heat_sigma = heat_sigma
        #: Thin pulls (:func:`opend_mj.policy.perception.thin_proposals`) join the proposals where
        #: the map itself peaks on them: ``thin_fraction`` of its maximum or more.
        self.thin = thin
        self.thin_fraction = thin_fraction
        #: ... and where they stack with a proposal (:func:`drawer_stack`: same column, same size):
        #: one pull design down a stack of drawers, seen clearly by the map on one of them. Faster
        #: R-CNN's solver has no such rule: there it did not help.
        self.thin_stack = thin_stack
        #: Under a noisy sensor, the depth proposals also search the depth averaged along bars and
        #: over knobs (:data:`opend_mj.policy.perception.proposals.NOISE_WINDOWS`); the map's score
        #: then chooses among them as among the others. Exact depth reads as without.
        self.noise_windows = noise_windows
        self.last_map: np.ndarray | None = None

    #: :meth:`solve` takes ``observed``: handles whose kind the robot saw by moving them.
    accepts_observed = True

    def solve(self, rgb, depth, instruction, camera_view, observed: tuple = ()):
        """The named handle's box; ``observed``: ((u0, v0, u1, v1), "drawer" | "door") pairs of
        handles the robot moved and saw the kind of (a retry after a wrong handle)."""
        from opend_mj.language import canonical_instruction
        from opend_mj.policy.handle_box import HandleBox

        if self.canonical:
            instruction = canonical_instruction(instruction)
        prob = predict(self.model, self.config, self.text, rgb, depth, instruction)
        self.last_map = prob
        if self.proposals and camera_view is not None:
            chosen = choose_proposal(prob, self._proposals(prob, depth, camera_view), instruction, depth, camera_view,
                                     self.plausible_fraction, self.heat_sigma, observed=tuple(observed))
            if chosen is not None:
                return HandleBox(*chosen, orientation=None, score=float(prob.max()), from_depth=True)
        _, box, orientation, peak = map_to_box(prob, min_box=self.min_box)
        return HandleBox(*box, orientation=orientation, score=peak)

    def _proposals(self, prob: np.ndarray, depth, camera_view) -> list:
        """The depth proposals, and the thin ones the map peaks on (see ``thin``)."""
        from opend_mj.policy.perception import ProposalConfig, handle_proposals, thin_proposals
        from opend_mj.policy.perception.proposals import NOISE_WINDOWS

        main = handle_proposals(depth, camera_view,
                                ProposalConfig(noise_windows=NOISE_WINDOWS if self.noise_windows else ()))
        if not self.thin:
            return main
        top = float(prob.max())
        thin = thin_proposals(depth, camera_view, main)
        peaked = [float(prob[b[1]:b[3], b[0]:b[2]][m].max()) >= self.thin_fraction * top for b, m in thin]
        if self.thin_stack and thin:
            members = set(range(len(main))) | {len(main) + i for i, p in enumerate(peaked) if p}
            stack = drawer_stack(np.array([b for b, _ in main + thin], float), members)
            peaked = [p or len(main) + i in stack for i, p in enumerate(peaked)]
        return main + [t for t, p in zip(thin, peaked) if p]


def config_dict(config: AffordanceConfig) -> dict:
    return asdict(config)
