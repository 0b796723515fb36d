"""What perturbation axes (`sim.perturb`) add to a scene's MJCF: everyday objects (the distractors
axis) and textures no training render has (the texture axis)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Distractor:
    """One everyday object: a name, its parts (type, centre offset, size, rgba) and where it stands."""

    name: str
    pos: tuple[float, float, float]  # centre of its base, world (m)
    half: tuple[float, float, float]  # half extents of its bounding box (m)
    parts: tuple = ()

    def box(self) -> tuple[np.ndarray, np.ndarray]:
        p, h = np.asarray(self.pos, float), np.asarray(self.half, float)
        return p - np.array([h[0], h[1], 0.0]), p + np.array([h[0], h[1], 2 * h[2]])


def everyday_object(rng, name: str, small: bool) -> tuple[tuple[float, float, float], tuple]:
    """(half extents, parts) of an everyday object; parts' offsets are from the base centre."""
    colour = tuple(float(c) for c in np.clip(rng.uniform(0.1, 0.95, 3), 0, 1)) + (1.0,)
    if small:
        kind = ["mug", "book", "bottle", "box", "vase"][int(rng.integers(5))]
    else:
        kind = ["bin", "carton", "plant"][int(rng.integers(3))]
    if kind == "mug":
        r, h = rng.uniform(0.035, 0.05), rng.uniform(0.045, 0.06)
        parts = (("cylinder", (0, 0, h), (r, h), colour), ("box", (0, r + 0.012, h), (0.006, 0.012, h * 0.6), colour))
        half = (r, r + 0.024, h)
    elif kind == "book":
        hx, hy, hz = rng.uniform(0.07, 0.11), rng.uniform(0.1, 0.14), rng.uniform(0.01, 0.025)
        parts = (("box", (0, 0, hz), (hx, hy, hz), colour),)
        half = (hx, hy, hz)
    elif kind == "bottle":
        r, h = rng.uniform(0.03, 0.045), rng.uniform(0.08, 0.13)
        parts = (("cylinder", (0, 0, h), (r, h), colour),
                 ("cylinder", (0, 0, 2 * h + 0.03), (r * 0.4, 0.03), colour))
        half = (r, r, h + 0.03)
    elif kind == "box":
        hx, hy, hz = rng.uniform(0.04, 0.1), rng.uniform(0.04, 0.1), rng.uniform(0.03, 0.08)
        parts = (("box", (0, 0, hz), (hx, hy, hz), (0.66, 0.5, 0.32, 1.0)),)
        half = (hx, hy, hz)
    elif kind == "vase":
        r, h = rng.uniform(0.04, 0.07), rng.uniform(0.08, 0.15)
        parts = (("cylinder", (0, 0, h), (r, h), colour), ("sphere", (0, 0, 2 * h), (r * 0.8,), (0.2, 0.6, 0.2, 1.0)))
        half = (r, r, h + 0.4 * r)
    elif kind == "bin":
        r, h = rng.uniform(0.12, 0.17), rng.uniform(0.2, 0.32)
        parts = (("cylinder", (0, 0, h), (r, h), colour),)
        half = (r, r, h)
    elif kind == "carton":
        hx, hy, hz = rng.uniform(0.12, 0.2), rng.uniform(0.1, 0.17), rng.uniform(0.1, 0.2)
        parts = (("box", (0, 0, hz), (hx, hy, hz), (0.66, 0.5, 0.32, 1.0)),)
        half = (hx, hy, hz)
    else:  # plant
        r, h = rng.uniform(0.1, 0.14), rng.uniform(0.12, 0.2)
        parts = (("cylinder", (0, 0, h), (r, h), (0.72, 0.38, 0.24, 1.0)),
                 ("sphere", (0, 0, 2 * h + r), (r * 1.3,), (0.2, 0.5, 0.2, 1.0)))
        half = (r * 1.3, r * 1.3, h + 1.15 * r)
    return tuple(float(x) for x in half), parts


def place_distractors(rng, top: int, beside: int, lo, hi, top_setback_m: float, beside_gap_m: float) -> list[Distractor]:
    """Objects on the cabinet's top (set back from its front) and on the floor beside its -y side
    (the hand starts on the +y side), none overlapping another: ``top`` on the top, ``top_setback_m``
    behind its front edge; ``beside`` on the floor, ``beside_gap_m`` from its side."""
    placed: list[Distractor] = []

    def free(d: Distractor) -> bool:
        a_lo, a_hi = d.box()
        return all(not (np.all(a_lo < b_hi + 0.01) and np.all(b_lo < a_hi + 0.01))
                   for b_lo, b_hi in (p.box() for p in placed))

    for i in range(top):
        for _ in range(30):
            half, parts = everyday_object(rng, "", small=True)
            x0, x1 = lo[0] + top_setback_m + half[0], hi[0] - half[0]
            y0, y1 = lo[1] + half[1], hi[1] - half[1]
            if x1 < x0 or y1 < y0:
                break
            d = Distractor(name=f"top{i}", pos=(float(rng.uniform(x0, x1)), float(rng.uniform(y0, y1)),
                                                float(hi[2]) + 0.001), half=half, parts=parts)
            if free(d):
                placed.append(d)
                break
    for i in range(beside):
        for _ in range(30):
            half, parts = everyday_object(rng, "", small=False)
            x0, x1 = lo[0] + 0.02 + half[0], max(lo[0] + 0.02 + half[0], hi[0] - half[0])
            y = lo[1] - beside_gap_m - half[1] - float(rng.uniform(0, 0.25))
            d = Distractor(name=f"beside{i}", pos=(float(rng.uniform(x0, x1)), y, 0.001), half=half, parts=parts)
            if free(d):
                placed.append(d)
                break
    return placed


def unseen_texture(rng, size: int = 128) -> np.ndarray:
    """A texture no training render has: smooth random blobs in three saturated colours
    (camouflage-like), (size, size, 3) 0-255."""
    import colorsys

    coarse = rng.normal(size=(8, 8))
    yy, xx = np.mgrid[0:size, 0:size] / size * 7
    i0, j0 = np.floor(yy).astype(int), np.floor(xx).astype(int)
    fy, fx = yy - i0, xx - j0
    field_ = (coarse[i0, j0] * (1 - fy) * (1 - fx) + coarse[i0 + 1, j0] * fy * (1 - fx)
              + coarse[i0, j0 + 1] * (1 - fy) * fx + coarse[i0 + 1, j0 + 1] * fy * fx)
    field_ += 0.3 * np.sin(xx * rng.uniform(6, 12) + yy * rng.uniform(-6, 6))
    hue = rng.uniform()
    palette = np.array([colorsys.hsv_to_rgb((hue + k / 3) % 1, rng.uniform(0.6, 1.0), rng.uniform(0.35, 0.95))
                        for k in range(3)])
    bands = np.digitize(field_, np.quantile(field_, [1 / 3, 2 / 3]))
    return palette[bands] * 255.0


def retexture(root, cabinet, handle_geoms, rng, with_cabinet: bool) -> None:
    """The floor and walls (and, ``with_cabinet``, the cabinet but its handles) in unseen textures."""
    from opend_mj.sim.rooms.textures import png_asset

    for name in ("floor", "wall"):
        mat = root.find("material", name)
        if mat is None:
            continue
        tex = root.asset.add("texture", name=f"unseen_{name}", type="2d", file=png_asset(unseen_texture(rng)))
        mat.texture = tex
        mat.rgba = [1, 1, 1, 1]
        mat.texuniform = "true"
        mat.texrepeat = [float(rng.uniform(1.0, 3.0))] * 2
    if not with_cabinet:
        return
    cab_root = cabinet.mjcf_model
    tex = cab_root.asset.add("texture", name="unseen_cabinet", type="2d", file=png_asset(unseen_texture(rng)))
    colour = np.clip(rng.uniform(0.2, 1.0, 3), 0, 1)
    mat = cab_root.asset.add("material", name="unseen_cabinet", texture=tex, texuniform="true",
                             texrepeat=[4.0, 4.0], rgba=[*colour.tolist(), 1.0], specular=0.3)
    handles = set(handle_geoms)
    for geom in cab_root.find_all("geom"):
        if geom.name in handles:
            continue
        if geom.rgba is not None and len(geom.rgba) == 4 and float(geom.rgba[3]) == 0.0:
            continue  # invisible collision geoms stay invisible
        geom.material = mat
        geom.rgba = None
