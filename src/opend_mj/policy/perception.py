"""Perception from the one RGB-D image: a solver's box snapped to the handle in depth, back-projected
into a 3D handle (centre, orientation, bar or knob, the panel behind it), and a single door's hinge
side. Reads only the depth image and the camera (intrinsics and pose).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from opend_mj.policy.handle import HandleBox


@dataclass
class HandleEstimate:
    centre: np.ndarray  # world, metres: the handle's grip centre
    orientation: str  # "horizontal" | "vertical"
    kind: str  # "bar" | "knob"
    size: tuple[float, float]  # world extent along y and z (m)
    front_x: float
    panel_x: float

    def to_dict(self) -> dict:
        return {"centre": [round(float(x), 4) for x in self.centre], "orientation": self.orientation,
                "kind": self.kind, "size": [round(float(x), 4) for x in self.size],
                "front_x": round(self.front_x, 4), "panel_x": round(self.panel_x, 4)}


@dataclass
class HandleShape:
    """The handle as measured in depth (metres): what a grasp is chosen from.

    ``thickness``: the bar's extent across its long axis; ``length``: along it; ``gap``: free space
    between the back of the bar and the panel (protrusion less thickness); ``protrusion``: front of
    the handle to the panel; ``clear``: free distance from the handle's box to the nearest other
    thing standing out of the panel (another handle, a frame), per side of the handle in the world
    (``up``, ``down``, ``left`` = +y, ``right`` = -y), capped at the search radius."""

    thickness: float
    length: float
    gap: float
    protrusion: float
    clear: dict

    def to_dict(self) -> dict:
        return {"thickness": round(self.thickness, 4), "length": round(self.length, 4), "gap": round(self.gap, 4),
                "protrusion": round(self.protrusion, 4), "clear": {k: round(v, 3) for k, v in self.clear.items()}}


def measure_handle(handle: "HandleEstimate", box: HandleBox, depth: np.ndarray, view, radius: float = 0.15,
                   min_protrusion: float = 0.008) -> HandleShape:
    """Bar thickness, length, stand-off gap and the free space around the handle, from depth alone."""
    # pixels per metre at the handle's distance (to size the search window)
    px_per_m = _px_per_m(view, *box.centre, handle.front_x)
    uu, vv, ok, pts, in_box = _window(box, depth, view, int(math.ceil(radius * px_per_m)))
    x = np.where(ok, pts[..., 0], np.inf)
    panel_x = _panel_around(x, ok, in_box, uu, vv, box, px_per_m)
    panel_x = max(panel_x if panel_x is not None else handle.panel_x, handle.front_x)
    # the bar: pixels in the box within a few mm of the handle's front
    bar = in_box & (x < handle.front_x + 0.006)
    m_per_px = 1.0 / px_per_m
    if bar.sum() >= 2:
        # extents in pixels (rows / columns covered), then metres: area / length for the thickness
        n_cols = int(np.any(bar, axis=0).sum())
        n_rows = int(np.any(bar, axis=1).sum())
        across_h = bar.sum() / max(1, n_cols)  # mean bar height per column (a horizontal bar)
        across_v = bar.sum() / max(1, n_rows)  # mean bar width per row (a vertical bar)
        ext_y, ext_z = n_cols * m_per_px, n_rows * m_per_px
    else:
        ext_y, ext_z = handle.size
        across_h, across_v = ext_z * px_per_m, ext_y * px_per_m
    if handle.orientation == "horizontal":
        length, thickness = ext_y, across_h * m_per_px
    else:
        length, thickness = ext_z, across_v * m_per_px
    if handle.kind == "knob":
        thickness = length = max(ext_y, ext_z)
    protrusion = max(0.0, panel_x - handle.front_x)
    gap = max(0.0, protrusion - thickness)
    # neighbours: anything else standing out of the panel near the handle
    proud = ok & (x < panel_x - min_protrusion) & ~in_box
    grown = (uu >= box.u0 - 0.01 * px_per_m) & (uu <= box.u1 + 0.01 * px_per_m) & \
            (vv >= box.v0 - 0.01 * px_per_m) & (vv <= box.v1 + 0.01 * px_per_m)
    proud &= ~grown
    lo = _ray_plane_x(view, box.u1, box.v1, handle.front_x)  # image right / bottom corner
    hi = _ray_plane_x(view, box.u0, box.v0, handle.front_x)  # image left / top corner
    y_lo, y_hi = min(lo[1], hi[1]), max(lo[1], hi[1])
    z_lo, z_hi = min(lo[2], hi[2]), max(lo[2], hi[2])
    clear = {"up": radius, "down": radius, "left": radius, "right": radius}
    if proud.any():
        q = pts[proud]
        band_z = (q[:, 2] > z_lo - 0.03) & (q[:, 2] < z_hi + 0.03)
        band_y = (q[:, 1] > y_lo - 0.03) & (q[:, 1] < y_hi + 0.03)
        for key, sel, dist in (("left", band_z & (q[:, 1] > y_hi), q[:, 1] - y_hi),
                               ("right", band_z & (q[:, 1] < y_lo), y_lo - q[:, 1]),
                               ("up", band_y & (q[:, 2] > z_hi), q[:, 2] - z_hi),
                               ("down", band_y & (q[:, 2] < z_lo), z_lo - q[:, 2])):
            if sel.any():
                clear[key] = float(min(radius, np.min(dist[sel])))
    return HandleShape(thickness=float(thickness), length=float(length), gap=float(gap),
                       protrusion=float(protrusion), clear=clear)


def _window(box: HandleBox, depth: np.ndarray, view, margin_px: int):
    """The pixels of ``box`` grown by ``margin_px`` (clipped to the image): their centres (uu, vv),
    which have a valid depth (ok), their world points (pts; invalid depths back-projected at 1 m)
    and which lie in the box itself (in_box)."""
    h, w = depth.shape
    u0, v0 = int(max(0, math.floor(box.u0) - margin_px)), int(max(0, math.floor(box.v0) - margin_px))
    u1, v1 = int(min(w, math.ceil(box.u1) + margin_px)), int(min(h, math.ceil(box.v1) + margin_px))
    vv, uu = np.meshgrid(np.arange(v0, v1) + 0.5, np.arange(u0, u1) + 0.5, indexing="ij")
    d = depth[v0:v1, u0:u1]
    ok = np.isfinite(d) & (d > 0.05)
    pts = view.backproject(uu, vv, np.where(ok, d, 1.0))
    in_box = (uu >= box.u0) & (uu <= box.u1) & (vv >= box.v0) & (vv <= box.v1)
    return uu, vv, ok, pts, in_box


def _panel_around(x: np.ndarray, ok: np.ndarray, in_box: np.ndarray, uu: np.ndarray, vv: np.ndarray,
                  box: HandleBox, px_per_m: float, band: float = 0.04) -> float | None:
    """The panel's x: the most common depth (median) of the pixels in a band ``band`` (m) wide just
    around the box (a tight box may hold only the bar); None where fewer than 5 pixels."""
    g = band * px_per_m
    ring = ok & ~in_box & (uu >= box.u0 - g) & (uu <= box.u1 + g) & (vv >= box.v0 - g) & (vv <= box.v1 + g)
    return float(np.median(x[ring])) if ring.sum() >= 5 else None


def _px_per_m(view, u: float, v: float, x: float) -> float:
    """Pixels per metre on the plane of constant ``x`` around pixel (u, v)."""
    p0 = _ray_plane_x(view, u, v, x)
    p1 = _ray_plane_x(view, u + 10.0, v, x)
    return 10.0 / max(1e-6, float(np.linalg.norm(p1 - p0)))


def _ray_plane_x(view, u: float, v: float, x: float) -> np.ndarray:
    """World point where the camera ray through pixel (u, v) meets the plane of constant x."""
    p1 = view.backproject(u, v, 1.0)
    d = p1 - view.pos
    if abs(d[0]) < 1e-9:
        return p1
    t = (x - view.pos[0]) / d[0]
    return view.pos + t * d


def snaps_to_depth(solver, box: HandleBox | None) -> bool:
    """Whether a solver's box is to be snapped to depth (:func:`refine_box_with_depth`): not the
    oracle's exact boxes, nor a box that is a depth proposal already."""
    return box is not None and not getattr(solver, "exact", False) and not box.from_depth


def refine_box_with_depth(box: HandleBox, depth: np.ndarray, view, margin_px: int = 12,
                          min_protrusion: float = 0.015, max_protrusion: float = 0.08) -> HandleBox:
    """Snap a solver's box to the handle that stands out of the panel in the depth image.

    Handles stand 3-4.5 cm proud of their door or drawer front. Around the box (grown by `margin_px`)
    the panel is the most common depth; pixels at least `min_protrusion` nearer are handle. The
    connected group of such pixels nearest the box centre becomes the box. Where there is none the
    box is returned unchanged.
    """
    from scipy import ndimage

    h, w = depth.shape
    u0 = int(max(0, math.floor(box.u0) - margin_px))
    v0 = int(max(0, math.floor(box.v0) - margin_px))
    u1 = int(min(w, math.ceil(box.u1) + margin_px))
    v1 = int(min(h, math.ceil(box.v1) + margin_px))
    if u1 - u0 < 3 or v1 - v0 < 3:
        return box
    vv, uu = np.meshgrid(np.arange(v0, v1) + 0.5, np.arange(u0, u1) + 0.5, indexing="ij")
    d = depth[v0:v1, u0:u1]
    if not np.isfinite(d).any():
        return box
    x = view.backproject(uu.ravel(), vv.ravel(), d.ravel())[:, 0].reshape(d.shape)
    panel_x = float(np.nanmedian(x))
    proud = (x < panel_x - min_protrusion) & (x > panel_x - max_protrusion)
    labels, n = ndimage.label(proud)
    if n == 0:
        return box
    uc, vc = box.centre
    best, best_dist = 0, np.inf
    for k in range(1, n + 1):
        rows, cols = np.nonzero(labels == k)
        if len(rows) < 3:
            continue
        dist = float(np.min(np.hypot(cols + u0 + 0.5 - uc, rows + v0 + 0.5 - vc)))
        if dist < best_dist:
            best, best_dist = k, dist
    if best == 0:
        return box
    rows, cols = np.nonzero(labels == best)
    return HandleBox(u0 + cols.min(), v0 + rows.min(), u0 + cols.max() + 1, v0 + rows.max() + 1,
                     orientation=box.orientation)


def one_of_paired_handles(box: HandleBox, depth: np.ndarray, min_protrusion: float = 0.015,
                          max_protrusion: float = 0.08, centre_px: int = 2) -> HandleBox | None:
    """The nearer of two or more separate handles that one box covers, or None when it covers one.

    Some fronts carry a pair of pulls (a cup pull near each end): the target's handle box then spans
    both, and its centre is bare panel. Inside the box, pixels standing `min_protrusion` or more out of
    the panel are handle; when the box centre (within `centre_px`) is not such a pixel and the handle
    pixels form two or more groups, the group nearest the centre becomes the box (the first in image
    order on a tie).
    """
    from scipy import ndimage

    h, w = depth.shape
    u0, v0 = int(max(0, math.floor(box.u0))), int(max(0, math.floor(box.v0)))
    u1, v1 = int(min(w, math.ceil(box.u1))), int(min(h, math.ceil(box.v1)))
    if u1 - u0 < 3 or v1 - v0 < 1:
        return None
    around = depth[max(0, v0 - 6):min(h, v1 + 6), max(0, u0 - 6):min(w, u1 + 6)]
    around = around[np.isfinite(around)]
    if around.size == 0:
        return None
    panel = float(np.median(around))  # the panel: the common depth around the box
    inner = depth[v0:v1, u0:u1]
    proud = (inner < panel - min_protrusion) & (inner > panel - max_protrusion)
    uc, vc = box.centre
    cu, cv = int(uc) - u0, int(vc) - v0
    near = proud[max(0, cv - centre_px):cv + centre_px + 1, max(0, cu - centre_px):cu + centre_px + 1]
    if near.any():
        return None
    labels, n = ndimage.label(proud, structure=np.ones((3, 3), bool))
    groups = [np.nonzero(labels == k) for k in range(1, n + 1)]
    groups = [g for g in groups if len(g[0]) >= 3]
    if len(groups) < 2:
        return None
    rows, cols = min(groups, key=lambda g: float(np.min(np.hypot(g[1] + u0 + 0.5 - uc, g[0] + v0 + 0.5 - vc))))
    return HandleBox(u0 + cols.min(), v0 + rows.min(), u0 + cols.max() + 1, v0 + rows.max() + 1,
                     orientation=box.orientation, score=box.score)


def estimate_handle(box: HandleBox, depth: np.ndarray, view, config) -> HandleEstimate | None:
    """Back-project the solver's box with the depth image into a 3D handle centre and orientation,
    with the front of the handle and the panel behind it (:func:`_panel_behind_tight_box`).

    ``config``: the planner's settings (``handle_radius``, ``knob_aspect``, ``knob_size``)."""
    h, w = depth.shape
    u0, v0 = int(max(0, math.floor(box.u0))), int(max(0, math.floor(box.v0)))
    u1, v1 = int(min(w, math.ceil(box.u1))), int(min(h, math.ceil(box.v1)))
    if u1 <= u0 or v1 <= v0:
        return None
    vv, uu = np.meshgrid(np.arange(v0, v1) + 0.5, np.arange(u0, u1) + 0.5, indexing="ij")
    d = depth[v0:v1, u0:u1]
    ok = np.isfinite(d) & (d > 0.05)
    if ok.sum() < 1:
        return None
    pts = view.backproject(uu[ok], vv[ok], d[ok])
    xs = pts[:, 0]
    front_x = float(np.percentile(xs, 3))
    panel_x = float(np.percentile(xs, 95))
    uc, vc = box.centre
    around = _panel_behind_tight_box(box, depth, view, xs, front_x)
    if around is not None:
        panel_x = around
    centre_x = front_x + config.handle_radius
    centre = _ray_plane_x(view, uc, vc, centre_x)
    # world extent of the box on the handle's plane
    c00 = _ray_plane_x(view, box.u0, box.v0, centre_x)
    c11 = _ray_plane_x(view, box.u1, box.v1, centre_x)
    size_y, size_z = abs(c00[1] - c11[1]), abs(c00[2] - c11[2])
    long_, short = max(size_y, size_z), max(min(size_y, size_z), 1e-4)
    if box.orientation in ("horizontal", "vertical"):
        orientation = box.orientation
    else:
        orientation = "horizontal" if size_y >= size_z else "vertical"
    kind = "knob" if (long_ / short < config.knob_aspect and long_ < config.knob_size) else "bar"
    return HandleEstimate(centre=centre, orientation=orientation, kind=kind, size=(size_y, size_z),
                          front_x=front_x, panel_x=panel_x)


def _panel_behind_tight_box(box: HandleBox, depth: np.ndarray, view, xs: np.ndarray, front_x: float,
                            near: float = 0.01, panel_share: float = 0.1, band: float = 0.04) -> float | None:
    """The panel's x seen around a box that holds only the handle, else None.

    A box snapped to the handle in depth (:func:`refine_box_with_depth`) is the handle's own
    pixels, all standing out of the panel, so the far end of its depths is the bar, not the panel
    (on 45385's low door bar 2 cm in front of it, which moved the door's hinge as much). Where
    fewer than ``panel_share`` of the box's pixels are within ``near`` (m) of the depth just around
    it (:func:`_panel_around`, in a band ``band`` m wide), that depth is the panel. A box that shows
    the panel between and beside the bar (an annotated box, a loose one) keeps its own far depths."""
    px_per_m = _px_per_m(view, *box.centre, front_x)
    uu, vv, ok, pts, in_box = _window(box, depth, view, int(math.ceil(band * px_per_m)) + 1)
    x = np.where(ok, pts[..., 0], np.inf)
    panel = _panel_around(x, ok, in_box, uu, vv, box, px_per_m, band)
    if panel is None or panel <= front_x:
        return None
    if float(np.mean(np.abs(xs - panel) < near)) >= panel_share:
        return None
    return panel


def door_edges(handle: HandleEstimate, depth: np.ndarray, view, tolerance: float = 0.03,
               gap_pixels: int = 3) -> tuple[float, float] | None:
    """World y of where the door's front plane ends to the left (+y) and to the right (-y) of the
    handle, along the image row through it (the plane the handle stands on)."""
    h, w = depth.shape
    uc, vc = view.project(handle.centre[None, :])[0]
    if not (np.isfinite(uc) and np.isfinite(vc)):
        return None
    row = int(np.clip(vc, 0, h - 1))
    cols = np.arange(w) + 0.5
    points = view.backproject(cols, np.full(w, row + 0.5), depth[row])
    on_plane = np.abs(points[:, 0] - handle.panel_x) < tolerance
    start = int(np.clip(uc, 0, w - 1))

    # the walk starts beside the handle: its own pixels (a knob is 10+ pixels wide) are not a gap
    half = float(handle.size[0]) / 2 + 0.01
    beside = np.abs(points[:, 1] - float(handle.centre[1])) > half
    beside[~np.isfinite(points[:, 1])] = True

    def reach(step: int) -> float:
        col, misses, last = start, 0, start
        while 0 <= col < w and misses <= gap_pixels:
            if on_plane[col]:
                last, misses = col, 0
            elif beside[col]:
                misses += 1
            col += step
        return float(points[last, 1])

    return reach(-1), reach(+1)  # image-left is +y


def infer_hinge_side(handle: HandleEstimate, depth: np.ndarray, view, tolerance: float = 0.03,
                     gap_pixels: int = 3) -> str | None:
    """Which side a single door hinges on, from the depth image alone.

    Along the image row through the handle, walk left and right over pixels that lie on the door's
    front plane (within `tolerance` of the panel seen behind the handle) until the plane ends; a handle
    sits near the free edge, so the hinge is on the side where the plane reaches farther.
    """
    edges = door_edges(handle, depth, view, tolerance, gap_pixels)
    if edges is None:
        return None
    toward_left, toward_right = (abs(edge - float(handle.centre[1])) for edge in edges)  # image-left is +y
    if max(toward_left, toward_right) < 0.05 or abs(toward_left - toward_right) < 0.02:
        return None
    return "left" if toward_left > toward_right else "right"


# --------------------------------------------------------------------------------------------------
# Handle proposals from depth (for learned solvers: their map says which, depth says where exactly)
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ProposalConfig:
    """Handles stand 1.2-9 cm proud of the panel they sit on: ``handle_proposals`` finds such groups.

    A pixel is proud when it is between ``min_protrusion`` and ``max_protrusion`` nearer (world x)
    than the median of its ``window``-pixel neighbourhood. A connected group of at least ``min_pixels``
    is a proposal when a ring ``ring`` pixels wide around it lies mostly (``ring_fraction``) on a panel
    just behind it (the silhouette corners of a cabinet against the room are not), and its extent
    (m) is handle-like: at most ``max_short`` across and ``max_long`` along (a raised door panel's
    frame is not). Tuned on the real train part of the OpenD cabinets and the procedural train split
    (candidates hold the named handle in 93 % / 99 % of images, 3-4 per image)."""

    window: int = 25
    stride: int = 2
    min_protrusion: float = 0.012
    max_protrusion: float = 0.09
    min_pixels: int = 3
    ring: int = 4
    ring_fraction: float = 0.6
    #: How far (m) behind the group a ring pixel may lie and still be the panel it sits on (a pull
    #: over a finger recess: the recess is panel too; the room behind a cabinet's corner is not).
    #: 0.11 lost a real bottom drawer's pull over an 8 cm recess; 0.2 keeps it and changes nothing
    #: else on the real train part (three draws) or the procedural train split; 0.3 loses targets
    #: there (corners against a wall close behind).
    ring_depth: float = 0.2
    max_short: float = 0.07
    max_long: float = 0.95
    #: A group too large or not ringed by a panel (a narrow cabinet's whole front stands proud of a
    #: window that reaches the room behind it, and the handle with it) is searched again against its
    #: own median depth: the front it is part of.
    split_groups: bool = True
    #: Groups touching the image's border are dropped: what the frame cuts (the room's furniture,
    #: the floor's edge, a cabinet side) cannot be told for a handle, nor a handle's position read
    #: from it; the camera frames the cabinet, and no target handle of the real train part or the
    #: procedural splits touches the border, while 1 in 7 proposals there did.
    drop_border: bool = True
    #: Groups standing more than ``front_band`` (m) nearer or farther than the cabinet's front are
    #: dropped: the room's furniture beside the cabinet (a desk's leg, a shelf's edge). The front is
    #: the 20th percentile of world x over the image's central window (the camera frames the
    #: cabinet there). On the real train part (three draws of the rooms) and the procedural train
    #: split every proposal on a handle stands within 6 cm of it; the 1 in 20 proposals beyond 30 cm
    #: were all on room furniture. 0: keep every group.
    front_band: float = 0.2
    #: A square-ish group (box sides within ``square_aspect`` of each other) must fill ``min_fill``
    #: of its box: a knob or a bar's end fills 0.67-0.88 of it, the corner of a raised panel's
    #: frame (an L) about half. On the real train part and the procedural train split no group on
    #: a handle is dropped; on the real train part the one square group on no handle is. 0: off.
    min_fill: float = 0.6
    square_aspect: float = 2.0


def handle_proposals(depth: np.ndarray, view, config: ProposalConfig = ProposalConfig()) -> list[tuple]:
    """Boxes (u0, v0, u1, v1) and pixel masks of the groups in ``depth`` that look like handles:
    a list of (box, mask), mask a bool array over the box's pixels (rows v0:v1, columns u0:u1)."""
    from scipy import ndimage

    h, w = depth.shape
    vv, uu = np.meshgrid(np.arange(h) + 0.5, np.arange(w) + 0.5, indexing="ij")
    d = np.where(np.isfinite(depth), depth, np.nanmax(depth[np.isfinite(depth)]) if np.isfinite(depth).any() else 0.0)
    pts = view.backproject(uu.ravel(), vv.ravel(), d.ravel()).reshape(h, w, 3)
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
        centre = x[int(h * 0.3):int(h * 0.7), int(w * 0.35):int(w * 0.65)]
        cabinet_front = float(np.percentile(centre, 20)) if centre.size else None

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
    from dataclasses import replace

    from opend_mj.policy.handle import centres_overlap

    if config.min_protrusion <= 0:
        return []
    thin = handle_proposals(depth, view, replace(base, min_protrusion=config.min_protrusion,
                                                 max_long=config.max_long))
    if thin and main:
        covered = centres_overlap(np.array([b for b, _ in thin], float), np.array([b for b, _ in main], float))
        thin = [p for p, c in zip(thin, covered.any(1)) if not c]
    return thin


# --------------------------------------------------------------------------------------------------
# How a front moved: a drawer's slides out level, a door's turns about its hinge
# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FrontMotionConfig:
    """What :func:`front_motion` reads of two depth images of one front, before and during a pull.

    Pixels that showed the front (within ``on_plane`` m of the most common depth within
    ``front_depth`` m of the panel behind the handle, and ``reach`` m of the handle across and
    up / down) and are now at least ``min_shift`` m nearer, away from the hand, say how the front
    moved: a drawer's front slides out level (the shift is the same across it), a door's turns
    (the shift grows along it, the slope is the tangent of the door's angle)."""

    on_plane: float = 0.015
    reach: tuple = (0.4, 0.3)
    #: the front is looked for within this (m) of the panel behind the handle
    front_depth: float = 0.1
    min_shift: float = 0.02
    max_shift: float = 0.6
    hand_clear: float = 0.12
    #: what is seen more than this (m) nearer the camera than the grasp site is the hand, not the
    #: front it holds (a drawer's front stays behind its handle; a door's free edge beyond the
    #: handle comes out a little ahead of it)
    before_site: float = 0.03
    #: fewer moved pixels than this say nothing (a sliver of a front fits any slope)
    min_pixels: int = 200
    #: where the moved pixels fall apart, the part that moved most is read alone if it spans this
    #: much (m) across
    min_extent: float = 0.1


def front_motion(depth0: np.ndarray, depth1: np.ndarray, view, centre, panel_x: float, site,
                 config: FrontMotionConfig = FrontMotionConfig()) -> dict | None:
    """How the front around a handle moved between two depth images from one camera, as a plane
    fitted to the shift toward the camera of each pixel that moved: ``across`` and ``up`` (m per m
    along y and z: 0 and 0 for a drawer, the tangent of a side-hinged door's angle across, of a
    flap's up), ``shift`` (m, at the handle), ``spread`` (m, across the front moved), ``pixels``
    and ``parts`` (connected groups of moved pixels: the one that moved most is read where it spans
    ``min_extent`` or more); None where too little of it is seen moving."""
    pts0 = view.point_cloud(np.where(np.isfinite(depth0), depth0, 1e3))
    pts1 = view.point_cloud(np.where(np.isfinite(depth1), depth1, 1e3))
    centre = np.asarray(centre, float)
    around = ((np.abs(pts0[..., 1] - centre[1]) < config.reach[0])
              & (np.abs(pts0[..., 2] - centre[2]) < config.reach[1])
              & (np.abs(pts0[..., 0] - panel_x) < config.front_depth))
    if not around.any():
        return None
    # the front: the most common depth around the handle (a panel estimated from the handle's own
    # ring can sit on a lip or a frame beside the front)
    xs = pts0[..., 0][around]
    hist, edges = np.histogram(xs, bins=np.arange(xs.min(), xs.max() + 2 * config.on_plane, config.on_plane))
    peak = int(np.argmax(hist))
    front_x = float(np.median(xs[(xs >= edges[peak] - config.on_plane) & (xs < edges[peak + 1] + config.on_plane)]))
    sel = around & (np.abs(pts0[..., 0] - front_x) < config.on_plane)
    shift = pts0[..., 0] - pts1[..., 0]
    site = np.asarray(site, float)
    # not the hand: away from the grasp site, and not in front of it (the palm, the wrist)
    clear = (np.linalg.norm(pts1 - site, axis=-1) > config.hand_clear) \
        & (pts1[..., 0] >= site[0] - config.before_site)
    moved = sel & clear & (shift > config.min_shift) & (shift < config.max_shift)
    if int(moved.sum()) < config.min_pixels:
        return None
    # the part that moved most: a double door's two leaves move apart, one plane over both reads
    # level where each of them turned; the seam between them splits the moved pixels
    from scipy import ndimage

    labels, n = ndimage.label(moved)
    if n > 1:
        sizes = ndimage.sum(np.ones_like(shift), labels, index=np.arange(1, n + 1))
        pushed = ndimage.sum(np.where(moved, shift, 0.0), labels, index=np.arange(1, n + 1))
        best = int(np.argmax(np.where(sizes >= config.min_pixels, pushed, -1.0))) + 1
        part = labels == best
        if part.sum() >= config.min_pixels and np.ptp(pts0[..., 1][part]) >= config.min_extent:
            moved = part
    y, z, d = pts0[..., 1][moved] - centre[1], pts0[..., 2][moved] - centre[2], shift[moved]
    fit = _fit_shift_plane(y, z, d, config.min_pixels)
    if fit is None:
        return None
    coef, keep = fit
    return {"across": float(coef[1]), "up": float(coef[2]), "shift": float(coef[0]),
            "spread": float(np.ptp(y[keep])), "pixels": int(keep.sum()), "parts": int(n)}


def _fit_shift_plane(y: np.ndarray, z: np.ndarray, d: np.ndarray, min_pixels: int):
    """(coefficients (shift, across, up), inliers) of ``d = shift + across * y + up * z``, least
    squares dropping what the plane leaves far (the hand's shadow, an edge); None below
    ``min_pixels``."""
    if len(d) < min_pixels:
        return None
    a = np.stack([np.ones(len(y)), y, z], 1)
    keep = np.ones(len(y), bool)
    for _ in range(3):
        coef, *_ = np.linalg.lstsq(a[keep], d[keep], rcond=None)
        resid = np.abs(d - a @ coef)
        new = resid < max(0.01, 2.5 * float(np.median(resid[keep])))
        if new.sum() < min_pixels or (new == keep).all():
            break
        keep = new
    return coef, keep
