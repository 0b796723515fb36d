"""A door's front plane in the depth image: where it ends left and right of the handle, and which
side a single door hinges on."""

from __future__ import annotations

import numpy as np

from opend_mj.policy.perception.config import PerceptionConfig
from opend_mj.policy.perception.handle import HandleEstimate


def door_edges(handle: HandleEstimate, depth: np.ndarray, view,
               config: PerceptionConfig = PerceptionConfig()) -> tuple[float, float] | None:
    """World y of where the door's front plane ends to the left (+y) and to the right (-y) of the
    handle, along the image row through it (the plane the handle stands on: pixels within
    ``plane_tolerance`` of the panel behind the handle; the plane ends after more than
    ``plane_gap_pixels`` pixels off it)."""
    tolerance, gap_pixels = config.plane_tolerance, config.plane_gap_pixels
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
    half = float(handle.size[0]) / 2 + config.handle_margin
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


def door_edges_vertical(handle: HandleEstimate, depth: np.ndarray, view,
                        config: PerceptionConfig = PerceptionConfig()) -> tuple[float, float] | None:
    """World z of where the door's front plane ends above and below the handle, along the image
    column through it (as :func:`door_edges` does along the row): a flap hinged at its top or
    bottom edge has its handle near the other edge."""
    tolerance, gap_pixels = config.plane_tolerance, config.plane_gap_pixels
    h, w = depth.shape
    uc, vc = view.project(handle.centre[None, :])[0]
    if not (np.isfinite(uc) and np.isfinite(vc)):
        return None
    col = int(np.clip(uc, 0, w - 1))
    rows = np.arange(h) + 0.5
    points = view.backproject(np.full(h, col + 0.5), rows, depth[:, col])
    on_plane = np.abs(points[:, 0] - handle.panel_x) < tolerance
    start = int(np.clip(vc, 0, h - 1))
    half = float(handle.size[1]) / 2 + config.handle_margin
    beside = np.abs(points[:, 2] - float(handle.centre[2])) > half
    beside[~np.isfinite(points[:, 2])] = True

    def reach(step: int) -> float:
        row, misses, last = start, 0, start
        while 0 <= row < h and misses <= gap_pixels:
            if on_plane[row]:
                last, misses = row, 0
            elif beside[row]:
                misses += 1
            row += step
        return float(points[last, 2])

    return reach(-1), reach(+1)  # image-up is +z


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
