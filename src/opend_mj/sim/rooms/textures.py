"""Procedural textures (numpy -> PNG bytes in memory, nothing on disk) and colours of the rooms."""

from __future__ import annotations

import io

import numpy as np
from dm_control import mjcf


def png_asset(arr: np.ndarray) -> mjcf.Asset:
    """An in-memory PNG texture asset of an (h, w, 3) image with values 0-255."""
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.clip(arr, 0, 255).astype(np.uint8)).save(buf, format="PNG")
    return mjcf.Asset(buf.getvalue(), ".png")


def tex_wood(rng, base, size=256, planks=8) -> np.ndarray:
    """Wood planks (size x size RGB, 0-255) around the colour ``base`` (0-1)."""
    h = w = size
    ph = h // planks
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    img = np.zeros((h, w, 3))
    for p in range(planks):
        rows = slice(p * ph, (p + 1) * ph)
        col = np.asarray(base) * (1.0 + rng.normal(0.0, 0.09))
        phase = rng.uniform(0, 2 * np.pi)
        freq = rng.uniform(2.5, 5.0)
        y = yy[rows] - p * ph
        grain = np.sin(2 * np.pi * (y / freq + 1.2 * np.sin(2 * np.pi * xx[rows] / rng.uniform(120, 260) + phase)))
        shade = 1.0 + 0.07 * grain + rng.normal(0, 0.02, size=y.shape)
        img[rows] = col[None, None, :] * shade[..., None]
        img[p * ph, :] *= 0.55  # seam between planks
        j = int(rng.integers(0, w))
        img[rows, j : j + 1] *= 0.6  # end joint
    return img * 255.0


def tex_brick(rng, brick, mortar, size=128) -> np.ndarray:
    """Bricks of colour ``brick`` in ``mortar`` (0-1), size x size RGB 0-255."""
    h = w = size
    bh, bw = 16, 32
    img = np.empty((h, w, 3))
    img[:] = np.asarray(mortar)
    for r in range(h // bh):
        off = (bw // 2) * (r % 2)
        for c in range(-1, w // bw + 1):
            x0 = c * bw + off
            col = np.asarray(brick) * (1.0 + rng.normal(0, 0.08))
            xs = slice(max(x0 + 2, 0), min(x0 + bw - 1, w))
            if xs.start < xs.stop:
                img[r * bh + 2 : (r + 1) * bh - 1, xs] = col
    img *= 1.0 + rng.normal(0, 0.03, size=(h, w, 1))
    return img * 255.0


def tex_stripes(rng, c1, c2, size=128) -> np.ndarray:
    """Vertical stripes of colours ``c1`` and ``c2`` (0-1), size x size RGB 0-255."""
    w = size
    period = int(rng.choice([16, 32, 64]))
    frac = rng.uniform(0.3, 0.7)
    x = np.arange(w) % period
    band = (x < frac * period).astype(float)
    row = band[:, None] * np.asarray(c1) + (1 - band[:, None]) * np.asarray(c2)
    img = np.repeat(row[None], size, axis=0)
    img *= 1.0 + rng.normal(0, 0.015, size=(size, w, 1))
    return img * 255.0


def hsv(h, s, v):
    """RGB (0-1) of a hue (wrapped), saturation and value (clipped to 0-1)."""
    import colorsys

    return np.array(colorsys.hsv_to_rgb(h % 1.0, np.clip(s, 0, 1), np.clip(v, 0, 1)))


#: Base colours (RGB 0-1) of wooden floors and furniture.
WOOD_TONES = [(0.72, 0.52, 0.33), (0.55, 0.36, 0.2), (0.82, 0.66, 0.45), (0.42, 0.27, 0.16), (0.66, 0.45, 0.3)]
