"""Procedural cabinets written in SAPIEN PartNet-Mobility format.

Each cabinet is a folder ``proc_NNNN/`` with ``mobility.urdf``, ``semantics.txt``, ``meta.json`` and
``textured_objs/original-K.obj`` (+ ``.mtl``), laid out exactly like a real PartNet-Mobility object so
that one compiler handles both.

Conventions (the same as PartNet-Mobility):

* Mesh frame: y up, the cabinet front faces +z, +x is to the right seen from the front. Vertices are
  object coordinates in PartNet's normalised units: real metres divided by ``PARTNET_SCALE``.
* ``base`` is an empty link; the carcass ``link_N`` (N = number of movable parts) hangs off it with a
  fixed joint rotated ``rpy="pi/2 0 -pi/2"`` (y-up to z-up, front to world -x). Every movable link is a
  child of the carcass; its joint origin is the axis point P and its visuals/collisions are offset by -P.
* Drawers are prismatic along +z; doors are revolute about the vertical edge at the front face (axis
  ``0 -1 0`` for a left hinge, ``0 1 0`` for a right hinge: both open outward for positive angles).

Every convex piece (panel box, handle cylinder) is its own closed, outward-oriented connected component
in its OBJ, so the compiler can keep pieces as convex collision geoms without decomposition. Closed
cabinets have at least ``clearance`` (4 mm) between parts of different links.

About half of the cabinets are deliberately not describable by the language rule of OpenD's
Algorithm 1 (e.g. stacks of 6-8 drawers: more than five vertical levels); ``meta.json`` records this
under ``procedural.describable`` together with the handle centres that decide it.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
from tqdm import tqdm

from opend_mj.assets.layout import PARTNET_SCALE
from opend_mj.language import LanguageConfig, LanguageInvalid, TargetLayout, describe

#: Bumped whenever the generated geometry changes.
GENERATOR_VERSION = "4"

HANDLE_KINDS = ("bar", "arched", "knob")


@dataclass(frozen=True)
class GeneratorConfig:
    """Knobs of the procedural generator (lengths in real metres)."""

    scale: float = PARTNET_SCALE
    #: Target fraction of cabinets that the language rule cannot describe (as in OpenD: 172/346).
    invalid_fraction: float = 0.5
    #: Gap between a movable part and every carcass panel / neighbouring movable part.
    clearance: float = 0.004
    #: Sides of every handle cylinder.
    cylinder_sides: int = 16
    #: Decimals written for every float (determinism and file size).
    decimals: int = 6
    #: Language rule: handle centres closer than this (m) form one level / one column position.
    level_tolerance: float = 0.04
    #: Language rule: at most this many vertical levels and horizontal positions can be named.
    max_levels: int = 5
    width_range: tuple[float, float] = (0.3, 1.2)
    height_range: tuple[float, float] = (0.3, 1.8)
    depth_range: tuple[float, float] = (0.3, 0.6)
    thickness_range: tuple[float, float] = (0.015, 0.020)
    #: Handle population, matched to the real OpenD training cabinets as the planner measures them in
    #: depth (``tools/handle_stats.py``; real 10th / 50th / 90th percentiles: bar thickness 6.6 / 12.3 /
    #: 16.9 mm, stand-off gap 9.6 / 23.1 / 34.8 mm, bar length 57 / 154 / 542 mm, knobs 4 %, knob size
    #: 37 / 41 / 44 mm). Generator 1 had 10-16 mm bars on 30-45 mm stand-offs, 8-30 cm long, 12 % knobs.
    bar_diameter_range: tuple[float, float] = (0.005, 0.021)
    bar_gap_range: tuple[float, float] = (0.008, 0.038)
    #: Probabilities of (bar, arched, knob) per target type.
    drawer_handle_kinds: tuple[float, float, float] = (0.70, 0.24, 0.06)
    door_handle_kinds: tuple[float, float, float] = (0.70, 0.24, 0.06)
    #: Share of straight bars that run most of their panel (long door pulls, full-width drawer bars).
    long_bar_share: float = 0.35
    long_bar_max: float = 0.80
    short_bar_min: float = 0.05
    #: Wide drawers (front wider than ``paired_pull_min_width``) carry two pulls, one per half, this often.
    paired_pull_share: float = 0.35
    paired_pull_min_width: float = 0.55
    knob_cap_radius_range: tuple[float, float] = (0.017, 0.023)
    #: Door handles sit this far (m) from the door's free edge (double doors: handles 3-12 cm apart).
    door_handle_margin_range: tuple[float, float] = (0.015, 0.06)
    #: Door handles that are horizontal bars (real side-hinged doors of the OpenD training cabinets:
    #: 47 of 126; generator 2 had 20 %). Of those, the real ones sit along the door's top edge (34 of
    #: 47; else along its bottom edge, as on wall units), 2-5 cm from it, centred across the door
    #: about half of the time (24 of 47; else near its free edge).
    door_horizontal_share: float = 0.37
    door_bar_top_share: float = 0.72
    door_bar_centred_share: float = 0.5
    door_bar_edge_range: tuple[float, float] = (0.03, 0.06)
    #: How a cabinet meets the floor, as shares of (bottom fronts down to the floor, fronts inset above
    #: the bottom panel, a low plinth in ``low_plinth_range``, a plinth or legs in ``plinth_range``).
    #: Matched to the real OpenD training cabinets' lowest moving part above the floor (the feasibility
    #: check's figure, 133 cabinets): 18 % within 5 mm, 16 % 0.5-5 cm, 4 % 5-10 cm, 62 % 10-22 cm.
    #: Drawn from a random stream of its own (the draws before the layout are version 3's).
    base_shares: tuple[float, float, float, float] = (0.18, 0.16, 0.05, 0.61)
    low_plinth_range: tuple[float, float] = (0.03, 0.08)
    plinth_range: tuple[float, float] = (0.08, 0.18)


# --------------------------------------------------------------------------------------------------
# Convex pieces and their meshes


@dataclass(frozen=True)
class Box:
    """Axis-aligned box in the mesh frame (metres)."""

    lo: tuple[float, float, float]
    hi: tuple[float, float, float]


@dataclass(frozen=True)
class Cylinder:
    """Closed prism with ``sides`` sides from ``p0`` to ``p1`` (metres)."""

    p0: tuple[float, float, float]
    p1: tuple[float, float, float]
    radius: float


Piece = Box | Cylinder

# Box corners (index bits: x = 4, y = 2, z = 1) and outward-facing triangles.
_BOX_FACES = (
    (0, 3, 2), (0, 1, 3),  # x = lo
    (4, 7, 5), (4, 6, 7),  # x = hi
    (0, 5, 1), (0, 4, 5),  # y = lo
    (2, 7, 6), (2, 3, 7),  # y = hi
    (0, 6, 4), (0, 2, 6),  # z = lo
    (1, 7, 3), (1, 5, 7),  # z = hi
)


def piece_mesh(piece: Piece, sides: int = 16) -> tuple[np.ndarray, list[tuple[int, int, int]]]:
    """Vertices (metres) and outward, counter-clockwise triangles of one convex piece."""
    if isinstance(piece, Box):
        lo, hi = piece.lo, piece.hi
        verts = np.array(
            [[(lo, hi)[i >> 2 & 1][0], (lo, hi)[i >> 1 & 1][1], (lo, hi)[i & 1][2]] for i in range(8)]
        )
        return verts, list(_BOX_FACES)
    p0, p1 = np.asarray(piece.p0, float), np.asarray(piece.p1, float)
    w = p1 - p0
    w /= np.linalg.norm(w)
    helper = np.array([1.0, 0.0, 0.0]) if abs(w[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(w, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(w, e1)  # e1 x e2 = w
    ang = 2.0 * np.pi * np.arange(sides) / sides
    ring = piece.radius * (np.cos(ang)[:, None] * e1 + np.sin(ang)[:, None] * e2)
    verts = np.vstack([p0 + ring, p1 + ring])
    n = sides
    faces: list[tuple[int, int, int]] = []
    for i in range(n):
        j = (i + 1) % n
        faces.append((i, j, n + j))
        faces.append((i, n + j, n + i))
    for i in range(1, n - 1):
        faces.append((0, i + 1, i))  # bottom cap, normal -w
        faces.append((n, n + i, n + i + 1))  # top cap, normal +w
    return verts, faces


def piece_bounds(piece: Piece) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned bounds (metres) of a piece (exact for boxes, conservative for cylinders)."""
    if isinstance(piece, Box):
        return np.asarray(piece.lo, float), np.asarray(piece.hi, float)
    p0, p1 = np.asarray(piece.p0, float), np.asarray(piece.p1, float)
    w = p1 - p0
    w /= np.linalg.norm(w)
    ext = piece.radius * np.sqrt(np.clip(1.0 - w * w, 0.0, 1.0))
    return np.minimum(p0, p1) - ext, np.maximum(p0, p1) + ext


# --------------------------------------------------------------------------------------------------
# Materials

_PALETTES: dict[str, list[tuple[float, float, float]]] = {
    "wood": [(0.72, 0.55, 0.36), (0.36, 0.24, 0.15), (0.55, 0.30, 0.17), (0.85, 0.74, 0.57),
             (0.80, 0.64, 0.42), (0.62, 0.45, 0.30)],
    "white": [(0.93, 0.93, 0.91), (0.90, 0.88, 0.83)],
    "grey": [(0.62, 0.62, 0.62), (0.42, 0.43, 0.45), (0.25, 0.26, 0.28)],
    "black": [(0.08, 0.08, 0.08)],
    "colour": [(0.55, 0.65, 0.52), (0.15, 0.22, 0.38), (0.60, 0.72, 0.82), (0.60, 0.16, 0.13),
               (0.86, 0.73, 0.32), (0.75, 0.55, 0.60)],
}
_PALETTE_WEIGHTS = {"wood": 0.4, "white": 0.2, "grey": 0.15, "black": 0.08, "colour": 0.17}
_HANDLE_FINISHES = {
    "steel": ((0.72, 0.73, 0.75), 0.6, 200.0),
    "chrome": ((0.86, 0.86, 0.88), 0.8, 400.0),
    "dark_grey": ((0.28, 0.28, 0.30), 0.4, 120.0),
    "black": ((0.04, 0.04, 0.04), 0.3, 80.0),
    "brass": ((0.78, 0.60, 0.26), 0.7, 250.0),
}


@dataclass(frozen=True)
class Material:
    """Phong material of one MTL file."""

    name: str
    kd: tuple[float, float, float]
    ks: float = 0.08
    ns: float = 30.0


def _pick_colour(rng: np.random.Generator) -> tuple[float, float, float]:
    names = list(_PALETTE_WEIGHTS)
    p = np.array([_PALETTE_WEIGHTS[k] for k in names])
    pal = _PALETTES[names[rng.choice(len(names), p=p / p.sum())]]
    base = np.array(pal[rng.integers(len(pal))])
    return tuple(float(c) for c in np.clip(base + rng.uniform(-0.03, 0.03, 3), 0.0, 1.0))


# --------------------------------------------------------------------------------------------------
# Layouts: a tree of row/column splits whose leaves are drawers, doors or open shelves


@dataclass
class Leaf:
    """A compartment: ``drawer``, ``door`` (hinge ``left``/``right``), ``double_door`` or ``open``."""

    kind: str
    hinge: str = ""


@dataclass
class Split:
    """Rows (top to bottom) or columns (left to right as seen from the front) with size weights."""

    axis: str  # "rows" | "cols"
    children: list[tuple[float, "Leaf | Split"]]


@dataclass
class Layout:
    """A sampled layout: its name, size (m), tree and whether it is meant to be describable."""

    name: str
    width: float
    height: float
    depth: float
    tree: Leaf | Split
    describable: bool


def _rows(*children: tuple[float, Leaf | Split]) -> Split:
    return Split("rows", list(children))


def _cols(*children: tuple[float, Leaf | Split]) -> Split:
    return Split("cols", list(children))


def _drawer_stack(rng: np.random.Generator, n: int) -> Split:
    """A column of n drawers, optionally graduated (deeper drawers at the bottom)."""
    if n == 1:
        return _rows((1.0, Leaf("drawer")))
    grad = rng.random() < 0.4
    weights = [1.0 + (0.15 * i if grad else 0.0) for i in range(n)]
    return _rows(*[(w, Leaf("drawer")) for w in weights])


def _size_for_rows(rng: np.random.Generator, cfg: GeneratorConfig, n_rows: int, row_h: tuple[float, float],
                   extra: float) -> float:
    """Cabinet height for ``n_rows`` rows of height in ``row_h`` plus ``extra`` (panels, plinth)."""
    lo = max(cfg.height_range[0], n_rows * row_h[0] + extra)
    hi = min(cfg.height_range[1], n_rows * row_h[1] + extra)
    return float(rng.uniform(lo, max(lo, hi)))


def _sample_layout(rng: np.random.Generator, cfg: GeneratorConfig, t: float, plinth: float) -> Layout:
    """Pick a layout family, then its size and tree."""
    d = float(rng.uniform(*cfg.depth_range))
    frame = 2 * t + plinth

    def rows_h(n_rows: int, row_h: tuple[float, float]) -> float:
        return _size_for_rows(rng, cfg, n_rows, row_h, frame + (n_rows - 1) * t)

    u = rng.uniform

    def single_drawer():
        w = u(0.35, 0.8)
        if rng.random() < 0.5:  # nightstand: drawer over an open shelf
            h = rows_h(2, (0.14, 0.3))
            return Layout("drawer_over_shelf", w, h, d, _rows((1.0, Leaf("drawer")), (1.6, Leaf("open"))), True)
        return Layout("single_drawer", w, rows_h(1, (0.2, 0.35)), d, _rows((1.0, Leaf("drawer"))), True)

    def drawer_stack():
        n = int(rng.choice([2, 3, 4, 5], p=[0.55, 0.3, 0.1, 0.05]))
        return Layout(f"drawer_stack_{n}", u(0.35, 1.0), rows_h(n, (0.1, 0.3)), d, _drawer_stack(rng, n), True)

    def drawer_grid():
        cols, rows = [(2, 1), (2, 2), (3, 1), (2, 3)][rng.choice(4, p=[0.5, 0.25, 0.15, 0.1])]
        w = u(max(0.6, cols * 0.3), 1.2)
        tree = _cols(*[(1.0, _drawer_stack(rng, rows) if rows > 1 else Leaf("drawer")) for _ in range(cols)])
        if rows > 1:  # identical rows in every column (same handle levels)
            tree = _cols(*[(1.0, tree.children[0][1]) for _ in range(cols)])
        return Layout(f"drawer_grid_{cols}x{rows}", w, rows_h(rows, (0.12, 0.25)), d, tree, True)

    def single_door():
        hinge = "left" if rng.random() < 0.5 else "right"
        h = u(0.4, 1.8)
        tree: Leaf | Split = Leaf("door", hinge)
        return Layout("single_door", u(0.3, 0.6), h, d, tree, True)

    def double_door():
        return Layout("double_door", u(0.6, 1.2), u(0.4, 1.8), d, Leaf("double_door"), True)

    def drawers_over_doors():
        w = u(0.45, 1.2)
        double = w > 0.65
        n_top = 2 if (double and w > 0.8 and rng.random() < 0.4) else 1
        top = _cols(*[(1.0, Leaf("drawer")) for _ in range(n_top)]) if n_top > 1 else Leaf("drawer")
        bottom = Leaf("double_door") if double else Leaf("door", "left" if rng.random() < 0.5 else "right")
        h = u(0.65, 1.2)
        ratio = u(0.22, 0.35)
        name = f"drawer{'s' if n_top > 1 else ''}_over_{'double_door' if double else 'door'}"
        return Layout(name, w, h, d, _rows((ratio, top), (1 - ratio, bottom)), True)

    def door_beside_drawers():
        w = u(0.7, 1.2)
        n = int(rng.choice([2, 3, 4], p=[0.5, 0.35, 0.15]))
        h = rows_h(n, (0.12, 0.25))
        stack = _drawer_stack(rng, n)
        if rng.random() < 0.5:
            tree = _cols((1.0, Leaf("door", "left")), (u(0.7, 1.0), stack))
        else:
            tree = _cols((u(0.7, 1.0), stack), (1.0, Leaf("door", "right")))
        return Layout(f"door_beside_{n}_drawers", w, h, d, tree, True)

    def wardrobe():
        w = u(0.7, 1.2)
        h = u(1.3, 1.8)
        n = int(rng.choice([1, 2]))
        bottom = _drawer_stack(rng, n) if n > 1 else Leaf("drawer")
        tree = _rows((u(0.7, 0.8), Leaf("double_door")), (0.1 * n + u(0.0, 0.05), bottom))
        return Layout(f"wardrobe_{n}_drawers", w, h, d, tree, True)

    def double_door_rows():
        w = u(0.6, 1.1)
        h = u(1.2, 1.8)
        return Layout("double_door_rows", w, h, d, _rows((u(0.8, 1.2), Leaf("double_door")), (1.0, Leaf("double_door"))), True)

    def stacked_doors():
        hinge = "left" if rng.random() < 0.5 else "right"
        return Layout("stacked_doors", u(0.35, 0.6), u(1.0, 1.8), d,
                      _rows((u(0.6, 1.0), Leaf("door", hinge)), (1.0, Leaf("door", hinge))), True)

    # ---- layouts that the language rule cannot describe
    def tall_drawer_stack():
        n = int(rng.integers(6, 9))
        return Layout(f"tall_drawer_stack_{n}", u(0.3, 0.8), rows_h(n, (0.08, 0.18)), d, _drawer_stack(rng, n), False)

    def drawer_row():
        n = int(rng.integers(6, 9))
        w = u(max(0.8, n * 0.13 + 0.1), 1.2)
        return Layout(f"drawer_row_{n}", w, rows_h(1, (0.12, 0.25)), d,
                      _cols(*[(1.0, Leaf("drawer")) for _ in range(n)]), False)

    def stack_beside_door():
        n = int(rng.integers(6, 8))
        w = u(0.7, 1.2)
        h = rows_h(n, (0.08, 0.16))
        stack = _drawer_stack(rng, n)
        if rng.random() < 0.5:
            tree = _cols((1.0, Leaf("door", "left")), (u(0.7, 1.0), stack))
        else:
            tree = _cols((u(0.7, 1.0), stack), (1.0, Leaf("door", "right")))
        return Layout(f"door_beside_{n}_drawers", w, h, d, tree, False)

    valid: list[tuple[float, Callable[[], Layout]]] = [
        (0.16, single_drawer), (0.14, drawer_stack), (0.04, drawer_grid), (0.22, single_door),
        (0.19, double_door), (0.08, drawers_over_doors), (0.04, door_beside_drawers), (0.04, wardrobe),
        (0.04, double_door_rows), (0.05, stacked_doors),
    ]
    invalid: list[tuple[float, Callable[[], Layout]]] = [
        (0.6, tall_drawer_stack), (0.2, drawer_row), (0.2, stack_beside_door),
    ]
    family = invalid if rng.random() < cfg.invalid_fraction else valid
    p = np.array([wt for wt, _ in family])
    layout = family[rng.choice(len(family), p=p / p.sum())][1]()
    layout.width = float(np.clip(layout.width, *cfg.width_range))
    layout.height = float(np.clip(layout.height, *cfg.height_range))
    return layout


# --------------------------------------------------------------------------------------------------
# The cabinet model


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


@dataclass
class HandleStyle:
    """Per-cabinet handle choice for one target type."""

    kind: str
    orientation: str  # "horizontal" | "vertical" (knobs: "none")
    diameter: float
    clearance: float
    square: bool
    arch_style: str
    length_frac: float
    long: bool = False


def _handle_style(rng: np.random.Generator, cfg: GeneratorConfig, target: str,
                  kind: str | None = None) -> HandleStyle:
    if kind is None:
        p = cfg.drawer_handle_kinds if target == "drawer" else cfg.door_handle_kinds
        kind = HANDLE_KINDS[rng.choice(3, p=list(p))]
    if kind == "knob":
        orient = "none"
    elif target == "drawer":
        orient = "vertical" if rng.random() < 0.12 else "horizontal"
    else:
        orient = "horizontal" if rng.random() < cfg.door_horizontal_share else "vertical"
    return HandleStyle(
        kind=kind,
        orientation=orient,
        diameter=float(rng.uniform(*cfg.bar_diameter_range)),
        clearance=float(rng.uniform(*cfg.bar_gap_range)),
        square=bool(rng.random() < 0.25),
        arch_style="u" if rng.random() < 0.5 else "trapezoid",
        length_frac=float(rng.uniform(0.0, 1.0)),
        long=bool(rng.random() < cfg.long_bar_share),
    )


def _bar_pieces(c: np.ndarray, u: np.ndarray, z0: float, length: float, st: HandleStyle,
                rng: np.random.Generator) -> list[Piece]:
    """Straight bar of ``length`` along ``u`` centred at ``c`` on two posts from the panel at z0."""
    r = st.diameter / 2
    zc = z0 + st.clearance + r
    inset = min(float(rng.uniform(0.0, 0.02)), max(0.0, (length - 0.064) / 2))
    post_off = length / 2 - inset - r
    pieces: list[Piece] = []
    a = c + u * (-length / 2)
    b = c + u * (length / 2)
    a[2] = b[2] = zc
    if st.square:
        lo, hi = np.minimum(a, b) - r, np.maximum(a, b) + r
        pieces.append(Box(tuple(lo), tuple(hi)))
    else:
        pieces.append(Cylinder(tuple(a), tuple(b), r))
    pr = r * 0.85
    for s in (-1.0, 1.0):
        p = c + u * (s * post_off)
        p0 = np.array([p[0], p[1], z0])
        p1 = np.array([p[0], p[1], zc])
        if st.square:
            pieces.append(Box((p0[0] - pr, p0[1] - pr, z0), (p0[0] + pr, p0[1] + pr, zc - r)))
        else:
            pieces.append(Cylinder(tuple(p0), tuple(p1 - np.array([0, 0, r * 0.5])), pr))
    return pieces


def _arched_pieces(c: np.ndarray, u: np.ndarray, z0: float, length: float, st: HandleStyle) -> list[Piece]:
    """A bar made of several round segments that arches out from the panel (U or trapezoid)."""
    r = st.diameter / 2
    h = st.clearance + r  # centreline height of the grip above the panel
    a = length / 2 - r
    if st.arch_style == "u":
        rc = 0.6 * h
        ccx, ccy = -a + rc, h - rc  # centre of the left rounded corner
        pts2 = [(-a, 0.0)] + [(ccx + rc * math.cos(phi), ccy + rc * math.sin(phi))
                              for phi in (math.pi, 5 * math.pi / 6, 2 * math.pi / 3, math.pi / 2)]
        right = [(-x, y) for x, y in reversed(pts2)]
        pts2 = pts2 + right
    else:
        delta = 0.6 * h
        pts2 = [(-a, 0.0), (-a + delta, h), (a - delta, h), (a, 0.0)]
    pts = [c + u * x + np.array([0.0, 0.0, z0 + y - c[2]]) for x, y in pts2]
    pieces: list[Piece] = []
    n = len(pts)
    for i in range(n - 1):
        p0, p1 = pts[i].copy(), pts[i + 1].copy()
        d = p1 - p0
        length_i = float(np.linalg.norm(d))
        if length_i < 1e-6:
            continue
        d /= length_i
        # extend into the neighbouring segments so that joints have no gaps
        ext0 = r * 0.6 if i > 0 else 0.0
        ext1 = r * 0.6 if i < n - 2 else 0.0
        pieces.append(Cylinder(tuple(p0 - d * ext0), tuple(p1 + d * ext1), r))
    return pieces


def _knob_pieces(c: np.ndarray, z0: float, rng: np.random.Generator, cfg: GeneratorConfig) -> list[Piece]:
    """Knob: stem and cap (optionally a thin rim plate against the panel)."""
    stem_r = float(rng.uniform(0.005, 0.007))
    stem_l = float(rng.uniform(0.018, 0.028))
    cap_r = float(rng.uniform(*cfg.knob_cap_radius_range))
    cap_t = float(rng.uniform(0.010, 0.016))
    x, y = float(c[0]), float(c[1])
    pieces: list[Piece] = [
        Cylinder((x, y, z0), (x, y, z0 + stem_l + 0.002), stem_r),
        Cylinder((x, y, z0 + stem_l), (x, y, z0 + stem_l + cap_t), cap_r),
    ]
    if rng.random() < 0.4:
        pieces.append(Cylinder((x, y, z0), (x, y, z0 + 0.003), stem_r * 1.8))
    return pieces


def _make_handle(rng: np.random.Generator, cfg: GeneratorConfig, st: HandleStyle, panel_lo: np.ndarray,
                 panel_hi: np.ndarray, center: np.ndarray) -> tuple[list[Piece], str, str]:
    """Handle pieces on the front face of a panel (box lo/hi) centred at ``center`` (x, y)."""
    z0 = float(panel_hi[2])
    pw, ph = float(panel_hi[0] - panel_lo[0]), float(panel_hi[1] - panel_lo[1])
    kind, orient = st.kind, st.orientation
    margin = 0.025
    if kind != "knob":
        room = (pw if orient == "horizontal" else ph) - 2 * margin
        if kind == "arched" and room < 0.10:
            kind = "bar"
        if room < 0.08:
            kind, orient = "knob", "none"
    c = np.array([center[0], center[1], z0])
    if kind == "knob":
        return _knob_pieces(c, z0, rng, cfg), "knob", "none"
    along = pw if orient == "horizontal" else ph
    if kind == "bar" and st.long:
        max_len = min(cfg.long_bar_max, room, 0.9 * along)
    else:
        max_len = min(0.30, room, 0.7 * along)
    min_len = 0.10 if kind == "arched" else cfg.short_bar_min
    max_len = max(min_len, max_len)
    length = min_len + st.length_frac * (max_len - min_len)
    u = np.array([1.0, 0.0, 0.0]) if orient == "horizontal" else np.array([0.0, 1.0, 0.0])
    # keep the handle inside the panel
    lo_c = panel_lo[:2] + margin + (u[:2] * length / 2)
    hi_c = panel_hi[:2] - margin - (u[:2] * length / 2)
    c[:2] = np.clip(c[:2], lo_c, np.maximum(lo_c, hi_c))
    if kind == "bar":
        return _bar_pieces(c, u, z0, length, st, rng), kind, orient
    return _arched_pieces(c, u, z0, length, st), kind, orient


def _build(rng: np.random.Generator, cfg: GeneratorConfig, layout: Layout, t: float, plinth: float,
           colours: dict, floor_fronts: bool = False) -> tuple[list[Visual], list[Target]]:
    """Carcass visuals and movable targets of a layout (metres, mesh frame).

    ``floor_fronts``: the bottom row's doors and drawer fronts reach down to the floor (the bottom panel
    stands back behind them), as on many real cabinets without a plinth."""
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

    drawer_style = _handle_style(rng, cfg, "drawer")
    if rng.random() < 0.7:  # usually one handle kind for the whole cabinet
        door_style = _handle_style(rng, cfg, "door", drawer_style.kind)
        door_style.diameter, door_style.clearance, door_style.square = (
            drawer_style.diameter, drawer_style.clearance, drawer_style.square)
        door_style.arch_style = drawer_style.arch_style
    else:
        door_style = _handle_style(rng, cfg, "door")
    t_front = float(rng.uniform(0.016, 0.02))
    t_box = float(rng.uniform(0.010, 0.014))
    door_upper = float(rng.uniform(1.57, 2.0))
    door_handle_margin = float(rng.uniform(*cfg.door_handle_margin_range))
    door_handle_dy = float(rng.uniform(-0.25, 0.25))
    door_bar_top = bool(rng.random() < cfg.door_bar_top_share)
    door_bar_centred = bool(rng.random() < cfg.door_bar_centred_share)
    door_bar_edge = float(rng.uniform(*cfg.door_bar_edge_range))
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
                    part, kind, orient = _make_handle(rng, cfg, drawer_style, hlo, hhi, (hlo + hhi) / 2)
                    pieces += part
            else:
                pieces, kind, orient = _make_handle(rng, cfg, drawer_style, lo, hi, centre)
            origin = (float(centre[0]), float(centre[1]), zf)
            tg = Target("drawer", "prismatic", (0.0, 0.0, 1.0), origin, float(rng.uniform(0.7, 0.9)) * depth,
                        [Visual("drawer_front", [Box(tuple(lo), tuple(hi))], front),
                         Visual("drawer_box", box, inner),
                         Visual("handle", pieces, handle_mat)],
                        handle_kind=kind, handle_orientation=orient)
            targets.append(tg)
            continue
        # doors (with an inner shelf behind tall ones)
        if cy1 - cy0 > 0.45 and rng.random() < 0.6:
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
            pieces, kind, orient = _make_handle(rng, cfg, st, lo, hi, np.array([hx, hy, 0.0]))
            if orient == "horizontal" and not door_bar_centred:  # its real length, from near the free edge
                bl, bh = _bounds_of(pieces)
                shift = (free_x + inward * 0.025) - (bh[0] if hinge == "left" else bl[0])
                pieces = [_translate(p, (shift, 0.0, 0.0)) for p in pieces]
            hinge_x = lx0 if hinge == "left" else lx1
            axis = (0.0, -1.0, 0.0) if hinge == "left" else (0.0, 1.0, 0.0)
            origin = (hinge_x, float((lo[1] + hi[1]) / 2), zf)
            targets.append(Target("door", "revolute", axis, origin, door_upper,
                                  [Visual("cabinet_door_surface", [Box(tuple(lo), tuple(hi))], front),
                                   Visual("handle", pieces, handle_mat)],
                                  hinge=hinge, double=leaf.kind == "double_door",
                                  handle_kind=kind, handle_orientation=orient))
    for tg in targets:
        hl, hh = _bounds_of(tg.visuals[-1].pieces)
        tg.handle_center = tuple(float(v) for v in (hl + hh) / 2)
    return carcass, targets


def _translate(p: Piece, d: tuple[float, float, float]) -> Piece:
    dv = np.asarray(d)
    if isinstance(p, Box):
        return Box(tuple(np.asarray(p.lo) + dv), tuple(np.asarray(p.hi) + dv))
    return Cylinder(tuple(np.asarray(p.p0) + dv), tuple(np.asarray(p.p1) + dv), p.radius)


def _unshare_vertices(visuals: list[Visual]) -> list[Visual]:
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


def _bounds_of(pieces: list[Piece]) -> tuple[np.ndarray, np.ndarray]:
    bs = [piece_bounds(p) for p in pieces]
    return np.min([b[0] for b in bs], axis=0), np.max([b[1] for b in bs], axis=0)


# --------------------------------------------------------------------------------------------------
# Language rule (OpenD Algorithm 1, as the compiler applies it)


def describable(targets: list[tuple[str, float, float]], tol: float = 0.04, max_levels: int = 5) -> bool:
    """Whether targets ``(type, height_m, horizontal_m)`` can all be named apart by Algorithm 1
    (`opend_mj.language.describe`, the rule the compiler applies), with level tolerance ``tol`` and at
    most ``max_levels`` levels and positions per level."""
    if not targets:
        return True
    labels = {n: v for n, v in LanguageConfig().vertical_labels.items() if n <= max_levels}
    config = LanguageConfig(level_tolerance=tol, vertical_labels=labels,
                            horizontal_labels={n: v for n, v in LanguageConfig().horizontal_labels.items()
                                               if n <= max_levels})
    layout = [TargetLayout(key=str(i), kind=kind, y=horizontal, z=height)
              for i, (kind, height, horizontal) in enumerate(targets)]
    try:
        describe(layout, config)
    except LanguageInvalid:
        return False
    return True


# --------------------------------------------------------------------------------------------------
# Writing


def _fmt(v: float, decimals: int) -> str:
    s = f"{v:.{decimals}f}"
    return "0" + s[2:] if s.startswith("-0") and float(s) == 0.0 else s


def _obj_text(pieces: list[Piece], mtl_name: str, material: str, scale: float, cfg: GeneratorConfig) -> str:
    lines = [f"mtllib {mtl_name}", f"usemtl {material}"]
    faces_out: list[str] = []
    base = 1
    nd = cfg.decimals
    for p in pieces:
        verts, faces = piece_mesh(p, cfg.cylinder_sides)
        verts = verts / scale
        lines.extend(f"v {_fmt(x, nd)} {_fmt(y, nd)} {_fmt(z, nd)}" for x, y, z in verts)
        faces_out.extend(f"f {a + base} {b + base} {c + base}" for a, b, c in faces)
        base += len(verts)
    return "\n".join(lines + faces_out) + "\n"


def _mtl_text(m: Material) -> str:
    r, g, b = m.kd
    return (f"newmtl {m.name}\nKa 0.1 0.1 0.1\nKd {r:.4f} {g:.4f} {b:.4f}\n"
            f"Ks {m.ks:.4f} {m.ks:.4f} {m.ks:.4f}\nNs {m.ns:.1f}\nd 1\nillum 2\n")


def _vec(v, decimals: int) -> str:
    return " ".join(_fmt(float(x), decimals) for x in v)


BASES = ("floor_fronts", "inset", "low_plinth", "plinth")


def _draw_base(rng: np.random.Generator, cfg: GeneratorConfig) -> tuple[str, float]:
    """How the cabinet meets the floor (one of ``BASES``) and its plinth height (m)."""
    base = BASES[int(rng.choice(len(BASES), p=list(cfg.base_shares)))]
    if base == "low_plinth":
        return base, float(rng.uniform(*cfg.low_plinth_range))
    if base == "plinth":
        return base, float(rng.uniform(*cfg.plinth_range))
    return base, 0.0


def generate_source(index: int, seed: int, out_root: Path, config: GeneratorConfig = GeneratorConfig()) -> Path:
    """Write cabinet ``proc_<index>`` (PartNet-Mobility format) under ``out_root`` and return its folder."""
    cfg = config
    rng = np.random.default_rng([seed, index])
    cabinet_id = f"proc_{index:04d}"
    folder = Path(out_root) / cabinet_id
    objs = folder / "textured_objs"
    objs.mkdir(parents=True, exist_ok=True)

    t = float(rng.uniform(*cfg.thickness_range))
    if rng.random() < 0.35:  # version 3 drew its plinth here: the draws stay, so that the layout's draws
        rng.uniform(0.05, 0.1)  # start where they did; the base has a random stream of its own
    base, plinth = _draw_base(np.random.default_rng([seed, index, 4]), cfg)
    layout = _sample_layout(rng, cfg, t, plinth)
    body = _pick_colour(rng)
    front = body if rng.random() < 0.7 else _pick_colour(rng)
    interior = body if rng.random() < 0.5 else tuple(
        float(c) for c in np.clip(np.array(_PALETTES["wood"][3]) + rng.uniform(-0.05, 0.05, 3), 0, 1))
    if rng.random() < 0.15:
        handle = (front, 0.1, 40.0)
        finish = "body"
    else:
        finish = list(_HANDLE_FINISHES)[rng.integers(len(_HANDLE_FINISHES))]
        handle = _HANDLE_FINISHES[finish]
    colours = {"body": body, "front": front, "interior": interior, "handle": handle}
    carcass, targets = _build(rng, cfg, layout, t, plinth, colours, floor_fronts=base == "floor_fronts")

    s, nd = cfg.scale, cfg.decimals
    n = len(targets)
    body_link = f"link_{n}"
    part_id = 0
    obj_id = 0
    files: dict[str, str] = {}

    def emit(visuals: list[Visual], offset: tuple[float, float, float]) -> list[str]:
        nonlocal part_id, obj_id
        vis_xml, col_xml = [], []
        origin = _vec(offset, nd)
        for v in visuals:
            part_id += 1
            name = f"original-{obj_id}"
            obj_id += 1
            files[f"textured_objs/{name}.obj"] = _obj_text(v.pieces, f"{name}.mtl", v.material.name, s, cfg)
            files[f"textured_objs/{name}.mtl"] = _mtl_text(v.material)
            geom = (f'\t\t\t<origin xyz="{origin}"/>\n\t\t\t<geometry>\n'
                    f'\t\t\t\t<mesh filename="textured_objs/{name}.obj"/>\n\t\t\t</geometry>\n')
            vis_xml.append(f'\t\t<visual name="{v.part}-{part_id}">\n{geom}\t\t</visual>\n')
            col_xml.append(f"\t\t<collision>\n{geom}\t\t</collision>\n")
        return vis_xml + col_xml

    xml = ['<?xml version="1.0" ?>\n', f'<robot name="{cabinet_id}">\n', '\t<link name="base"/>\n']
    sem = []
    for i, tg in enumerate(targets):
        p = np.asarray(tg.origin) / s
        xml.append(f'\t<link name="link_{i}">\n')
        xml.extend(emit(_unshare_vertices(tg.visuals), tuple(-p)))
        xml.append("\t</link>\n")
        upper = tg.upper / s if tg.joint_type == "prismatic" else tg.upper
        xml.append(
            f'\t<joint name="joint_{i}" type="{tg.joint_type}">\n'
            f'\t\t<origin xyz="{_vec(p, nd)}"/>\n\t\t<axis xyz="{_vec(tg.axis, 1).replace(".0", "")}"/>\n'
            f'\t\t<child link="link_{i}"/>\n\t\t<parent link="{body_link}"/>\n'
            f'\t\t<limit lower="0.0" upper="{_fmt(upper, nd)}"/>\n\t</joint>\n')
        sem.append(f"link_{i} {'slider drawer' if tg.kind == 'drawer' else 'hinge rotation_door'}")
    xml.append(f'\t<link name="{body_link}">\n')
    xml.extend(emit(_unshare_vertices(carcass), (0.0, 0.0, 0.0)))
    xml.append("\t</link>\n")
    xml.append(f'\t<joint name="joint_{n}" type="fixed">\n'
               '\t\t<origin rpy="1.570796326794897 0 -1.570796326794897" xyz="0 0 0"/>\n'
               f'\t\t<child link="{body_link}"/>\n\t\t<parent link="base"/>\n\t</joint>\n</robot>\n')
    sem.append(f"{body_link} heavy furniture_body")
    files["mobility.urdf"] = "".join(xml).replace('xyz="0.000000 0.000000 0.000000"', 'xyz="0 0 0"')
    files["semantics.txt"] = "\n".join(sem) + "\n"

    floor = -layout.height / 2
    lang = [(tg.kind, tg.handle_center[1] - floor, tg.handle_center[0]) for tg in targets]
    ok = describable(lang, cfg.level_tolerance, cfg.max_levels)
    meta = {
        "model_id": cabinet_id,
        "anno_id": cabinet_id,
        "model_cat": "StorageFurniture",
        "version": GENERATOR_VERSION,
        "procedural": {
            "generator_version": GENERATOR_VERSION,
            "seed": int(seed),
            "index": int(index),
            "size_m": {k: round(v, 4) for k, v in
                       (("width", layout.width), ("height", layout.height), ("depth", layout.depth))},
            "panel_thickness_m": round(t, 4),
            "plinth_m": round(plinth, 4),
            "base": base,
            "layout": layout.name,
            "describable": bool(ok),
            "describable_intended": bool(layout.describable),
            "handle_kinds": sorted({tg.handle_kind for tg in targets}),
            "handle_finish": finish,
            "targets": [
                {
                    "link": f"link_{i}",
                    "joint": f"joint_{i}",
                    "type": tg.kind,
                    "hinge": tg.hinge or None,
                    "double_door": tg.double,
                    "handle_kind": tg.handle_kind,
                    "handle_orientation": tg.handle_orientation,
                    "handle_center_m": [round(v, 4) for v in tg.handle_center],
                }
                for i, tg in enumerate(targets)
            ],
        },
    }
    files["meta.json"] = json.dumps(meta)
    for rel, text in files.items():
        (folder / rel).write_text(text)
    return folder


def generate_sources(count: int, seed: int, out_root: Path, config: GeneratorConfig = GeneratorConfig(),
                     progress: bool = True) -> list[Path]:
    """Write cabinets ``proc_0000`` ... ``proc_<count-1>`` under ``out_root``."""
    out_root = Path(out_root)
    out_root.mkdir(parents=True, exist_ok=True)
    return [generate_source(i, seed, out_root, config)
            for i in tqdm(range(count), desc="generate", unit="cabinet", disable=not progress)]


__all__ = [
    "GENERATOR_VERSION", "HANDLE_KINDS", "PARTNET_SCALE", "Box", "Cylinder", "GeneratorConfig",
    "describable", "generate_source", "generate_sources", "piece_bounds", "piece_mesh",
]
