"""Nine procedural rooms (the arena of the OpenD task), built from MuJoCo primitives.

``RoomArena(room, seed, light_scale)`` is a dm_control ``composer.Arena``. The room type (0..8, see
``ROOM_NAMES``) fixes which furniture the room holds; the seed fixes everything that varies per
episode: room size, wall distance behind the cabinet, floor material and texture (wood planks,
tiles, checker, gradient, flat/concrete, carpet), wall type and colour (paint, stripes, brick,
tiles, wainscot), light count, intensity and direction, furniture colours and positions.
``light_scale`` multiplies every light (lights, headlight, emissive materials): 0.7 reproduces the
paper's low-light ablation.

Layout and keep-out zones (world frame, z up, the cabinet faces -x):

* the cabinet zone ``|x| < zone_x``, ``|y| < zone_y``, ``0 <= z < zone_z`` (default 0.5, 0.8, 2.0 m)
  around the origin, where the cabinet stands on the floor (attach it at ``arena.cabinet_site``);
* the line-of-sight strip in front of it, ``los_x_min <= x < zone_x``, ``|y| < zone_y + los_margin``,
  ``z < los_z`` (default from x = -3.6 m, 0.1 m margin, 2.5 m high), which holds the camera, the
  hand and the view between them.

No geom of the arena other than the floor enters either box (``arena.keepout_boxes``; tested).
The back wall stands 0.25-0.6 m behind the cabinet zone.

Collisions: only the floor (a plane, group 0) collides. Walls, ceiling and furniture are visual
only (``contype = conaffinity = 0``, geom group 1), so they cost nothing in the contact pipeline and
can never push the cabinet or the hand.

Physics options for the whole scene are `opend_mj.sim.physics.PhysicsOptions` (noslip off; the
dm_control base arena turns on 5 noslip iterations; pass ``noslip_iterations`` to change it); the
task then sets its own timestep. The off-screen buffer is 640x480 (videos) unless asked otherwise.
"""

from __future__ import annotations

import io
import os

os.environ.setdefault("MUJOCO_GL", "egl")  # before dm_control picks a GL backend

from dataclasses import dataclass  # noqa: E402
from typing import Callable  # noqa: E402

import numpy as np  # noqa: E402
from dm_control import composer, mjcf  # noqa: E402

from opend_mj.sim.physics import PhysicsOptions  # noqa: E402
from opend_mj.transforms import look_rotation, yaw_quat  # noqa: E402

__all__ = ["ROOM_NAMES", "RoomArena", "KeepOut"]

ROOM_NAMES = (
    "kitchen",
    "living room",
    "office",
    "bedroom",
    "dining room",
    "library",
    "laundry room",
    "workshop",
    "hallway",
)


@dataclass(frozen=True)
class KeepOut:
    """Boxes no decoration may enter: the cabinet zone and the camera's line-of-sight strip."""

    zone_x: float = 0.5
    zone_y: float = 0.8
    zone_z: float = 2.0
    los_x_min: float = -3.6
    los_margin: float = 0.1
    los_z: float = 2.5

    def boxes(self) -> list[tuple[np.ndarray, np.ndarray]]:
        zone = (np.array([-self.zone_x, -self.zone_y, 0.0]), np.array([self.zone_x, self.zone_y, self.zone_z]))
        w = self.zone_y + self.los_margin
        los = (np.array([self.los_x_min, -w, 0.0]), np.array([self.zone_x, w, self.los_z]))
        return [zone, los]


def _overlap(a_lo, a_hi, b_lo, b_hi, pad=0.0) -> bool:
    return bool(np.all(a_lo < b_hi + pad) and np.all(b_lo < a_hi + pad))


# --------------------------------------------------------------------------------------------------
# Procedural textures (numpy -> PNG bytes in memory, nothing on disk)
# --------------------------------------------------------------------------------------------------


def _png(arr: np.ndarray) -> mjcf.Asset:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.clip(arr, 0, 255).astype(np.uint8)).save(buf, format="PNG")
    return mjcf.Asset(buf.getvalue(), ".png")


def _tex_wood(rng, base, size=256, planks=8) -> np.ndarray:
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


def _tex_brick(rng, brick, mortar, size=128) -> np.ndarray:
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


def _tex_stripes(rng, c1, c2, size=128) -> np.ndarray:
    w = size
    period = int(rng.choice([16, 32, 64]))
    frac = rng.uniform(0.3, 0.7)
    x = np.arange(w) % period
    band = (x < frac * period).astype(float)
    row = band[:, None] * np.asarray(c1) + (1 - band[:, None]) * np.asarray(c2)
    img = np.repeat(row[None], size, axis=0)
    img *= 1.0 + rng.normal(0, 0.015, size=(size, w, 1))
    return img * 255.0


# --------------------------------------------------------------------------------------------------
# Furniture, as lists of primitive parts in a local frame: origin on the floor at the footprint
# centre, front facing local +x. Each builder returns (half_x, half_y, height, parts).
# A part: (type, pos, size, material, euler_or_None).
# --------------------------------------------------------------------------------------------------

Part = tuple


def _box(pos, half, mat, euler=None) -> Part:
    return ("box", pos, half, mat, euler)


def _cyl(pos, r, hh, mat, euler=None) -> Part:
    return ("cylinder", pos, (r, hh), mat, euler)


def _legs(hx, hy, h, t, mat) -> list[Part]:
    return [_box((sx * (hx - t), sy * (hy - t), h / 2), (t, t, h / 2), mat) for sx in (-1, 1) for sy in (-1, 1)]


def f_table(rng, w=None, d=None, h=None):
    w = w or rng.uniform(0.9, 1.4)
    d = d or rng.uniform(0.6, 0.8)
    h = h or rng.uniform(0.72, 0.76)
    hx, hy = d / 2, w / 2
    parts = [_box((0, 0, h - 0.02), (hx, hy, 0.02), "wood")] + _legs(hx - 0.03, hy - 0.03, h - 0.04, 0.025, "wood")
    if rng.random() < 0.6:  # a vase or a bowl
        parts.append(_cyl((rng.uniform(-0.1, 0.1), rng.uniform(-0.2, 0.2), h + 0.08), 0.05, 0.08, "accent"))
    return hx, hy, h + 0.16, parts


def f_coffee_table(rng):
    hx, hy, h = rng.uniform(0.3, 0.4), rng.uniform(0.45, 0.6), 0.42
    parts = [_box((0, 0, h - 0.03), (hx, hy, 0.03), "wood_dark")] + _legs(hx - 0.03, hy - 0.03, h - 0.06, 0.03, "wood_dark")
    parts.append(_box((0.05, -0.1, h + 0.015), (0.12, 0.09, 0.015), "accent"))  # a book
    return hx, hy, h + 0.03, parts


def f_chair(rng):
    s = 0.22
    hs = 0.46
    parts = _legs(s, s, hs - 0.03, 0.02, "wood")
    parts.append(_box((0, 0, hs - 0.015), (s, s, 0.03), "fabric"))
    parts.append(_box((-s + 0.02, 0, hs + 0.22), (0.02, s, 0.22), "wood"))
    return s, s, hs + 0.44, parts


def f_office_chair(rng):
    parts = [
        _cyl((0, 0, 0.04), 0.3, 0.02, "black"),
        _cyl((0, 0, 0.25), 0.025, 0.2, "metal"),
        _box((0, 0, 0.48), (0.25, 0.25, 0.04), "fabric"),
        _box((-0.25, 0, 0.85), (0.04, 0.23, 0.3), "fabric"),
    ]
    return 0.3, 0.3, 1.15, parts


def f_bookshelf(rng, w=None, h=None):
    w = w or rng.uniform(0.7, 1.0)
    h = h or rng.uniform(1.6, 2.0)
    d = 0.32
    hx, hy = d / 2, w / 2
    t = 0.02
    parts = [
        _box((0, -hy + t, h / 2), (hx, t, h / 2), "wood"),
        _box((0, hy - t, h / 2), (hx, t, h / 2), "wood"),
        _box((-hx + t / 2, 0, h / 2), (t / 2, hy, h / 2), "wood_dark"),
    ]
    n = int(rng.integers(4, 6))
    gap = (h - t) / n
    for i in range(n + 1):
        z = i * gap + t / 2
        parts.append(_box((0, 0, z), (hx, hy - 2 * t, t / 2), "wood"))
        if i == n:
            break
        y = -hy + 2 * t + 0.01
        while True:  # a row of books
            bw = rng.uniform(0.02, 0.05)
            if y + bw > hy - 2 * t - 0.01 or rng.random() < 0.06:
                break
            bh = rng.uniform(0.55, 0.85) * gap
            parts.append(_box((0.0, y + bw / 2, z + t / 2 + bh / 2), (hx * 0.8, bw / 2, bh / 2), f"book{int(rng.integers(0, 4))}"))
            y += bw + 0.002
    return hx, hy, h, parts


def f_sofa(rng, w=None):
    w = w or rng.uniform(1.6, 2.2)
    d = 0.9
    hx, hy = d / 2, w / 2
    parts = [
        _box((0.05, 0, 0.22), (hx - 0.05, hy, 0.16), "fabric"),
        _box((-hx + 0.1, 0, 0.55), (0.1, hy, 0.35), "fabric"),
        _box((0.05, -hy + 0.1, 0.45), (hx - 0.05, 0.1, 0.17), "fabric"),
        _box((0.05, hy - 0.1, 0.45), (hx - 0.05, 0.1, 0.17), "fabric"),
    ]
    n = 2 if w < 1.9 else 3
    cw = (w - 0.2) / n
    for i in range(n):
        parts.append(_box((0.08, -hy + 0.1 + cw * (i + 0.5), 0.43), (hx - 0.2, cw / 2 - 0.01, 0.05), "fabric2"))
    return hx, hy, 0.9, parts


def f_armchair(rng):
    hx, hy, _, parts = f_sofa(rng, w=0.9)
    return hx, hy, 0.9, parts


def f_floor_lamp(rng):
    h = rng.uniform(1.4, 1.7)
    parts = [
        _cyl((0, 0, 0.02), 0.16, 0.02, "metal"),
        _cyl((0, 0, h / 2), 0.015, h / 2, "metal"),
        _cyl((0, 0, h - 0.1), 0.18, 0.12, "lampshade"),
    ]
    return 0.18, 0.18, h + 0.02, parts


def f_plant(rng):
    r = rng.uniform(0.12, 0.2)
    hp = rng.uniform(0.25, 0.4)
    parts = [_cyl((0, 0, hp / 2), r, hp / 2, "terracotta"), _cyl((0, 0, hp - 0.01), r * 0.9, 0.012, "soil")]
    top = hp
    for _ in range(int(rng.integers(3, 6))):
        rr = rng.uniform(0.12, 0.2) * (r / 0.16)
        pos = (rng.uniform(-r, r) * 0.6, rng.uniform(-r, r) * 0.6, hp + rng.uniform(0.1, 0.5))
        parts.append(("ellipsoid", pos, (rr, rr, rr * 1.4), "leaf", None))
        top = max(top, pos[2] + rr * 1.4)
    half = max(r, 0.6 * r + 0.2 * (r / 0.16) + 0.01)
    return half, half, top, parts


def f_rug(rng):
    hx, hy = rng.uniform(0.5, 0.9), rng.uniform(0.6, 1.1)
    parts = [_box((0, 0, 0.004), (hx, hy, 0.004), "rug"), _box((0, 0, 0.0085), (hx - 0.08, hy - 0.08, 0.0005), "rug2")]
    return hx, hy, 0.009, parts


def f_bed(rng):
    w = rng.choice([1.4, 1.6, 1.8])
    length = 2.05
    hx, hy = length / 2, w / 2
    parts = [
        _box((0, 0, 0.15), (hx, hy, 0.12), "wood"),
        _box((0.02, 0, 0.38), (hx - 0.03, hy - 0.03, 0.11), "white"),
        _box((0.25, 0, 0.5), (hx - 0.28, hy - 0.02, 0.02), "fabric"),
        _box((-hx + 0.04, 0, 0.55), (0.04, hy, 0.55), "wood_dark"),
    ]
    for s in (-1, 1):
        parts.append(_box((-hx + 0.3, s * hy / 2, 0.54), (0.17, hy / 2 - 0.08, 0.06), "white"))
    return hx, hy, 1.1, parts


def f_nightstand(rng):
    parts = [_box((0, 0, 0.27), (0.2, 0.22, 0.27), "wood"), _box((0.205, 0, 0.4), (0.005, 0.18, 0.08), "wood_dark")]
    parts += f_table_lamp_parts(0.54)
    return 0.21, 0.22, 0.98, parts


def f_table_lamp_parts(z):
    return [_cyl((0, 0, z + 0.02), 0.07, 0.02, "metal"), _cyl((0, 0, z + 0.16), 0.012, 0.14, "metal"), _cyl((0, 0, z + 0.34), 0.12, 0.1, "lampshade")]


def f_wardrobe(rng):
    w = rng.uniform(1.0, 1.4)
    h = rng.uniform(1.9, 2.2)
    hx, hy = 0.3, w / 2
    parts = [_box((0, 0, h / 2), (hx, hy, h / 2), "wood")]
    for s in (-1, 1):
        parts.append(_box((hx + 0.005, s * hy / 2, h / 2 + 0.02), (0.005, hy / 2 - 0.02, h / 2 - 0.06), "wood_dark"))
        parts.append(_box((hx + 0.02, s * 0.06, h / 2), (0.01, 0.01, 0.12), "metal"))
    return hx + 0.03, hy, h, parts


def f_counter(rng, w=None):
    w = w or rng.uniform(1.6, 2.6)
    hx, hy = 0.3, w / 2
    parts = [_box((-0.02, 0, 0.45), (hx - 0.02, hy, 0.43), "white"), _box((0, 0, 0.885), (hx, hy, 0.02), "stone")]
    n = max(2, int(w / 0.6))
    dw = w / n
    for i in range(n):
        y = -hy + dw * (i + 0.5)
        parts.append(_box((hx - 0.035, y, 0.45), (0.006, dw / 2 - 0.01, 0.4), "cabinet_front"))
        parts.append(_box((hx - 0.02, y + dw / 2 - 0.06, 0.75), (0.01, 0.008, 0.05), "metal"))
    # sink or stove on top
    if rng.random() < 0.5:
        parts.append(_box((0.02, -hy / 3, 0.9), (0.2, 0.25, 0.006), "metal"))
        parts.append(_cyl((-0.2, -hy / 3, 1.05), 0.015, 0.15, "metal"))
    else:
        parts.append(_box((0.02, hy / 3, 0.91), (0.26, 0.3, 0.01), "black"))
        for dx in (-0.1, 0.12):
            for dy in (-0.14, 0.14):
                parts.append(_cyl((0.02 + dx, hy / 3 + dy, 0.922), 0.08, 0.003, "metal"))
    for _ in range(int(rng.integers(0, 3))):  # jars and kettles
        parts.append(_cyl((-0.1, rng.uniform(-hy + 0.1, hy - 0.1), 0.99), rng.uniform(0.04, 0.08), rng.uniform(0.05, 0.1), "accent"))
    return hx, hy, 1.2, parts


def f_fridge(rng):
    hx, hy, h = 0.35, 0.35, rng.uniform(1.7, 1.9)
    parts = [
        _box((0, 0, h / 2), (hx - 0.01, hy, h / 2), "white"),
        _box((hx - 0.005, 0, h * 0.72), (0.005, hy - 0.01, h * 0.27), "white"),
        _box((hx + 0.02, hy - 0.06, h * 0.6), (0.015, 0.012, 0.15), "metal"),
        _box((hx + 0.02, hy - 0.06, h * 0.3), (0.015, 0.012, 0.12), "metal"),
    ]
    return hx + 0.035, hy, h, parts


def f_desk(rng):
    hx, hy, h, parts = f_table(rng, w=rng.uniform(1.2, 1.6), d=0.7, h=0.74)
    parts = [p for p in parts if p[0] == "box"]  # no vase
    parts += [
        _box((-0.2, 0, h + 0.01), (0.1, 0.12, 0.01), "black"),
        _box((-0.2, 0, h + 0.1), (0.02, 0.02, 0.1), "black"),
        _box((-0.18, 0, h + 0.33), (0.015, 0.3, 0.18), "black"),
        _box((-0.164, 0, h + 0.34), (0.002, 0.28, 0.16), "screen"),
        _box((0.12, 0, h + 0.01), (0.08, 0.22, 0.01), "black"),
    ]
    return hx, hy, h + 0.52, parts


def f_tv(rng):
    w = rng.uniform(1.2, 1.8)
    hx, hy = 0.22, w / 2
    parts = [_box((0, 0, 0.25), (hx, hy, 0.25), "wood_dark")]
    tw = rng.uniform(0.5, 0.7)
    parts += [
        _box((-0.05, 0, 0.53), (0.1, 0.15, 0.02), "black"),
        _box((-0.05, 0, 0.6), (0.02, 0.04, 0.07), "black"),
        _box((-0.05, 0, 0.67 + tw * 0.3), (0.025, tw, tw * 0.3 + 0.02), "black"),
        _box((-0.024, 0, 0.67 + tw * 0.3), (0.002, tw - 0.02, tw * 0.3), "screen"),
    ]
    return hx, hy, 0.72 + tw * 0.6, parts


def f_sideboard(rng):
    w = rng.uniform(1.2, 1.8)
    hx, hy, h = 0.23, w / 2, 0.8
    parts = [_box((0, 0, h / 2 + 0.05), (hx, hy, h / 2 - 0.05), "wood")] + _legs(hx - 0.02, hy - 0.02, 0.1, 0.02, "wood_dark")
    for i in range(3):
        y = -hy + w / 3 * (i + 0.5)
        parts.append(_box((hx + 0.004, y, h / 2 + 0.05), (0.004, w / 6 - 0.015, h / 2 - 0.08), "wood_dark"))
    parts.append(_cyl((0, rng.uniform(-hy + 0.2, hy - 0.2), h + 0.12), 0.07, 0.12, "accent"))
    return hx + 0.01, hy, h + 0.24, parts


def f_washer(rng):
    hx = hy = 0.3
    h = 0.85
    parts = [
        _box((0, 0, h / 2), (hx, hy, h / 2), "white"),
        _cyl((hx + 0.005, 0, 0.42), 0.19, 0.008, "metal", (0, np.pi / 2, 0)),
        _cyl((hx + 0.012, 0, 0.42), 0.14, 0.004, "screen", (0, np.pi / 2, 0)),
        _box((hx + 0.003, 0, 0.78), (0.003, hy - 0.03, 0.04), "metal"),
    ]
    return hx + 0.02, hy, h, parts


def f_workbench(rng):
    hx, hy, h = 0.35, rng.uniform(0.8, 1.1), 0.9
    parts = [_box((0, 0, h - 0.03), (hx, hy, 0.03), "wood")] + _legs(hx - 0.02, hy - 0.02, h - 0.06, 0.035, "metal")
    parts.append(_box((0, 0, 0.2), (hx - 0.04, hy - 0.04, 0.015), "wood"))
    for _ in range(int(rng.integers(2, 5))):  # tools and boxes on top
        parts.append(_box((rng.uniform(-0.2, 0.2), rng.uniform(-hy + 0.15, hy - 0.15), h + 0.04), (rng.uniform(0.03, 0.1), rng.uniform(0.05, 0.15), 0.04), f"book{int(rng.integers(0, 4))}"))
    return hx, hy, h + 0.08, parts


def f_boxes(rng):
    parts = []
    z = 0.0
    s = rng.uniform(0.25, 0.35)
    for _ in range(int(rng.integers(1, 4))):
        parts.append(_box((rng.uniform(-0.03, 0.03), rng.uniform(-0.03, 0.03), z + s / 2), (s / 2, s / 2 * 1.2, s / 2), "cardboard"))
        z += s
        s *= rng.uniform(0.75, 0.95)
    return 0.25, 0.27, z, parts


def f_coat_rack(rng):
    h = 1.75
    parts = [_cyl((0, 0, 0.02), 0.2, 0.02, "wood_dark"), _cyl((0, 0, h / 2), 0.02, h / 2, "wood_dark")]
    for a in rng.uniform(0, 2 * np.pi, size=int(rng.integers(1, 4))):
        parts.append(("ellipsoid", (0.1 * np.cos(a), 0.1 * np.sin(a), h - 0.45), (0.09, 0.14, 0.4), "fabric2", None))
    return 0.25, 0.25, h, parts


def f_bench(rng):
    w = rng.uniform(0.9, 1.3)
    hx, hy, h = 0.2, w / 2, 0.46
    parts = [_box((0, 0, h - 0.025), (hx, hy, 0.025), "wood")] + _legs(hx, hy - 0.03, h - 0.05, 0.025, "wood_dark")
    parts.append(_box((0, 0, 0.12), (hx - 0.02, hy - 0.05, 0.01), "wood_dark"))
    return hx, hy, h, parts


def f_basket(rng):
    r = rng.uniform(0.18, 0.25)
    return r, r, 0.5, [_cyl((0, 0, 0.25), r, 0.25, "cardboard"), _cyl((0, 0, 0.49), r * 0.85, 0.01, "fabric2")]


def f_dining_set(rng):
    """A table with chairs around it (chairs face the table)."""
    w, d, h = rng.uniform(1.2, 1.6), 0.85, 0.75
    _, _, _, parts = f_table(rng, w=w, d=d, h=h)
    out = list(parts)
    seats = [(-(d / 2 + 0.15), y, 0.0) for y in (-w / 4, w / 4)] + [((d / 2 + 0.15), y, np.pi) for y in (-w / 4, w / 4)]
    for cx, cy, yaw in seats:
        _, _, _, cp = f_chair(rng)
        c, s = np.cos(yaw), np.sin(yaw)
        for typ, pos, size, mat, eul in cp:
            p = (cx + c * pos[0] - s * pos[1], cy + s * pos[0] + c * pos[1], pos[2])
            size = (size[1], size[0], size[2]) if (typ == "box" and abs(s) > 0.5) else size
            out.append((typ, p, size, mat, eul))
    return d / 2 + 0.4, w / 2, 0.95, out


# Wall-mounted items: local frame origin on the wall surface at the item's centre height,
# +x pointing into the room. Return (half_depth_x, half_y, half_z, parts).


def w_picture(rng):
    hy, hz = rng.uniform(0.2, 0.45), rng.uniform(0.15, 0.35)
    return 0.02, hy, hz, [_box((0.015, 0, 0), (0.015, hy, hz), "wood_dark"), _box((0.031, 0, 0), (0.001, hy - 0.03, hz - 0.03), f"art{int(rng.integers(0, 2))}")]


def w_window(rng):
    hy, hz = rng.uniform(0.4, 0.7), rng.uniform(0.4, 0.6)
    return 0.03, hy, hz, [
        _box((0.02, 0, 0), (0.02, hy, hz), "white"),
        _box((0.041, 0, 0), (0.001, hy - 0.05, hz - 0.05), "window"),
        _box((0.045, 0, 0), (0.004, 0.02, hz - 0.05), "white"),
    ]


def w_clock(rng):
    r = rng.uniform(0.12, 0.18)
    return 0.03, r, r, [_cyl((0.015, 0, 0), r, 0.015, "white", (0, np.pi / 2, 0)), _cyl((0.03, 0, 0), r * 0.9, 0.002, "black", (0, np.pi / 2, 0)), _cyl((0.033, 0, 0), r * 0.85, 0.002, "white", (0, np.pi / 2, 0))]


def w_shelf(rng):
    hy = rng.uniform(0.35, 0.6)
    parts = [_box((0.11, 0, 0), (0.11, hy, 0.015), "wood")]
    y = -hy + 0.05
    while y < hy - 0.1:
        s = rng.uniform(0.03, 0.08)
        parts.append(_cyl((0.11, y + s, 0.015 + s * 1.2), s, s * 1.2, "accent"))
        y += 2 * s + rng.uniform(0.05, 0.15)
    return 0.22, hy, 0.2, parts


def w_upper_cabinets(rng):
    hy = rng.uniform(0.6, 1.0)
    parts = [_box((0.17, 0, 0), (0.17, hy, 0.35), "white")]
    n = max(2, int(2 * hy / 0.5))
    for i in range(n):
        y = -hy + 2 * hy / n * (i + 0.5)
        parts.append(_box((0.345, y, 0), (0.005, hy / n - 0.01, 0.33), "cabinet_front"))
    return 0.35, hy, 0.35, parts


def w_whiteboard(rng):
    hy, hz = rng.uniform(0.6, 0.9), rng.uniform(0.4, 0.5)
    return 0.02, hy, hz, [_box((0.01, 0, 0), (0.01, hy, hz), "metal"), _box((0.021, 0, 0), (0.001, hy - 0.02, hz - 0.02), "white")]


def w_door(rng):
    return 0.03, 0.45, 1.03, [
        _box((0.015, 0, 0), (0.015, 0.5, 1.05), "white"),
        _box((0.035, 0, -0.01), (0.01, 0.44, 1.02), "wood"),
        _box((0.06, 0.36, -0.05), (0.02, 0.05, 0.01), "metal"),
    ]


FLOOR_ITEMS: dict[str, Callable] = {
    "table": f_table, "coffee_table": f_coffee_table, "chair": f_chair, "office_chair": f_office_chair,
    "bookshelf": f_bookshelf, "sofa": f_sofa, "armchair": f_armchair, "floor_lamp": f_floor_lamp,
    "plant": f_plant, "rug": f_rug, "bed": f_bed, "nightstand": f_nightstand, "wardrobe": f_wardrobe,
    "counter": f_counter, "fridge": f_fridge, "desk": f_desk, "tv": f_tv, "sideboard": f_sideboard,
    "washer": f_washer, "workbench": f_workbench, "boxes": f_boxes, "coat_rack": f_coat_rack,
    "bench": f_bench, "basket": f_basket, "dining_set": f_dining_set,
}
WALL_ITEMS: dict[str, Callable] = {
    "picture": w_picture, "window": w_window, "clock": w_clock, "shelf": w_shelf,
    "upper_cabinets": w_upper_cabinets, "whiteboard": w_whiteboard, "door": w_door,
}

# Per room: floor items as (item, where) with where in back / side / free / back_corner;
# wall items as (item, wall, centre height) with wall in back / side; preferred floor and wall kinds.
ROOM_SPECS = {
    0: dict(  # kitchen
        floor=[("counter", "back"), ("counter", "side"), ("fridge", "back_corner"), ("table", "free"), ("chair", "free"), ("plant", "side")],
        wall=[("upper_cabinets", "back", 1.75), ("window", "side", 1.5), ("clock", "back", 2.2)],
        floors=("tiles", "tiles", "checker", "wood", "flat"), walls=("tiles", "paint", "paint", "brick")),
    1: dict(  # living room
        floor=[("sofa", "side"), ("tv", "back"), ("coffee_table", "free"), ("rug", "free"), ("floor_lamp", "back_corner"), ("plant", "back"), ("armchair", "side")],
        wall=[("picture", "back", 1.6), ("picture", "side", 1.5), ("window", "side", 1.5), ("shelf", "back", 1.8)],
        floors=("wood", "wood", "carpet", "gradient"), walls=("paint", "stripes", "wainscot", "brick"), width=(2.0, 2.8)),
    2: dict(  # office
        floor=[("desk", "back"), ("office_chair", "free"), ("bookshelf", "back"), ("bookshelf", "side"), ("plant", "back_corner"), ("boxes", "side")],
        wall=[("whiteboard", "back", 1.5), ("clock", "side", 2.1), ("window", "side", 1.5)],
        floors=("carpet", "wood", "checker", "flat"), walls=("paint", "paint", "wainscot")),
    3: dict(  # bedroom
        floor=[("bed", "side"), ("nightstand", "back"), ("wardrobe", "back"), ("rug", "free"), ("plant", "back_corner"), ("chair", "side")],
        wall=[("picture", "back", 1.5), ("window", "side", 1.5), ("shelf", "back", 1.8)],
        floors=("wood", "carpet", "carpet", "gradient"), walls=("paint", "stripes", "wainscot")),
    4: dict(  # dining room
        floor=[("dining_set", "free"), ("sideboard", "back"), ("plant", "back_corner"), ("floor_lamp", "side"), ("rug", "free")],
        wall=[("picture", "back", 1.6), ("window", "side", 1.5), ("clock", "back", 2.1)],
        floors=("wood", "tiles", "checker"), walls=("paint", "stripes", "wainscot", "brick"), width=(2.4, 2.9)),
    5: dict(  # library
        floor=[("bookshelf", "back"), ("bookshelf", "back"), ("bookshelf", "side"), ("armchair", "free"), ("floor_lamp", "free"), ("rug", "free"), ("table", "side")],
        wall=[("picture", "back", 1.9), ("clock", "side", 2.0)],
        floors=("wood", "carpet", "checker"), walls=("wainscot", "paint", "stripes")),
    6: dict(  # laundry room
        floor=[("washer", "back"), ("washer", "back"), ("basket", "free"), ("basket", "side"), ("boxes", "back_corner"), ("bench", "side")],
        wall=[("shelf", "back", 1.5), ("upper_cabinets", "back", 1.8), ("window", "side", 1.6)],
        floors=("tiles", "tiles", "flat", "checker"), walls=("tiles", "paint")),
    7: dict(  # workshop / garage
        floor=[("workbench", "back"), ("workbench", "side"), ("boxes", "back_corner"), ("boxes", "free"), ("bookshelf", "side"), ("chair", "free")],
        wall=[("shelf", "back", 1.4), ("shelf", "back", 1.8), ("whiteboard", "side", 1.5), ("door", "side", 1.05)],
        floors=("flat", "flat", "checker", "gradient"), walls=("brick", "paint", "brick")),
    8: dict(  # hallway / entrance
        floor=[("coat_rack", "back_corner"), ("bench", "back"), ("bench", "side"), ("plant", "side"), ("rug", "free"), ("boxes", "side")],
        wall=[("picture", "back", 1.55), ("door", "side", 1.05), ("clock", "back", 2.1), ("picture", "side", 1.5)],
        floors=("tiles", "wood", "checker", "carpet"), walls=("paint", "stripes", "wainscot")),
}


def _hsv(h, s, v):
    import colorsys

    return np.array(colorsys.hsv_to_rgb(h % 1.0, np.clip(s, 0, 1), np.clip(v, 0, 1)))


WOOD_TONES = [(0.72, 0.52, 0.33), (0.55, 0.36, 0.2), (0.82, 0.66, 0.45), (0.42, 0.27, 0.16), (0.66, 0.45, 0.3)]


# --------------------------------------------------------------------------------------------------
# The arena
# --------------------------------------------------------------------------------------------------


class RoomArena(composer.Arena):
    """One of nine rooms, randomised by ``seed``.

    Args:
      room: 0..8, index into ``ROOM_NAMES``.
      seed: per-episode randomisation (``np.random.default_rng(seed)``); same seed -> same room.
      light_scale: multiplies every light intensity (0.7 = the paper's 30 % darker ablation).
      keepout: the :class:`KeepOut` boxes (cabinet zone and camera strip) decoration must avoid.
      fast_render: shadows and multisampling off (about 20x faster on a CPU renderer).
      offscreen: (width, height) of the off-screen buffer; 640x480 suffices for 256x256 and video.
      noslip_iterations: 0 by default (the base dm_control arena uses 5).
    """

    def _build(
        self,
        room: int = 0,
        seed: int = 0,
        light_scale: float = 1.0,
        keepout: KeepOut | None = None,
        fast_render: bool = True,
        offscreen: tuple[int, int] = (640, 480),
        noslip_iterations: int = 0,
        name: str | None = None,
    ):
        if not 0 <= int(room) < len(ROOM_NAMES):
            raise ValueError(f"room must be in 0..{len(ROOM_NAMES) - 1}, got {room}")
        super()._build(name=name or f"room{int(room)}_{ROOM_NAMES[int(room)].replace(' ', '_')}")
        self.room = int(room)
        self.room_name = ROOM_NAMES[self.room]
        self.seed = int(seed)
        self.light_scale = float(light_scale)
        self.keepout = keepout or KeepOut()
        self._rng = np.random.default_rng([self.seed, self.room])
        self._decorations: list = []
        self._placed: list[tuple[np.ndarray, np.ndarray]] = []

        root = self._mjcf_root
        PhysicsOptions(noslip_iterations=int(noslip_iterations)).apply(root)
        g = root.visual.get_children("global")
        g.offwidth, g.offheight = int(offscreen[0]), int(offscreen[1])
        q = root.visual.quality
        if fast_render:
            q.shadowsize = 0
            q.offsamples = 0
        root.visual.map.znear = 0.01
        root.visual.map.zfar = 50

        self._make_materials()
        self._make_shell()
        self._make_lights()
        self._place_furniture()
        self._cabinet_site = root.worldbody.add("site", name="cabinet_site", pos=[0, 0, 0], size=[0.01], rgba=[0, 0, 0, 0], group=5)
        # A wide view for debugging and figures (not the benchmark camera).
        ov = np.array([-self.keepout.zone_x - 2.6, -self.half_width + 0.3, self.ceiling - 0.25])
        tgt = np.array([self.back_x - 0.3, 0.5, 0.6])
        look = look_rotation(tgt - ov)
        root.worldbody.add("camera", name="overview", pos=ov, xyaxes=np.concatenate([look[:, 0], look[:, 1]]), fovy=70)

    # ------------------------------------------------------------------ materials
    def _mat(self, name, rgba=None, texture=None, texrepeat=None, emission=None, specular=0.2, shininess=0.2, texuniform=True):
        kw = dict(name=name, specular=specular, shininess=shininess)
        if rgba is not None:
            kw["rgba"] = [float(x) for x in rgba]
        if texture is not None:
            kw["texture"] = texture
            kw["texuniform"] = "true" if texuniform else "false"
            kw["texrepeat"] = [float(x) for x in (texrepeat or (1, 1))]
        if emission is not None:
            kw["emission"] = float(emission) * self.light_scale
        return self._mjcf_root.asset.add("material", **kw)

    def _make_materials(self):
        rng = self._rng
        spec = ROOM_SPECS[self.room]
        A = self._mjcf_root.asset
        # ---- floor
        kind = str(rng.choice(spec["floors"]))
        self.floor_kind = kind
        if kind == "wood":
            base = np.array(WOOD_TONES[int(rng.integers(len(WOOD_TONES)))]) * rng.uniform(0.85, 1.1)
            tex = A.add("texture", name="floor_tex", type="2d", file=_png(_tex_wood(rng, base)))
            rep = 1.0 / rng.uniform(1.0, 1.6)
        elif kind == "tiles":
            c = _hsv(rng.uniform(), rng.uniform(0.0, 0.3), rng.uniform(0.55, 0.95))
            c2 = c * rng.uniform(0.85, 1.0) if rng.random() < 0.6 else _hsv(rng.uniform(), rng.uniform(0, 0.3), rng.uniform(0.2, 0.5))
            tex = A.add("texture", name="floor_tex", type="2d", builtin="checker", rgb1=c, rgb2=c2, mark="edge",
                        markrgb=c * 0.55, width=256, height=256)
            rep = 1.0 / (2 * rng.uniform(0.25, 0.6))
        elif kind == "checker":
            c1 = _hsv(rng.uniform(), rng.uniform(0, 0.6), rng.uniform(0.5, 0.9))
            c2 = _hsv(rng.uniform(), rng.uniform(0, 0.6), rng.uniform(0.1, 0.5))
            tex = A.add("texture", name="floor_tex", type="2d", builtin="checker", rgb1=c1, rgb2=c2, width=128, height=128)
            rep = 1.0 / (2 * rng.uniform(0.2, 0.5))
        elif kind == "gradient":
            c1 = _hsv(rng.uniform(), rng.uniform(0.1, 0.6), rng.uniform(0.5, 0.9))
            c2 = _hsv(rng.uniform(), rng.uniform(0.1, 0.6), rng.uniform(0.2, 0.5))
            tex = A.add("texture", name="floor_tex", type="2d", builtin="gradient", rgb1=c1, rgb2=c2, width=128, height=128)
            rep = 1.0 / rng.uniform(0.5, 2.0)
        elif kind == "carpet":
            c = _hsv(rng.uniform(), rng.uniform(0.2, 0.6), rng.uniform(0.3, 0.7))
            tex = A.add("texture", name="floor_tex", type="2d", builtin="flat", rgb1=c, rgb2=c, mark="random",
                        markrgb=c * 0.8, random=0.3, width=128, height=128)
            rep = 2.0
        else:  # flat: concrete / linoleum
            c = _hsv(rng.uniform(), rng.uniform(0, 0.15), rng.uniform(0.45, 0.8))
            tex = A.add("texture", name="floor_tex", type="2d", builtin="flat", rgb1=c, rgb2=c, mark="random",
                        markrgb=c * 0.9, random=0.05, width=128, height=128)
            rep = 1.0
        self._mat("floor", texture=tex, texrepeat=(rep, rep), specular=float(rng.uniform(0.05, 0.4)))
        # ---- walls
        wk = str(rng.choice(spec["walls"]))
        self.wall_kind = wk
        paint = _hsv(rng.uniform(), rng.uniform(0.0, 0.45), rng.uniform(0.6, 0.95))
        if wk == "paint":
            self._mat("wall", rgba=(*paint, 1), specular=0.05)
        elif wk == "stripes":
            c2 = paint * rng.uniform(0.75, 0.92)
            tex = A.add("texture", name="wall_tex", type="2d", file=_png(_tex_stripes(rng, paint, c2)))
            self._mat("wall", texture=tex, texrepeat=(1 / rng.uniform(0.4, 1.0), 1 / rng.uniform(0.4, 1.0)), specular=0.05)
        elif wk == "brick":
            brick = _hsv(rng.uniform(0.0, 0.08), rng.uniform(0.4, 0.7), rng.uniform(0.45, 0.75))
            if rng.random() < 0.3:  # painted brick
                brick = paint
            tex = A.add("texture", name="wall_tex", type="2d", file=_png(_tex_brick(rng, brick, brick * 0.6 + 0.35)))
            self._mat("wall", texture=tex, texrepeat=(1 / 0.8, 1 / 0.8), specular=0.05)
        elif wk == "tiles":
            tex = A.add("texture", name="wall_tex", type="2d", builtin="checker", rgb1=paint, rgb2=paint * 0.97, mark="edge",
                        markrgb=paint * 0.7, width=128, height=128)
            self._mat("wall", texture=tex, texrepeat=(1 / (2 * 0.15), 1 / (2 * 0.15)), specular=0.3)
        else:  # wainscot: paint above, wood panel below (panel added as geoms in _make_shell)
            self._mat("wall", rgba=(*paint, 1), specular=0.05)
        # ---- furniture palette
        wood = np.array(WOOD_TONES[int(rng.integers(len(WOOD_TONES)))])
        self._mat("wood", rgba=(*wood, 1), specular=0.2)
        self._mat("wood_dark", rgba=(*(wood * 0.6), 1), specular=0.2)
        fab = _hsv(rng.uniform(), rng.uniform(0.2, 0.7), rng.uniform(0.3, 0.8))
        self._mat("fabric", rgba=(*fab, 1), specular=0.02)
        self._mat("fabric2", rgba=(*_hsv(rng.uniform(), rng.uniform(0.2, 0.7), rng.uniform(0.3, 0.8)), 1), specular=0.02)
        self._mat("accent", rgba=(*_hsv(rng.uniform(), rng.uniform(0.5, 0.9), rng.uniform(0.5, 0.9)), 1), specular=0.5, shininess=0.6)
        self._mat("metal", rgba=(0.6, 0.6, 0.62, 1), specular=0.8, shininess=0.8)
        self._mat("white", rgba=(0.92, 0.92, 0.9, 1), specular=0.3)
        self._mat("black", rgba=(0.08, 0.08, 0.09, 1), specular=0.5)
        self._mat("screen", rgba=(0.05, 0.08, 0.12, 1), specular=0.9, shininess=0.9)
        self._mat("stone", rgba=(*_hsv(rng.uniform(), rng.uniform(0, 0.2), rng.uniform(0.2, 0.9)), 1), specular=0.6)
        self._mat("cabinet_front", rgba=(*_hsv(rng.uniform(), rng.uniform(0, 0.4), rng.uniform(0.4, 0.95)), 1), specular=0.3)
        self._mat("terracotta", rgba=(0.72, 0.38, 0.24, 1), specular=0.1)
        self._mat("soil", rgba=(0.2, 0.13, 0.08, 1), specular=0.0)
        self._mat("leaf", rgba=(*_hsv(rng.uniform(0.25, 0.4), rng.uniform(0.5, 0.8), rng.uniform(0.3, 0.6)), 1), specular=0.2)
        self._mat("cardboard", rgba=(0.66, 0.5, 0.32, 1), specular=0.05)
        self._mat("lampshade", rgba=(1.0, 0.95, 0.82, 1), emission=0.6, specular=0.0)
        self._mat("window", rgba=(0.75, 0.88, 1.0, 1), emission=0.8, specular=0.0)
        rug = _hsv(rng.uniform(), rng.uniform(0.3, 0.8), rng.uniform(0.25, 0.6))
        self._mat("rug", rgba=(*rug, 1), specular=0.0)
        self._mat("rug2", rgba=(*_hsv(rng.uniform(), rng.uniform(0.2, 0.6), rng.uniform(0.4, 0.8)), 1), specular=0.0)
        for i in range(4):
            self._mat(f"book{i}", rgba=(*_hsv(rng.uniform(), rng.uniform(0.3, 0.8), rng.uniform(0.25, 0.75)), 1), specular=0.1)
        for i in range(2):
            self._mat(f"art{i}", rgba=(*_hsv(rng.uniform(), rng.uniform(0.3, 0.9), rng.uniform(0.3, 0.9)), 1), specular=0.1)

    # ------------------------------------------------------------------ floor, walls, ceiling
    def _deco_geom(self, parent, **kw):
        kw.setdefault("contype", 0)
        kw.setdefault("conaffinity", 0)
        kw.setdefault("group", 1)
        g = parent.add("geom", **kw)
        self._decorations.append(g)
        return g

    def _make_shell(self):
        rng = self._rng
        k = self.keepout
        self.back_x = k.zone_x + float(rng.uniform(0.25, 0.6))
        self.front_x = k.los_x_min - float(rng.uniform(0.4, 1.0))
        self.half_width = float(rng.uniform(*ROOM_SPECS[self.room].get("width", (1.7, 2.6))))
        self.ceiling = float(max(k.los_z, k.zone_z) + rng.uniform(0.15, 0.5))
        wb = self._mjcf_root.worldbody
        cx = 0.5 * (self.back_x + self.front_x)
        hx = 0.5 * (self.back_x - self.front_x)
        W, H, t = self.half_width, self.ceiling, 0.1
        self.floor = wb.add("geom", name="floor", type="plane", pos=[cx, 0, 0], size=[hx, W, 0.1], material="floor",
                            friction=[1.0, 0.005, 0.0001], group=0)
        # Walls are finite visual planes facing into the room: a plane maps a 2D texture onto its own
        # x-y axes (boxes would smear it along one axis), and texrepeat then counts repeats per metre.
        walls = (
            ("wall_back", [self.back_x, 0, H / 2], [0, -1, 0, 0, 0, 1], W),
            ("wall_front", [self.front_x, 0, H / 2], [0, 1, 0, 0, 0, 1], W),
            ("wall_left", [cx, W, H / 2], [1, 0, 0, 0, 0, 1], hx),
            ("wall_right", [cx, -W, H / 2], [-1, 0, 0, 0, 0, 1], hx),
        )
        for nm, pos, xy, half in walls:
            self._deco_geom(wb, name=nm, type="plane", pos=pos, xyaxes=xy, size=[half, H / 2, 0.1], material="wall")
        self._deco_geom(wb, name="ceiling", type="box", pos=[cx, 0, H + t], size=[hx + 2 * t, W + 2 * t, t], rgba=[0.95, 0.95, 0.93, 1])
        # skirting boards (and a wood panel for wainscot walls)
        skirt_h = 0.45 if self.wall_kind == "wainscot" else 0.04
        mat = "wood" if self.wall_kind == "wainscot" else "white"
        self._deco_geom(wb, name="skirt_back", type="box", pos=[self.back_x - 0.008, 0, skirt_h], size=[0.008, W, skirt_h], material=mat)
        for s in (1, -1):
            self._deco_geom(wb, name=f"skirt_{'left' if s > 0 else 'right'}", type="box", pos=[cx, s * (W - 0.008), skirt_h],
                            size=[hx, 0.008, skirt_h], material=mat)

    # ------------------------------------------------------------------ lights
    def _make_lights(self):
        rng = self._rng
        s = self.light_scale
        wb = self._mjcf_root.worldbody
        amb = float(rng.uniform(0.15, 0.3))
        hl = self._mjcf_root.visual.headlight
        hl.ambient = [amb * s] * 3
        hl.diffuse = [float(rng.uniform(0.1, 0.25)) * s] * 3
        hl.specular = [0.05 * s] * 3
        n = int(rng.integers(1, 4))
        self.lights = []
        tint = 1.0 + np.array([0.06, 0.0, -0.08]) * rng.uniform(-1, 1)  # warm or cool light
        for i in range(n):
            pos = np.array([rng.uniform(-2.0, self.back_x - 0.3), rng.uniform(-self.half_width + 0.4, self.half_width - 0.4), self.ceiling - 0.05])
            target = np.array([rng.uniform(-0.6, 0.4), rng.uniform(-0.8, 0.8), 0.0])
            d = target - pos
            d /= np.linalg.norm(d)
            diff = float(rng.uniform(0.35, 0.75)) / np.sqrt(n) * s
            directional = bool(rng.random() < 0.3)
            self.lights.append(wb.add(
                "light", name=f"light{i}", pos=pos, dir=d, type="directional" if directional else "spot",
                diffuse=np.clip(diff * tint, 0, None), specular=[0.15 * s] * 3, ambient=[0.0, 0.0, 0.0],
                cutoff=float(rng.uniform(55, 85)), exponent=float(rng.uniform(1, 6)), castshadow="false"))
            # a ceiling fixture where the light hangs
            self._deco_geom(wb, name=f"ceiling_lamp{i}", type="cylinder", pos=[pos[0], pos[1], self.ceiling - 0.02], size=[0.18, 0.02], material="lampshade")

    # ------------------------------------------------------------------ furniture
    def _free(self, lo, hi) -> bool:
        for klo, khi in self.keepout.boxes():
            if _overlap(lo, hi, klo, khi, pad=0.02):
                return False
        for plo, phi in self._placed:
            if _overlap(lo, hi, plo, phi, pad=0.03):
                return False
        room_lo = np.array([self.front_x, -self.half_width, 0.0])
        room_hi = np.array([self.back_x, self.half_width, self.ceiling])
        return bool(np.all(lo >= room_lo - 1e-9) and np.all(hi <= room_hi + 1e-9))

    def _add_item(self, name, parts, pos, yaw):
        body = self._mjcf_root.worldbody.add("body", name=name, pos=[float(x) for x in pos], quat=[float(x) for x in yaw_quat(yaw)])
        for j, (typ, p, size, mat, euler) in enumerate(parts):
            kw = dict(name=f"{name}_{j}", type=typ, pos=[float(x) for x in p], size=[float(x) for x in size], material=mat)
            if euler is not None:
                kw["euler"] = [float(x) for x in euler]
            self._deco_geom(body, **kw)
        return body

    def _place_first_free(self, propose, tries: int):
        """Rejection sampling: the first proposal ``(pos, yaw, lo, hi)`` whose box is free, or None."""
        for _ in range(tries):
            pos, yaw, lo, hi = propose()
            if self._free(lo, hi):
                self._placed.append((lo, hi))
                return pos, yaw
        return None

    def _place_furniture(self):
        rng = self._rng
        spec = ROOM_SPECS[self.room]
        k = self.keepout
        W = self.half_width
        self.furniture: list[str] = []
        x_min = max(self.front_x + 0.05, -2.8)  # behind the camera nothing is seen
        for idx, (item, where) in enumerate(spec["floor"]):
            hx0, hy0, h, parts = FLOOR_ITEMS[item](rng)

            def propose_floor(where=where, hx0=hx0, hy0=hy0, h=h):
                side = 1 if rng.random() < 0.5 else -1
                if where == "back":  # against the back wall, facing -x
                    yaw, hx, hy = np.pi, hx0, hy0
                    x = self.back_x - hx - 0.01
                    y = rng.uniform(-W + hy, W - hy)
                elif where == "back_corner":
                    yaw, hx, hy = np.pi, hx0, hy0
                    x = self.back_x - hx - 0.01
                    y = side * (W - hy - 0.01)
                elif where == "side":  # against a side wall, facing the room
                    yaw, hx, hy = -side * np.pi / 2, hy0, hx0
                    y = side * (W - hy - 0.01)
                    x = rng.uniform(x_min + hx, self.back_x - hx)
                else:  # free standing
                    yaw = float(rng.integers(0, 4)) * np.pi / 2
                    hx, hy = (hx0, hy0) if int(round(yaw / (np.pi / 2))) % 2 == 0 else (hy0, hx0)
                    x = rng.uniform(x_min + hx, self.back_x - hx)
                    y = side * rng.uniform(k.zone_y + k.los_margin + hy, max(W - hy, k.zone_y + k.los_margin + hy + 1e-3))
                return (x, y, 0.0), yaw, np.array([x - hx, y - hy, 0.0]), np.array([x + hx, y + hy, h])

            placed = self._place_first_free(propose_floor, 60)
            if placed is not None:
                self._add_item(f"{item}{idx}", parts, *placed)
                self.furniture.append(item)
        for idx, (item, wall, zc) in enumerate(spec["wall"]):
            hd, hy0, hz, parts = WALL_ITEMS[item](rng)

            def propose_wall(wall=wall, zc=zc, hd=hd, hy0=hy0, hz=hz):
                z = zc + rng.uniform(-0.1, 0.1)
                z = min(max(z, hz + 0.01), self.ceiling - hz - 0.02)
                if wall == "back":
                    yaw = np.pi
                    x, y = self.back_x, rng.uniform(-W + hy0 + 0.05, W - hy0 - 0.05)
                    lo, hi = np.array([x - 2 * hd, y - hy0, z - hz]), np.array([x, y + hy0, z + hz])
                else:
                    side = 1 if rng.random() < 0.5 else -1
                    yaw = -side * np.pi / 2
                    x, y = rng.uniform(x_min + hy0, self.back_x - hy0 - 0.05), side * W
                    lo = np.array([x - hy0, y - 2 * hd if side > 0 else y, z - hz])
                    hi = np.array([x + hy0, y if side > 0 else y + 2 * hd, z + hz])
                return (x, y, z), yaw, lo, hi

            placed = self._place_first_free(propose_wall, 40)
            if placed is not None:
                self._add_item(f"{item}_w{idx}", parts, *placed)
                self.furniture.append(item)

    # ------------------------------------------------------------------ API
    @property
    def cabinet_site(self):
        """Site at the world origin on the floor: attach the cabinet here (``attach_cabinet``)."""
        return self._cabinet_site

    def attach_cabinet(self, cabinet_entity):
        """Attach a cabinet entity (fixed, no free joint) at the origin; returns the attachment frame.

        The carcass stands on the floor; its doors and drawers do not touch it (no floor contact for
        the cabinet's moving bodies, as real fronts hang a few millimetres clear of the floor; every
        other contact, the hand's with the floor included, is kept). See docs/cabinets.md.
        """
        from .cabinet import moving_bodies

        frame = self.attach(cabinet_entity, self._cabinet_site)
        bodies = (cabinet_entity.moving_bodies() if hasattr(cabinet_entity, "moving_bodies")
                  else moving_bodies(cabinet_entity.mjcf_model))
        for body in bodies:
            self._mjcf_root.contact.add("exclude", body1="world", body2=body)
        return frame

    def add_camera(self, pose, name: str = "front"):
        from .camera import add_camera

        return add_camera(self._mjcf_root, pose, name=name)

    @property
    def decoration_geoms(self) -> list:
        """All visual-only geoms (walls, ceiling, furniture, lamps); the floor is not among them."""
        return list(self._decorations)

    @property
    def keepout_boxes(self) -> list[tuple[np.ndarray, np.ndarray]]:
        return self.keepout.boxes()
