"""How a front moved between two depth images from one camera: a drawer's front slides out level,
a door's turns about its hinge (the shift toward the camera grows along it)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class FrontMotionConfig:
    """What :func:`front_motion` reads of two depth images of one front, before and during a pull.

    Pixels that showed the front (within ``on_plane`` m of the most common depth within
    ``front_depth`` m of the panel behind the handle, and ``reach`` m of the handle across and
    up / down) and are now ``min_shift`` to ``max_shift`` m nearer, away from the hand (farther than
    ``hand_clear`` m from the grasp site), say how the front
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
    #: the plane fit drops, up to ``fit_rounds`` times, pixels farther from the plane than
    #: ``outlier_factor`` times the median residual, but no nearer than ``outlier_floor`` (m)
    fit_rounds: int = 3
    outlier_factor: float = 2.5
    outlier_floor: float = 0.01
    #: depth (m) given to pixels with no reading (they fall outside every window)
    no_reading: float = 1e3


def front_motion(depth0: np.ndarray, depth1: np.ndarray, view, centre, panel_x: float, site,
                 config: FrontMotionConfig = FrontMotionConfig()) -> dict | None:
    """How the front around a handle moved between two depth images from one camera, as a plane
    fitted to the shift toward the camera of each pixel that moved: ``across`` and ``up`` (m per m
    along y and z: 0 and 0 for a drawer, the tangent of a side-hinged door's angle across, of a
    flap's up), ``shift`` (m, at the handle), ``spread`` (m, across the front moved), ``pixels``
    and ``parts`` (connected groups of moved pixels: the one that moved most is read where it spans
    ``min_extent`` or more); None where too little of it is seen moving."""
    pts0 = view.point_cloud(np.where(np.isfinite(depth0), depth0, config.no_reading))
    pts1 = view.point_cloud(np.where(np.isfinite(depth1), depth1, config.no_reading))
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
    fit = _fit_shift_plane(y, z, d, config)
    if fit is None:
        return None
    coef, keep = fit
    return {"across": float(coef[1]), "up": float(coef[2]), "shift": float(coef[0]),
            "spread": float(np.ptp(y[keep])), "pixels": int(keep.sum()), "parts": int(n)}


def _fit_shift_plane(y: np.ndarray, z: np.ndarray, d: np.ndarray, config: FrontMotionConfig):
    """(coefficients (shift, across, up), inliers) of ``d = shift + across * y + up * z``, least
    squares dropping what the plane leaves far (the hand's shadow, an edge); None below
    ``min_pixels``."""
    min_pixels = config.min_pixels
    if len(d) < min_pixels:
        return None
    a = np.stack([np.ones(len(y)), y, z], 1)
    keep = np.ones(len(y), bool)
    for _ in range(config.fit_rounds):
        coef, *_ = np.linalg.lstsq(a[keep], d[keep], rcond=None)
        resid = np.abs(d - a @ coef)
        new = resid < max(config.outlier_floor, config.outlier_factor * float(np.median(resid[keep])))
        if new.sum() < min_pixels or (new == keep).all():
            break
        keep = new
    return coef, keep
