"""How noisy a depth image is, read from the image itself: perception allows for it where a
threshold in millimetres would otherwise meet noise of the same size (a real sensor's, or
`sim.perturb`'s depth_noise)."""

from __future__ import annotations

import math

import numpy as np

#: Where the camera frames the cabinet's front: rows from, to; columns from, to (fractions of the
#: image). Perception reads the front's depth and its noise there.
FRONT_WINDOW = (0.3, 0.7, 0.35, 0.65)


def front_window(shape: tuple, window: tuple = FRONT_WINDOW, step: int = 1) -> tuple[slice, slice]:
    """The (rows, columns) slices of ``window`` in an image of ``shape``, every ``step``-th column."""
    h, w = shape[:2]
    r0, r1, c0, c1 = window
    return slice(int(h * r0), int(h * r1)), slice(int(w * c0), int(w * c1), max(1, int(step)))


def front_noise(x: np.ndarray, ok: np.ndarray, floor: float, window: tuple = FRONT_WINDOW,
                step: int = 1) -> float:
    """:func:`pixel_noise` of ``x`` (valid where ``ok``) over ``window`` (:func:`front_window`), from
    every ``step``-th column (columns averaged together are not independent)."""
    rows, cols = front_window(x.shape, window, step)
    return pixel_noise(x[rows, cols], ok[rows, cols], floor)


def pixel_noise(x: np.ndarray, ok: np.ndarray, floor: float) -> float:
    """The noise (m, one sigma) of a grid of world coordinates ``x`` (valid where ``ok``): the robust
    spread, 1.4826 MAD / sqrt(6), of the second differences along rows (x[u+1] - 2 x[u] + x[u-1]).
    A surface, flat or sloped, gives second differences of about 0 and an edge moves few of them;
    noise moves them all. 0 below ``floor`` (exact depth) or where fewer than 16 triples are valid."""
    triple = ok[:, 2:] & ok[:, 1:-1] & ok[:, :-2]
    if triple.sum() < 16:
        return 0.0
    second = (x[:, 2:] - 2.0 * x[:, 1:-1] + x[:, :-2])[triple]
    sigma = 1.4826 * float(np.median(np.abs(second - np.median(second)))) / math.sqrt(6.0)
    return sigma if sigma >= floor else 0.0


def fill_holes(depth: np.ndarray) -> np.ndarray:
    """``depth`` (m) with a sensor's missing pixels (0, or not finite) set to the nearest pixel with
    a reading: a model trained on renders, which have none, reads a hole as a surface right at the
    lens. Depth without holes comes back unchanged."""
    d = np.asarray(depth, np.float32)
    missing = ~np.isfinite(d) | (d <= 0)
    if not missing.any() or missing.all():
        return d
    from scipy.ndimage import distance_transform_edt

    nearest = distance_transform_edt(missing, return_distances=False, return_indices=True)
    return d[tuple(nearest)]
