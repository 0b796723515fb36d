"""Furniture, as lists of primitive parts in a local frame: origin on the floor at the footprint
centre, front facing local +x. Each builder returns (half_x, half_y, height, parts); a part is
(type, pos, size, material, euler_or_None)."""

from __future__ import annotations

from typing import Callable

import numpy as np


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
