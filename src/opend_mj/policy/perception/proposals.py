"""Handle proposals from depth alone: groups of pixels that stand out of the panel they sit on and
are shaped like a handle. Learned solvers choose among them (their map says which, depth says where
exactly)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from opend_mj.policy.perception.noise import FRONT_WINDOW, front_noise, front_window


@dataclass(frozen=True)
class ProposalConfig:
    """The whole-image search for handle candidates (for learned solvers: their map says which,
    depth says where exactly). Handles stand out of the panel they sit on.

    A pixel is proud when it is between ``min_protrusion`` and ``max_protrusion`` (m) nearer (world
    x) than the median of its ``window``-pixel neighbourhood (taken every ``stride`` pixels). A
    connected group of at least ``min_pixels`` is a proposal when a ring ``ring`` pixels wide around
    it lies mostly (``ring_fraction``) on a panel just behind it (the silhouette corners of a
    cabinet against the room are not), and its extent (m) is handle-like: at most ``max_short``
    across and ``max_long`` along (a raised door panel's frame is not). This range is wider than
    the one that snaps a solver's box (:attr:`PerceptionConfig.snap_protrusion`): it only proposes."""

    window: int = 25
    stride: int = 2
    min_protrusion: float = 0.012
    max_protrusion: float = 0.09
    min_pixels: int = 3
    ring: int = 4
    ring_fraction: float = 0.6
    #: How far (m) behind the group a ring pixel may lie and still be the panel it sits on (a pull
    #: over a finger recess: the recess is panel too; the room behind a cabinet's corner, often
    #: farther, is not).
    ring_depth: float = 0.2
    max_short: float = 0.07
    max_long: float = 0.95
    #: A group too large or not ringed by a panel (a narrow cabinet's whole front stands proud of a
    #: window that reaches the room behind it, and the handle with it) is searched again against its
    #: own median depth: the front it is part of.
    split_groups: bool = True
    #: Groups touching the image's border are dropped: what the frame cuts (the room's furniture,
    #: the floor's edge, a cabinet side) cannot be told for a handle, nor a handle's position read
    #: from it; the camera frames the cabinet, so target handles lie inside the image.
    drop_border: bool = True
    #: Groups standing more than ``front_band`` (m) nearer or farther than the cabinet's front are
    #: dropped: the room's furniture beside the cabinet (a desk's leg, a shelf's edge). The front is
    #: the ``front_percentile`` percentile of world x over the image's central window
    #: ``front_window`` (rows from, to; columns from, to; fractions of the image: the camera frames
    #: the cabinet there). 0: keep every group.
    front_band: float = 0.2
    front_percentile: float = 20.0
    front_window: tuple = FRONT_WINDOW
    #: A square-ish group (box sides within ``square_aspect`` of each other) must fill ``min_fill``
    #: of its box: a knob or a bar's end fills most of it (two thirds or more), the corner of a
    #: raised panel's frame (an L) about half. 0: off.
    min_fill: float = 0.6
    square_aspect: float = 2.0
    #: Noisy depth (`noise.pixel_noise` over ``front_window``, at least ``noise_floor`` m): a pixel is proud
    #: only ``noise_sigmas`` sigmas nearer than its panel or more, and a group holds ``noise_min_pixels``
    #: or more, else noise alone forms groups.
    noise_floor: float = 0.001
    noise_sigmas: float = 3.0
    noise_min_pixels: int = 6
    #: Depth so noisy that it raises ``min_protrusion`` is searched again on copies averaged over
    #: each of these windows (rows, columns of pixels; missing pixels left out), whose noise,
    #: measured on each copy, is about 1/sqrt(rows x columns) of the image's: a bar 1-3 px wide and
    #: 30 px long stands out of 8-12 mm of noise once averaged along its length, a knob once averaged
    #: over its face. Groups found there join the proposals, replacing the smaller ones they overlap
    #: (the pieces noise cut a bar into; either holds the other's centre); a group there holds at
    #: least twice a window's pixels (averaged noise comes in blobs of a window's size). The averaged
    #: copies also propose edges that noise blurred into ridges, so a solver uses them where its model
    #: chooses among the proposals (`NOISE_WINDOWS`). Empty: the image alone, as without noise.
    noise_windows: tuple = ()


#: The averaging windows of :attr:`ProposalConfig.noise_windows` for a solver whose model chooses
#: among the proposals (Faster R-CNN's head scores each one's box, CLIPort's map its pixels): along a
#: vertical bar, along a horizontal one, and over a knob's face.
NOISE_WINDOWS = ((9, 1), (1, 9), (3, 3))


def handle_proposals(depth: np.ndarray, view, config: ProposalConfig = ProposalConfig()) -> list[tuple]:
    """Boxes (u0, v0, u1, v1) and pixel masks of the groups in ``depth`` that look like handles:
    a list of (box, mask), mask a bool array over the box's pixels (rows v0:v1, columns u0:u1)."""
    from opend_mj.policy.handle_box import centres_overlap

    h, w = depth.shape
    vv, uu = np.meshgrid(np.arange(h) + 0.5, np.arange(w) + 0.5, indexing="ij")
    d = np.where(np.isfinite(depth), depth, np.nanmax(depth[np.isfinite(depth)]) if np.isfinite(depth).any() else 0.0)
    pts = view.backproject(uu.ravel(), vv.ravel(), d.ravel()).reshape(h, w, 3)
    read = np.isfinite(depth) & (depth > 0)
    sigma = front_noise(pts[..., 0], read, config.noise_floor, config.front_window)
    if config.noise_sigmas * sigma <= config.min_protrusion:  # exact depth, or noise below the threshold
        return _search(pts, replace(config, min_pixels=max(config.min_pixels, config.noise_min_pixels))
                       if sigma > 0 else config)
    out: list = []
    for rows, cols in ((1, 1), *config.noise_windows):
        x = pts[..., 0] if rows * cols == 1 else _window_mean(pts[..., 0], read, rows, cols)
        noise = sigma if rows * cols == 1 else front_noise(x, read, config.noise_floor, config.front_window, step=cols)
        found = _search(np.concatenate([x[..., None], pts[..., 1:]], axis=-1), replace(
            config, min_protrusion=max(config.min_protrusion, config.noise_sigmas * noise),
            min_pixels=max(config.min_pixels, config.noise_min_pixels, 2 * rows * cols)))
        for group in found:  # an averaged group replaces the smaller ones it overlaps (pieces noise cut a bar into)
            if out and rows * cols > 1:
                held = centres_overlap(np.array([group[0]], float), np.array([b for b, _ in out], float))[0]
                if any(_area(out[i][0]) >= _area(group[0]) for i in np.nonzero(held)[0]):
                    continue
                out = [p for p, overlaps in zip(out, held) if not overlaps]
            out.append(group)
    return out


def _area(box) -> float:
    return float((box[2] - box[0]) * (box[3] - box[1]))


def _window_mean(x: np.ndarray, read: np.ndarray, rows: int, cols: int) -> np.ndarray:
    """``x`` averaged over a ``rows`` x ``cols`` window centred on each pixel, over the pixels with a
    reading (``read``); a pixel whose window has none keeps its value."""
    from scipy import ndimage

    size = (int(rows), int(cols))
    total = ndimage.uniform_filter(np.where(read, x, 0.0), size=size, mode="nearest")
    count = ndimage.uniform_filter(read.astype(float), size=size, mode="nearest")
    return np.where(count > 1e-6, total / np.maximum(count, 1e-6), x)


def _search(pts: np.ndarray, config: ProposalConfig) -> list[tuple]:
    """:func:`handle_proposals` on one (H, W, 3) grid of world points, with ``config``'s thresholds."""
    from scipy import ndimage

    h, w = pts.shape[:2]
    x = pts[..., 0]
    # the panel: a median over the window, taken on a grid of every ``stride``-th pixel (25 x 25
    # medians at every pixel cost ~1 s an image; on the grid 1/16 of it) and spread back
    s = max(1, int(config.stride))
    coarse = ndimage.median_filter(x[::s, ::s], size=max(3, config.window // s | 1))
    panel = np.repeat(np.repeat(coarse, s, axis=0), s, axis=1)[:h, :w]
    proud = (x < panel - config.min_protrusion) & (x > panel - config.max_protrusion)
    labels, _ = ndimage.label(proud, structure=np.ones((3, 3), bool))
    def handle_like(labels, k, sl, mask, group_x: float) -> bool:
        if config.ring:
            r = config.ring
            v0, v1 = max(0, sl[0].start - r), min(h, sl[0].stop + r)
            u0, u1 = max(0, sl[1].start - r), min(w, sl[1].stop + r)
            own = labels[v0:v1, u0:u1] == k
            ring = ndimage.binary_dilation(own, iterations=r) & ~own
            behind = x[v0:v1, u0:u1][ring]
            on_panel = (behind > group_x + config.min_protrusion / 2) & \
                       (behind < group_x + config.ring_depth)
            if behind.size == 0 or on_panel.mean() < config.ring_fraction:
                return False
        rows, cols = mask.shape
        if max(rows, cols) < config.square_aspect * min(rows, cols) and mask.mean() < config.min_fill:
            return False
        p = pts[sl][mask]
        short, long = sorted((float(np.ptp(p[:, 1])), float(np.ptp(p[:, 2]))))
        return short <= config.max_short and long <= config.max_long

    def groups(labels):
        """(label, slice, mask, the group's median world x) of each group of ``min_pixels`` or more
        that the border does not cut."""
        for k, sl in enumerate(ndimage.find_objects(labels), 1):
            if sl is None:
                continue
            if config.drop_border and (sl[0].start == 0 or sl[1].start == 0 or sl[0].stop == h or sl[1].stop == w):
                continue
            mask = labels[sl] == k
            if mask.sum() >= config.min_pixels:
                yield k, sl, mask, float(np.median(x[sl][mask]))

    cabinet_front = None
    if config.front_band > 0:
        centre = x[front_window(x.shape, config.front_window)]
        cabinet_front = float(np.percentile(centre, config.front_percentile)) if centre.size else None

    def on_front(group_x: float) -> bool:
        return cabinet_front is None or abs(group_x - cabinet_front) <= config.front_band

    out = []
    for k, sl, mask, group_x in groups(labels):
        if handle_like(labels, k, sl, mask, group_x):
            if on_front(group_x):
                out.append(((sl[1].start, sl[0].start, sl[1].stop, sl[0].stop), mask))
            continue
        if not config.split_groups:
            continue
        # again, against the group's own median depth (the front the handle stands on)
        inner = mask & (x[sl] < group_x - config.min_protrusion) & (x[sl] > group_x - config.max_protrusion)
        if inner.sum() < config.min_pixels:  # (most rejected groups: nothing stands out of them)
            continue
        sub_labels = np.zeros((h, w), np.int32)
        sub_labels[sl], _ = ndimage.label(inner, structure=np.ones((3, 3), bool))
        for j, sub_sl, sub_mask, sub_x in groups(sub_labels):
            if handle_like(sub_labels, j, sub_sl, sub_mask, sub_x) and on_front(sub_x):
                out.append(((sub_sl[1].start, sub_sl[0].start, sub_sl[1].stop, sub_sl[0].stop), sub_mask))
    return out


@dataclass(frozen=True)
class ThinProposalConfig:
    """Thin pulls stand only a few millimetres proud (a 7 mm bar 4.5 mm off a drawer front), like a
    front's moulding: depth alone cannot tell them apart, so ``thin_proposals`` only offers them,
    and a solver keeps those its learned model points at too. ``min_protrusion`` (m): how far
    proud; ``max_long`` (m): at most this long (a rail along the top of a cabinet is not a pull)."""

    min_protrusion: float = 0.003
    max_long: float = 0.5


def thin_proposals(depth: np.ndarray, view, main: list, config: ThinProposalConfig = ThinProposalConfig(),
                   base: ProposalConfig = ProposalConfig()) -> list[tuple]:
    """The groups (box, mask) standing ``config.min_protrusion`` proud that ``handle_proposals``
    (``main``, its (box, mask) list) misses: none of ``main`` and none of these holds the other's
    centre. Empty when ``config.min_protrusion`` is 0."""
    from opend_mj.policy.handle_box import centres_overlap

    if config.min_protrusion <= 0:
        return []
    thin = handle_proposals(depth, view, replace(base, min_protrusion=config.min_protrusion,
                                                 max_long=config.max_long))
    if thin and main:
        covered = centres_overlap(np.array([b for b, _ in thin], float), np.array([b for b, _ in main], float))
        thin = [p for p, c in zip(thin, covered.any(1)) if not c]
    return thin
