"""A door's front plane in the depth image: where it ends left and right of the handle, and which
side a single door hinges on."""

from __future__ import annotations

import numpy as np

from opend_mj.policy.perception.config import PerceptionConfig
from opend_mj.policy.perception.handle import HandleEstimate


def _plane_ends(handle: HandleEstimate, depth: np.ndarray, view, config: PerceptionConfig,
                axis: int) -> tuple[float, float] | None:
    """World coordinate ``axis`` (1: y, along the image row through the handle; 2: z, along its
    column) of where the front plane the handle stands on ends on either side of it, in image order
    (decreasing pixel index first). The plane: pixels within ``plane_tolerance`` of the panel behind
    the handle; it ends after more than ``plane_gap_pixels`` pixels off it."""
    h, w = depth.shape
    uc, vc = view.project(handle.centre[None, :])[0]
    if not (np.isfinite(uc) and np.isfinite(vc)):
        return None
    if axis == 1:
        line, n, start = int(np.clip(vc, 0, h - 1)), w, int(np.clip(uc, 0, w - 1))
        points = view.backproject(np.arange(w) + 0.5, np.full(w, line + 0.5), depth[line])
    else:
        line, n, start = int(np.clip(uc, 0, w - 1)), h, int(np.clip(vc, 0, h - 1))
        points = view.backproject(np.full(h, line + 0.5), np.arange(h) + 0.5, depth[:, line])
    on_plane = np.abs(points[:, 0] - handle.panel_x) < config.plane_tolerance

    # the walk starts beside the handle: its own pixels (a knob is 10+ pixels wide) are not a gap
    half = float(handle.size[axis - 1]) / 2 + config.handle_margin
    beside = np.abs(points[:, axis] - float(handle.centre[axis])) > half
    beside[~np.isfinite(points[:, axis])] = True

    def reach(step: int) -> float:
        k, misses, last = start, 0, start
        while 0 <= k < n and misses <= config.plane_gap_pixels:
            if on_plane[k]:
                last, misses = k, 0
            elif beside[k]:
                misses += 1
            k += step
        return float(points[last, axis])

    return reach(-1), reach(+1)


def door_edges(handle: HandleEstimate, depth: np.ndarray, view,
               config: PerceptionConfig = PerceptionConfig()) -> tuple[float, float] | None:
    """World y of where the door's front plane ends to the left (+y) and to the right (-y) of the
    handle, along the image row through it (image-left is +y)."""
    return _plane_ends(handle, depth, view, config, axis=1)


def door_edges_vertical(handle: HandleEstimate, depth: np.ndarray, view,
                        config: PerceptionConfig = PerceptionConfig()) -> tuple[float, float] | None:
    """World z of where the door's front plane ends above and below the handle, along the image
    column through it (image-up is +z): a flap hinged at its top or bottom edge has its handle near
    the other edge."""
    return _plane_ends(handle, depth, view, config, axis=2)


def infer_hinge_side(handle: HandleEstimate, depth: np.ndarray, view,
                     config: PerceptionConfig = PerceptionConfig()) -> str | None:
    """Which side a single door hinges on, from the depth image alone.

    Along the image row through the handle, walk left and right over pixels that lie on the door's
    front plane (:func:`door_edges`) until the plane ends; a handle sits near the free edge, so the
    hinge is on the side where the plane reaches farther: at least ``hinge_min_reach`` (m), and
    ``hinge_min_difference`` (m) farther than on the other side (else None: no verdict).
    """
    edges = door_edges(handle, depth, view, config)
    if edges is None:
        return None
    toward_left, toward_right = (abs(edge - float(handle.centre[1])) for edge in edges)  # image-left is +y
    if max(toward_left, toward_right) < config.hinge_min_reach \
            or abs(toward_left - toward_right) < config.hinge_min_difference:
        return None
    return "left" if toward_left > toward_right else "right"
