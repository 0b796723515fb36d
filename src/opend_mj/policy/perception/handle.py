"""The handle from a solver's box and the depth image: snapped to what stands out of the panel,
back-projected into 3D (centre, orientation, bar or knob, the panel behind it), and measured
(thickness, length, stand-off gap, free space around it). Reads only the depth image and the camera.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from opend_mj.policy.handle_box import HandleBox
from opend_mj.policy.perception.config import PerceptionConfig
from opend_mj.policy.perception.noise import pixel_noise


@dataclass
class HandleEstimate:
    """The handle in 3D, from a box and the depth image (world frame, metres)."""

    centre: np.ndarray  # world, metres: the handle's grip centre
    orientation: str  # "horizontal" | "vertical"
    kind: str  # "bar" | "knob"
    size: tuple[float, float]  # world extent along y and z (m)
    front_x: float  # world x of the handle's front (nearest to the camera)
    panel_x: float  # world x of the panel the handle stands on
    noise: float = 0.0  # depth noise seen around the handle (m, sigma; 0 below PerceptionConfig.noise_floor)

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


def measure_handle(handle: "HandleEstimate", box: HandleBox, depth: np.ndarray, view,
                   config: PerceptionConfig = PerceptionConfig()) -> HandleShape:
    """Bar thickness, length, stand-off gap and the free space around the handle, from depth alone."""
    radius = config.search_radius
    # pixels per metre at the handle's distance (to size the search window)
    px_per_m = _px_per_m(view, *box.centre, handle.front_x)
    uu, vv, ok, pts, in_box = _window(box, depth, view, int(math.ceil(radius * px_per_m)), config)
    x = np.where(ok, pts[..., 0], np.inf)
    panel_x = _panel_around(x, ok, in_box, uu, vv, box, px_per_m, config, handle.front_x)
    panel_x = max(panel_x if panel_x is not None else handle.panel_x, handle.front_x)
    # the bar: pixels in the box within a few mm of the handle's front
    bar = in_box & (x < handle.front_x + config.bar_depth + config.bar_noise_depth * handle.noise)
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
    proud = ok & (x < panel_x - config.neighbour_protrusion - config.neighbour_noise_depth * handle.noise) & ~in_box
    m = config.handle_margin
    grown = (uu >= box.u0 - m * px_per_m) & (uu <= box.u1 + m * px_per_m) & \
            (vv >= box.v0 - m * px_per_m) & (vv <= box.v1 + m * px_per_m)
    proud &= ~grown
    lo = _ray_plane_x(view, box.u1, box.v1, handle.front_x)  # image right / bottom corner
    hi = _ray_plane_x(view, box.u0, box.v0, handle.front_x)  # image left / top corner
    y_lo, y_hi = min(lo[1], hi[1]), max(lo[1], hi[1])
    z_lo, z_hi = min(lo[2], hi[2]), max(lo[2], hi[2])
    clear = {"up": radius, "down": radius, "left": radius, "right": radius}
    if proud.any():
        q = pts[proud]
        b = config.neighbour_band
        band_z = (q[:, 2] > z_lo - b) & (q[:, 2] < z_hi + b)
        band_y = (q[:, 1] > y_lo - b) & (q[:, 1] < y_hi + b)
        for key, sel, dist in (("left", band_z & (q[:, 1] > y_hi), q[:, 1] - y_hi),
                               ("right", band_z & (q[:, 1] < y_lo), y_lo - q[:, 1]),
                               ("up", band_y & (q[:, 2] > z_hi), q[:, 2] - z_hi),
                               ("down", band_y & (q[:, 2] < z_lo), z_lo - q[:, 2])):
            if sel.any():
                clear[key] = float(min(radius, np.min(dist[sel])))
    return HandleShape(thickness=float(thickness), length=float(length), gap=float(gap),
                       protrusion=float(protrusion), clear=clear)


def _window(box: HandleBox, depth: np.ndarray, view, margin_px: int, config: PerceptionConfig):
    """The pixels of ``box`` grown by ``margin_px`` (clipped to the image): their centres (uu, vv),
    which have a valid depth (ok), their world points (pts; invalid depths back-projected at 1 m)
    and which lie in the box itself (in_box)."""
    h, w = depth.shape
    u0, v0 = int(max(0, math.floor(box.u0) - margin_px)), int(max(0, math.floor(box.v0) - margin_px))
    u1, v1 = int(min(w, math.ceil(box.u1) + margin_px)), int(min(h, math.ceil(box.v1) + margin_px))
    vv, uu = np.meshgrid(np.arange(v0, v1) + 0.5, np.arange(u0, u1) + 0.5, indexing="ij")
    d = depth[v0:v1, u0:u1]
    ok = np.isfinite(d) & (d > config.min_depth)
    pts = view.backproject(uu, vv, np.where(ok, d, 1.0))
    in_box = (uu >= box.u0) & (uu <= box.u1) & (vv >= box.v0) & (vv <= box.v1)
    return uu, vv, ok, pts, in_box


def _panel_around(x: np.ndarray, ok: np.ndarray, in_box: np.ndarray, uu: np.ndarray, vv: np.ndarray,
                  box: HandleBox, px_per_m: float, config: PerceptionConfig, front_x: float) -> float | None:
    """The panel's x: the most common depth (median) of the pixels in a band ``panel_band`` (m)
    wide just around the box (a tight box may hold only the bar), no more than ``panel_max_behind``
    behind the handle's front ``front_x`` (m); None where fewer than ``panel_min_pixels``."""
    g = config.panel_band * px_per_m
    ring = ok & ~in_box & (uu >= box.u0 - g) & (uu <= box.u1 + g) & (vv >= box.v0 - g) & (vv <= box.v1 + g)
    ring &= x <= front_x + config.panel_max_behind
    return float(np.median(x[ring])) if ring.sum() >= config.panel_min_pixels else None


def _px_per_m(view, u: float, v: float, x: float) -> float:
    """Pixels per metre on the plane of constant ``x`` around pixel (u, v) (measured over 10 pixels)."""
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


def refine_box_with_depth(box: HandleBox, depth: np.ndarray, view,
                          config: PerceptionConfig = PerceptionConfig()) -> HandleBox:
    """Snap a solver's box to the handle that stands out of the panel in the depth image.

    Around the box (grown by ``snap_margin_px``) the panel is the most common depth; pixels
    ``snap_protrusion`` nearer are handle. The connected group of such pixels (of at least
    ``min_group_pixels``) nearest the box centre becomes the box. Where there is none the box is
    returned unchanged.
    """
    from scipy import ndimage

    margin_px = config.snap_margin_px
    min_protrusion, max_protrusion = config.snap_protrusion
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
        if len(rows) < config.min_group_pixels:
            continue
        dist = float(np.min(np.hypot(cols + u0 + 0.5 - uc, rows + v0 + 0.5 - vc)))
        if dist < best_dist:
            best, best_dist = k, dist
    if best == 0:
        return box
    rows, cols = np.nonzero(labels == best)
    return HandleBox(u0 + cols.min(), v0 + rows.min(), u0 + cols.max() + 1, v0 + rows.max() + 1,
                     orientation=box.orientation)


def one_of_paired_handles(box: HandleBox, depth: np.ndarray,
                          config: PerceptionConfig = PerceptionConfig()) -> HandleBox | None:
    """The nearer of two or more separate handles that one box covers, or None when it covers one.

    Some fronts carry a pair of pulls (a cup pull near each end): the target's handle box then spans
    both, and its centre is bare panel. The panel is the median depth of the box grown by
    ``paired_ring_px``; inside the box, pixels standing ``snap_protrusion`` out of it are handle;
    when the box centre (within ``paired_centre_px``) is not such a pixel and the handle pixels form
    two or more groups (of ``min_group_pixels`` or more), the group nearest the centre becomes the
    box (the first in image order on a tie).
    """
    from scipy import ndimage

    min_protrusion, max_protrusion = config.snap_protrusion
    centre_px, ring = config.paired_centre_px, config.paired_ring_px
    h, w = depth.shape
    u0, v0 = int(max(0, math.floor(box.u0))), int(max(0, math.floor(box.v0)))
    u1, v1 = int(min(w, math.ceil(box.u1))), int(min(h, math.ceil(box.v1)))
    if u1 - u0 < 3 or v1 - v0 < 1:
        return None
    around = depth[max(0, v0 - ring):min(h, v1 + ring), max(0, u0 - ring):min(w, u1 + ring)]
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
    groups = [g for g in groups if len(g[0]) >= config.min_group_pixels]
    if len(groups) < 2:
        return None
    rows, cols = min(groups, key=lambda g: float(np.min(np.hypot(g[1] + u0 + 0.5 - uc, g[0] + v0 + 0.5 - vc))))
    return HandleBox(u0 + cols.min(), v0 + rows.min(), u0 + cols.max() + 1, v0 + rows.max() + 1,
                     orientation=box.orientation, score=box.score)


def estimate_handle(box: HandleBox, depth: np.ndarray, view,
                    config: PerceptionConfig = PerceptionConfig()) -> HandleEstimate | None:
    """Back-project the solver's box with the depth image into a 3D handle centre and orientation,
    with the front of the handle (a low percentile of the box's depths) and the panel behind it (a
    high percentile, or the ring around a box that holds only the handle:
    :func:`_panel_behind_tight_box`); a small square-ish box is a knob."""
    h, w = depth.shape
    u0, v0 = int(max(0, math.floor(box.u0))), int(max(0, math.floor(box.v0)))
    u1, v1 = int(min(w, math.ceil(box.u1))), int(min(h, math.ceil(box.v1)))
    if u1 <= u0 or v1 <= v0:
        return None
    vv, uu = np.meshgrid(np.arange(v0, v1) + 0.5, np.arange(u0, u1) + 0.5, indexing="ij")
    d = depth[v0:v1, u0:u1]
    ok = np.isfinite(d) & (d > config.min_depth)
    if ok.sum() < 1:
        return None
    pts = view.backproject(uu[ok], vv[ok], d[ok])
    xs = pts[:, 0]
    front_x = float(np.percentile(xs, config.front_percentile))
    noise = _depth_noise(box, depth, view, front_x, config)
    front_x += config.front_noise_shift * noise
    behind = xs[xs <= front_x + config.panel_max_behind]
    panel_x = float(np.percentile(behind if len(behind) else xs, config.panel_percentile))
    uc, vc = box.centre
    around = _panel_behind_tight_box(box, depth, view, xs, front_x, config)
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
                          front_x=front_x, panel_x=panel_x, noise=noise)


def _depth_noise(box: HandleBox, depth: np.ndarray, view, front_x: float, config: PerceptionConfig) -> float:
    """The depth noise (m) in the box and the band around it (`noise.pixel_noise`)."""
    px_per_m = _px_per_m(view, *box.centre, front_x)
    _, _, ok, pts, _ = _window(box, depth, view, int(math.ceil(config.panel_band * px_per_m)) + 1, config)
    return pixel_noise(pts[..., 0], ok, config.noise_floor)


def _panel_behind_tight_box(box: HandleBox, depth: np.ndarray, view, xs: np.ndarray, front_x: float,
                            config: PerceptionConfig) -> float | None:
    """The panel's x seen around a box that holds only the handle, else None.

    A box snapped to the handle in depth (:func:`refine_box_with_depth`) is the handle's own
    pixels, all standing out of the panel, so the far end of its depths is the bar, not the panel
    (placing a door's hinge that far in front of the door). Where fewer than ``panel_share`` of the
    box's pixels are within ``panel_near`` (m) of the depth just around it (:func:`_panel_around`),
    that depth is the panel. A box that shows the panel between and beside the bar (an annotated
    box, a loose one) keeps its own far depths."""
    px_per_m = _px_per_m(view, *box.centre, front_x)
    uu, vv, ok, pts, in_box = _window(box, depth, view, int(math.ceil(config.panel_band * px_per_m)) + 1, config)
    x = np.where(ok, pts[..., 0], np.inf)
    panel = _panel_around(x, ok, in_box, uu, vv, box, px_per_m, config, front_x)
    if panel is None or panel <= front_x:
        return None
    if float(np.mean(np.abs(xs - panel) < config.panel_near)) >= config.panel_share:
        return None
    return panel
