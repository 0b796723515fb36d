"""Sampling a whole cabinet: carcass panels, drawers and doors with their handles (metres, mesh frame)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from opend_mj.assets.procedural.config import GeneratorConfig
from opend_mj.assets.procedural.handles import HandleStyle, handle_style, make_handle
from opend_mj.assets.procedural.layouts import Layout, Leaf, sample_layout
from opend_mj.assets.procedural.materials import HANDLE_FINISHES, PALETTES, Material, pick_colour
from opend_mj.assets.procedural.pieces import Box, Piece, bounds_of, translate_piece


@dataclass
class Visual:
    """One OBJ file: a PartNet part name (``drawer_front``) and its convex pieces."""

    part: str
    pieces: list[Piece]
    material: Material


@dataclass
class Target:
    """A movable link: drawer or door, with its joint and handle."""

    kind: str  # "drawer" | "door"
    joint_type: str  # "prismatic" | "revolute"
    axis: tuple[float, float, float]
    origin: tuple[float, float, float]  # axis point P, metres, mesh frame
    upper: float
    visuals: list[Visual] = field(default_factory=list)
    hinge: str = ""
    double: bool = False
    handle_kind: str = ""
    handle_orientation: str = ""
    handle_center: tuple[float, float, float] = (0.0, 0.0, 0.0)


def build_parts(rng: np.random.Generator, cfg: GeneratorConfig, layout: Layout, t: float, plinth: float,
                colours: dict, floor_fronts: bool = False,
                doors_rng: np.random.Generator | None = None) -> tuple[list[Visual], list[Target]]:
    """Carcass visuals and movable targets of a layout (metres, mesh frame).

    ``floor_fronts``: the bottom row's doors and drawer fronts reach down to the floor (the bottom panel
    stands back behind them), as on many real cabinets without a plinth. ``doors_rng``: the random
    stream of the doors' flaps and of where a door's bar ends; None: no flaps, bars end 25 mm short."""
    W, H, D = layout.width, layout.height, layout.depth
    g = cfg.clearance
    body = Material("body", colours["body"])
    front = Material("front", colours["front"])
    inner = Material("interior", colours["interior"])
    hk = colours["handle"]
    handle_mat = Material("handle", hk[0], hk[1], hk[2])
    t_back = float(rng.uniform(0.008, 0.012))
    x0, x1 = -W / 2, W / 2
    y0, y1 = -H / 2, H / 2
    zb, zf = -D / 2, D / 2
    zbi = zb + t_back  # inner face of the back panel
    carcass: list[Visual] = [
        Visual("vertical_side_panel", [Box((x0, y0, zb), (x0 + t, y1 - t, zf))], body),
        Visual("vertical_side_panel", [Box((x1 - t, y0, zb), (x1, y1 - t, zf))], body),
        Visual("top_panel", [Box((x0, y1 - t, zb), (x1, y1, zf))], body),
        Visual("bottom_panel", [Box((x0 + t, y0 + plinth, zbi),
                                    (x1 - t, y0 + plinth + t, zf - (0.02 + g if floor_fronts else 0.0)))], body),
        Visual("back_panel", [Box((x0 + t, y0 + plinth, zb), (x1 - t, y1 - t, zbi))], body),
    ]
    if plinth > 0:
        setback = float(rng.uniform(0.02, 0.06))
        carcass.append(Visual("base_side_panel",
                              [Box((x0 + t, y0, zf - setback - t), (x1 - t, y0 + plinth, zf - setback))], body))
    # cells
    cells: list[tuple[Leaf, float, float, float, float]] = []

    def place(node, cx0, cx1, cy0, cy1):
        if isinstance(node, Leaf):
            cells.append((node, cx0, cx1, cy0, cy1))
            return
        ws = [w for w, _ in node.children]
        n = len(ws)
        if node.axis == "rows":
            avail = (cy1 - cy0) - (n - 1) * t
            y = cy1
            for i, (w, child) in enumerate(node.children):
                hgt = avail * w / sum(ws)
                place(child, cx0, cx1, y - hgt, y)
                y -= hgt
                if i < n - 1:
                    carcass.append(Visual("horizontal_divider_panel", [Box((cx0, y - t, zbi), (cx1, y, zf))], body))
                    y -= t
        else:
            avail = (cx1 - cx0) - (n - 1) * t
            x = cx0
            for i, (w, child) in enumerate(node.children):
                wid = avail * w / sum(ws)
                place(child, x, x + wid, cy0, cy1)
                x += wid
                if i < n - 1:
                    carcass.append(Visual("vertical_divider_panel", [Box((x, cy0, zbi), (x + t, cy1, zf))], body))
                    x += t

    place(layout.tree, x0 + t, x1 - t, y0 + plinth + t, y1 - t)

    drawer_style = handle_style(rng, cfg, "drawer")
    if rng.random() < cfg.shared_handle_kind_share:  # usually one handle kind for the whole cabinet
        door_style = handle_style(rng, cfg, "door", drawer_style.kind)
        door_style.diameter, door_style.clearance, door_style.square = (
            drawer_style.diameter, drawer_style.clearance, drawer_style.square)
        door_style.arch_style = drawer_style.arch_style
    else:
        door_style = handle_style(rng, cfg, "door")
    t_front = float(rng.uniform(0.016, 0.02))
    t_box = float(rng.uniform(0.010, 0.014))
    door_upper = float(rng.uniform(1.57, 2.0))
    door_handle_margin = float(rng.uniform(*cfg.door_handle_margin_range))
    door_handle_dy = float(rng.uniform(-0.25, 0.25))
    door_bar_top = bool(rng.random() < cfg.door_bar_top_share)
    door_bar_centred = bool(rng.random() < cfg.door_bar_centred_share)
    door_bar_edge = float(rng.uniform(*cfg.door_bar_edge_range))
    flap, flap_upper, bar_end_margin = None, door_upper, 0.025
    if doors_rng is not None:
        if doors_rng.random() < cfg.flap_share:
            flap = "top" if doors_rng.random() < cfg.flap_top_share else "bottom"
        flap_upper = float(doors_rng.uniform(*(cfg.flap_top_range if flap == "top" else cfg.flap_bottom_range)))
        bar_end_margin = float(doors_rng.uniform(*cfg.door_bar_end_margin_range))
    floor_y = y0
    bottom_row = y0 + plinth + t  # lower edge of the cells of the bottom row

    targets: list[Target] = []
    for leaf, cx0, cx1, cy0, cy1 in cells:
        if leaf.kind == "open":
            continue
        front_y0 = y0 if floor_fronts and abs(cy0 - bottom_row) < 1e-9 else cy0 + g
        if leaf.kind == "drawer":
            lo = np.array([cx0 + g, front_y0, zf - t_front])
            hi = np.array([cx1 - g, cy1 - g, zf])
            side_gap = max(g, 0.008)
            bx0, bx1 = cx0 + side_gap, cx1 - side_gap
            by0 = cy0 + max(g, 0.006)
            by1 = max(by0 + 2 * t_box + 0.02, cy1 - max(0.015, 0.15 * (cy1 - cy0)))
            bz0 = zbi + float(rng.uniform(0.01, 0.03))
            bz1 = zf - t_front
            box = [
                Box((bx0, by0, bz0), (bx1, by0 + t_box, bz1)),  # bottom
                Box((bx0, by0 + t_box, bz0), (bx0 + t_box, by1, bz1)),  # left
                Box((bx1 - t_box, by0 + t_box, bz0), (bx1, by1, bz1)),  # right
                Box((bx0 + t_box, by0 + t_box, bz0), (bx1 - t_box, by1, bz0 + t_box)),  # back
            ]
            depth = zf - bz0
            centre = (lo + hi) / 2
            if hi[0] - lo[0] > cfg.paired_pull_min_width and rng.random() < cfg.paired_pull_share:
                # two pulls, each centred on its half of the front (the pair is the drawer's handle)
                pieces = []
                for half_lo, half_hi in (((lo[0], lo[1]), (centre[0], hi[1])), ((centre[0], lo[1]), (hi[0], hi[1]))):
                    hlo = np.array([half_lo[0], half_lo[1], lo[2]])
                    hhi = np.array([half_hi[0], half_hi[1], hi[2]])
                    part, kind, orient = make_handle(rng, cfg, drawer_style, hlo, hhi, (hlo + hhi) / 2)
                    pieces += part
            else:
                pieces, kind, orient = make_handle(rng, cfg, drawer_style, lo, hi, centre)
            origin = (float(centre[0]), float(centre[1]), zf)
            tg = Target("drawer", "prismatic", (0.0, 0.0, 1.0), origin, float(rng.uniform(0.7, 0.9)) * depth,
                        [Visual("drawer_front", [Box(tuple(lo), tuple(hi))], front),
                         Visual("drawer_box", box, inner),
                         Visual("handle", pieces, handle_mat)],
                        handle_kind=kind, handle_orientation=orient)
            targets.append(tg)
            continue
        # doors (with an inner shelf behind tall ones)
        if cy1 - cy0 > 0.45 and rng.random() < cfg.door_shelf_share:
            ys = cy0 + float(rng.uniform(0.4, 0.6)) * (cy1 - cy0)
            carcass.append(Visual("shelf", [Box((cx0, ys, zbi), (cx1, ys + t, zf - t_front - 0.02))], body))
        leaves: list[tuple[float, float, str]] = []
        if leaf.kind == "double_door":
            xm = (cx0 + cx1) / 2
            leaves = [(cx0 + g, xm - g / 2 - 0.001, "left"), (xm + g / 2 + 0.001, cx1 - g, "right")]
        else:
            leaves = [(cx0 + g, cx1 - g, leaf.hinge)]
        for lx0, lx1, hinge in leaves:
            lo = np.array([lx0, front_y0, zf - t_front])
            hi = np.array([lx1, cy1 - g, zf])
            door_h = hi[1] - lo[1]
            if flap is not None and layout.flaps and door_h <= cfg.flap_max_height:
                targets.append(_flap(rng, cfg, lo, hi, flap if lo[1] > floor_y + 1e-9 else "top", flap_upper,
                                     door_style, door_bar_edge, bar_end_margin, hinge, leaf.kind == "double_door",
                                     lo[1] - floor_y, front, handle_mat))
                continue
            # handle near the free edge; near the top of low doors, around 1 m up on tall doors
            free_x = lx1 if hinge == "left" else lx0
            inward = -1.0 if hinge == "left" else 1.0
            hx = free_x + inward * door_handle_margin
            top_world = hi[1] - floor_y
            if top_world < 1.0:
                hy = hi[1] - 0.2 * door_h
            else:
                hy = (lo[1] + hi[1]) / 2 + door_handle_dy * door_h
            st = door_style
            if st.orientation == "horizontal":
                # a horizontal bar runs along the door's top (or bottom) edge, from near the free edge
                # or centred across the door
                if door_h < 0.9:  # (a tall door's bar stays about 1 m up)
                    hy = hi[1] - door_bar_edge if door_bar_top else lo[1] + door_bar_edge
                hx = (lx0 + lx1) / 2 if door_bar_centred else free_x + inward * (
                    0.025 + 0.5 * min(0.3, 0.5 * (lx1 - lx0)))
            pieces, kind, orient = make_handle(rng, cfg, st, lo, hi, np.array([hx, hy, 0.0]))
            if orient == "horizontal" and not door_bar_centred:  # its real length, from near the free edge
                pieces = _bar_end_at(pieces, free_x, inward, bar_end_margin)
            hinge_x = lx0 if hinge == "left" else lx1
            axis = (0.0, -1.0, 0.0) if hinge == "left" else (0.0, 1.0, 0.0)
            origin = (hinge_x, float((lo[1] + hi[1]) / 2), zf)
            targets.append(Target("door", "revolute", axis, origin, door_upper,
                                  [Visual("cabinet_door_surface", [Box(tuple(lo), tuple(hi))], front),
                                   Visual("handle", pieces, handle_mat)],
                                  hinge=hinge, double=leaf.kind == "double_door",
                                  handle_kind=kind, handle_orientation=orient))
    for tg in targets:
        hl, hh = bounds_of(tg.visuals[-1].pieces)
        tg.handle_center = tuple(float(v) for v in (hl + hh) / 2)
    return carcass, targets


def _bar_end_at(pieces: list[Piece], free_x: float, inward: float, margin: float) -> list[Piece]:
    """A horizontal bar's pieces moved along x so that its end nearest the door's free edge (at x =
    ``free_x``; ``inward``: +1 or -1, the direction into the door) stands ``margin`` (m) inside it."""
    bl, bh = bounds_of(pieces)
    shift = (free_x + inward * margin) - (bh[0] if inward < 0 else bl[0])
    return [translate_piece(p, (shift, 0.0, 0.0)) for p in pieces]


def _flap(rng: np.random.Generator, cfg: GeneratorConfig, lo: np.ndarray, hi: np.ndarray, edge: str,
          upper: float, style: HandleStyle, bar_edge: float, end_margin: float, side: str, double: bool,
          hinge_height: float, front: Material, handle_mat: Material) -> Target:
    """A door hinged about a horizontal axis along its ``edge`` ("top": it lifts up; "bottom": it drops
    down), with a horizontal bar along its free edge: centred on a single flap, from near the meeting
    edge on a pair (``side``: the leaf's hinge side as a double door, i.e. where its free edge is).

    A flap hinged at its bottom edge passes below its hinge beyond 90 degrees; its range keeps the free
    edge 1 cm above the floor (``hinge_height``, m, is the hinge's height above the floor)."""
    door_h = float(hi[1] - lo[1])
    if edge == "bottom":
        upper = min(upper, math.pi / 2 + max(0.0, hinge_height - 0.01) / door_h)
    st = replace(style, orientation="horizontal", kind="bar" if style.kind == "knob" else style.kind)
    hy = float(hi[1] - bar_edge) if edge == "bottom" else float(lo[1] + bar_edge)
    hx = float((lo[0] + hi[0]) / 2)
    pieces, kind, orient = make_handle(rng, cfg, st, lo, hi, np.array([hx, hy, 0.0]))
    if double and orient == "horizontal":  # side by side: the bar ends near the pair's meeting edge
        free_x, inward = (float(hi[0]), -1.0) if side == "left" else (float(lo[0]), 1.0)
        pieces = _bar_end_at(pieces, free_x, inward, end_margin)
    # a positive angle swings the free edge out of the front (+z) about the hinge line on the front face
    axis = (1.0, 0.0, 0.0) if edge == "bottom" else (-1.0, 0.0, 0.0)
    origin = (hx, float(lo[1] if edge == "bottom" else hi[1]), float(hi[2]))
    return Target("door", "revolute", axis, origin, float(upper),
                  [Visual("cabinet_door_surface", [Box(tuple(lo), tuple(hi))], front),
                   Visual("handle", pieces, handle_mat)],
                  hinge=edge, double=double, handle_kind=kind, handle_orientation=orient)


def unshare_vertices(visuals: list[Visual]) -> list[Visual]:
    """Shrink the k-th box of a link by (k+1) * 10 um so that no two pieces share a vertex position.

    Touching panels (a side and the top, a drawer's bottom and side) would otherwise share corners, and a
    compiler that welds vertices by position would merge them into one non-convex piece.
    """
    out, k = [], 0
    for v in visuals:
        pieces: list[Piece] = []
        for p in v.pieces:
            if isinstance(p, Box):
                k += 1
                e = 1e-5 * k
                p = Box(tuple(np.asarray(p.lo) + e), tuple(np.asarray(p.hi) - e))
            pieces.append(p)
        out.append(Visual(v.part, pieces, v.material))
    return out


BASES = ("floor_fronts", "inset", "low_plinth", "plinth")


def draw_base(rng: np.random.Generator, cfg: GeneratorConfig) -> tuple[str, float]:
    """How the cabinet meets the floor (one of ``BASES``) and its plinth height (m)."""
    base = BASES[int(rng.choice(len(BASES), p=list(cfg.base_shares)))]
    if base == "low_plinth":
        return base, float(rng.uniform(*cfg.low_plinth_range))
    if base == "plinth":
        return base, float(rng.uniform(*cfg.plinth_range))
    return base, 0.0


@dataclass
class SampledCabinet:
    """One procedural cabinet as sampled, before it is written: its layout, panel thickness and plinth
    (m), handle finish, carcass visuals and movable targets (metres, mesh frame)."""

    id: str
    seed: int
    index: int
    thickness: float
    plinth: float
    base: str
    layout: Layout
    finish: str
    carcass: list[Visual]
    targets: list[Target]


#: The random stream ``(seed, index, n)`` each aspect of cabinet ``index`` draws from. Apart streams keep
#: a change to how one aspect is drawn from moving the draws of every other aspect.
STREAMS = {"layout": 1, "colours": 2, "parts": 3, "base": 4, "doors": 5}


def sample_cabinet(index: int, seed: int, config: GeneratorConfig = GeneratorConfig()) -> SampledCabinet:
    """Sample cabinet ``proc_<index>`` from the random streams ``(seed, index, STREAMS[...])`` (deterministic)."""
    cfg = config

    def stream(aspect: str) -> np.random.Generator:
        return np.random.default_rng([seed, index, STREAMS[aspect]])

    rng = stream("layout")
    t = float(rng.uniform(*cfg.thickness_range))
    base, plinth = draw_base(stream("base"), cfg)
    layout = sample_layout(rng, cfg, t, plinth)
    rng = stream("colours")
    body = pick_colour(rng, cfg)
    front = body if rng.random() < cfg.front_matches_body_share else pick_colour(rng, cfg)
    interior = body if rng.random() < cfg.interior_matches_body_share else tuple(
        float(c) for c in np.clip(np.array(PALETTES["wood"][3]) + rng.uniform(-0.05, 0.05, 3), 0, 1))
    if rng.random() < cfg.body_coloured_handle_share:
        handle = (front, 0.1, 40.0)
        finish = "body"
    else:
        finish = list(HANDLE_FINISHES)[rng.integers(len(HANDLE_FINISHES))]
        handle = HANDLE_FINISHES[finish]
    colours = {"body": body, "front": front, "interior": interior, "handle": handle}
    carcass, targets = build_parts(stream("parts"), cfg, layout, t, plinth, colours,
                                   floor_fronts=base == "floor_fronts", doors_rng=stream("doors"))
    return SampledCabinet(f"proc_{index:04d}", int(seed), int(index), t, plinth, base, layout, finish, carcass,
                          targets)
