"""Sampling a cabinet layout: a tree of row/column splits whose leaves are drawers, doors or open
shelves, one of a few families (describable by the language rule or deliberately not)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from opend_mj.assets.procedural.config import GeneratorConfig


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
    #: its low doors may be drawn as flaps (`GeneratorConfig.flap_share`); False: side-hinged always
    flaps: bool = True


def _rows(*children: tuple[float, Leaf | Split]) -> Split:
    return Split("rows", list(children))


def _cols(*children: tuple[float, Leaf | Split]) -> Split:
    return Split("cols", list(children))


def _drawer_stack(rng: np.random.Generator, cfg: GeneratorConfig, n: int) -> Split:
    """A column of n drawers, optionally graduated (deeper drawers at the bottom)."""
    if n == 1:
        return _rows((1.0, Leaf("drawer")))
    grad = rng.random() < cfg.graduated_stack_share
    weights = [1.0 + (0.15 * i if grad else 0.0) for i in range(n)]
    return _rows(*[(w, Leaf("drawer")) for w in weights])


def _size_for_rows(rng: np.random.Generator, cfg: GeneratorConfig, n_rows: int, row_h: tuple[float, float],
                   extra: float) -> float:
    """Cabinet height for ``n_rows`` rows of height in ``row_h`` plus ``extra`` (panels, plinth)."""
    lo = max(cfg.height_range[0], n_rows * row_h[0] + extra)
    hi = min(cfg.height_range[1], n_rows * row_h[1] + extra)
    return float(rng.uniform(lo, max(lo, hi)))


@dataclass
class _Draw:
    """What every family's sampler shares: the generator, its configuration, the cabinet's depth (m),
    panel thickness ``t`` (m) and ``frame`` (m of height taken by the top and bottom panels and the
    plinth)."""

    rng: np.random.Generator
    cfg: GeneratorConfig
    depth: float
    t: float
    frame: float

    def u(self, low: float, high: float) -> float:
        return self.rng.uniform(low, high)

    def rows_h(self, n_rows: int, row_h: tuple[float, float]) -> float:
        """Cabinet height (m) for ``n_rows`` rows of height in ``row_h`` and the panels between them."""
        return _size_for_rows(self.rng, self.cfg, n_rows, row_h, self.frame + (n_rows - 1) * self.t)


def _door_beside(s: _Draw, stack: Split) -> Split:
    """A side-hinged door beside ``stack``, hinged at the cabinet's outer edge: on the left with
    ``left_hinge_share``, else on the right."""
    if s.rng.random() < s.cfg.left_hinge_share:
        return _cols((1.0, Leaf("door", "left")), (s.u(0.7, 1.0), stack))
    return _cols((s.u(0.7, 1.0), stack), (1.0, Leaf("door", "right")))


def _single_drawer(s: _Draw) -> Layout:
    w = s.u(0.35, 0.8)
    if s.rng.random() < s.cfg.nightstand_share:  # nightstand: drawer over an open shelf
        h = s.rows_h(2, (0.14, 0.3))
        return Layout("drawer_over_shelf", w, h, s.depth, _rows((1.0, Leaf("drawer")), (1.6, Leaf("open"))), True)
    return Layout("single_drawer", w, s.rows_h(1, (0.2, 0.35)), s.depth, _rows((1.0, Leaf("drawer"))), True)


def _drawer_stack_family(s: _Draw) -> Layout:
    n = int(s.rng.choice([k for k, _ in s.cfg.drawer_stack_sizes], p=[w for _, w in s.cfg.drawer_stack_sizes]))
    return Layout(f"drawer_stack_{n}", s.u(0.35, 1.0), s.rows_h(n, (0.1, 0.3)), s.depth, _drawer_stack(s.rng, s.cfg, n), True)


def _drawer_grid(s: _Draw) -> Layout:
    shapes = s.cfg.drawer_grid_shapes
    cols, rows = shapes[s.rng.choice(len(shapes), p=[w for _, w in shapes])][0]
    w = s.u(max(0.6, cols * 0.3), 1.2)
    tree = _cols(*[(1.0, _drawer_stack(s.rng, s.cfg, rows) if rows > 1 else Leaf("drawer")) for _ in range(cols)])
    if rows > 1:  # identical rows in every column (same handle levels)
        tree = _cols(*[(1.0, tree.children[0][1]) for _ in range(cols)])
    return Layout(f"drawer_grid_{cols}x{rows}", w, s.rows_h(rows, (0.12, 0.25)), s.depth, tree, True)


def _single_door(s: _Draw) -> Layout:
    hinge = "left" if s.rng.random() < s.cfg.left_hinge_share else "right"
    h = s.u(0.4, 1.8)
    tree: Leaf | Split = Leaf("door", hinge)
    return Layout("single_door", s.u(0.3, 0.6), h, s.depth, tree, True)


def _double_door(s: _Draw) -> Layout:
    return Layout("double_door", s.u(0.6, 1.2), s.u(0.4, 1.8), s.depth, Leaf("double_door"), True)


def _long_door(s: _Draw) -> Layout:
    """A wide, low cabinet with one side-hinged door across its whole width (never a flap), under an
    open shelf half of the time: the TV and sideboard cabinets of the real OpenD training set (18 of
    their 126 side-hinged doors are 0.95-1.25 m wide and 0.35-0.67 m tall, the only door of their
    cabinet; no real flap is that wide).
    Not among the default families (`GeneratorConfig.valid_layouts`): `opend generate --family`."""
    hinge = "left" if s.rng.random() < s.cfg.left_hinge_share else "right"
    w = s.u(0.95, 1.2)
    if s.rng.random() < 0.5:
        return Layout("long_door_under_shelf", w, s.u(0.6, 0.9), s.depth,
                      _rows((s.u(0.4, 0.8), Leaf("open")), (1.0, Leaf("door", hinge))), True, flaps=False)
    return Layout("long_door", w, s.u(0.4, 0.7), s.depth, Leaf("door", hinge), True, flaps=False)


def _drawers_over_doors(s: _Draw) -> Layout:
    w = s.u(0.45, 1.2)
    double = w > 0.65
    n_top = 2 if (double and w > 0.8 and s.rng.random() < s.cfg.paired_top_drawers_share) else 1
    top = _cols(*[(1.0, Leaf("drawer")) for _ in range(n_top)]) if n_top > 1 else Leaf("drawer")
    bottom = Leaf("double_door") if double else Leaf("door", "left" if s.rng.random() < s.cfg.left_hinge_share
                                                       else "right")
    h = s.u(0.65, 1.2)
    ratio = s.u(0.22, 0.35)
    name = f"drawer{'s' if n_top > 1 else ''}_over_{'double_door' if double else 'door'}"
    return Layout(name, w, h, s.depth, _rows((ratio, top), (1 - ratio, bottom)), True)


def _door_beside_drawers(s: _Draw) -> Layout:
    w = s.u(0.7, 1.2)
    sizes = s.cfg.door_beside_stack_sizes
    n = int(s.rng.choice([k for k, _ in sizes], p=[w for _, w in sizes]))
    h = s.rows_h(n, (0.12, 0.25))
    stack = _drawer_stack(s.rng, s.cfg, n)
    tree = _door_beside(s, stack)
    return Layout(f"door_beside_{n}_drawers", w, h, s.depth, tree, True)


def _wardrobe(s: _Draw) -> Layout:
    w = s.u(0.7, 1.2)
    h = s.u(1.3, 1.8)
    n = int(s.rng.choice([1, 2]))
    bottom = _drawer_stack(s.rng, s.cfg, n) if n > 1 else Leaf("drawer")
    tree = _rows((s.u(0.7, 0.8), Leaf("double_door")), (0.1 * n + s.u(0.0, 0.05), bottom))
    return Layout(f"wardrobe_{n}_drawers", w, h, s.depth, tree, True)


def _double_door_rows(s: _Draw) -> Layout:
    w = s.u(0.6, 1.1)
    h = s.u(1.2, 1.8)
    return Layout("double_door_rows", w, h, s.depth, _rows((s.u(0.8, 1.2), Leaf("double_door")), (1.0, Leaf("double_door"))), True)


def _stacked_doors(s: _Draw) -> Layout:
    hinge = "left" if s.rng.random() < s.cfg.left_hinge_share else "right"
    return Layout("stacked_doors", s.u(0.35, 0.6), s.u(1.0, 1.8), s.depth,
                  _rows((s.u(0.6, 1.0), Leaf("door", hinge)), (1.0, Leaf("door", hinge))), True)


# ---- layouts that the language rule cannot describe

def _tall_drawer_stack(s: _Draw) -> Layout:
    n = int(s.rng.integers(6, 9))
    return Layout(f"tall_drawer_stack_{n}", s.u(0.3, 0.8), s.rows_h(n, (0.08, 0.18)), s.depth, _drawer_stack(s.rng, s.cfg, n), False)


def _drawer_row(s: _Draw) -> Layout:
    n = int(s.rng.integers(6, 9))
    w = s.u(max(0.8, n * 0.13 + 0.1), 1.2)
    return Layout(f"drawer_row_{n}", w, s.rows_h(1, (0.12, 0.25)), s.depth,
                  _cols(*[(1.0, Leaf("drawer")) for _ in range(n)]), False)


def _stack_beside_door(s: _Draw) -> Layout:
    n = int(s.rng.integers(6, 8))
    w = s.u(0.7, 1.2)
    h = s.rows_h(n, (0.08, 0.16))
    stack = _drawer_stack(s.rng, s.cfg, n)
    tree = _door_beside(s, stack)
    return Layout(f"door_beside_{n}_drawers", w, h, s.depth, tree, False)


#: Every layout family by name: `GeneratorConfig.valid_layouts` / ``invalid_layouts`` and `opend
#: generate --family` pick from these.
FAMILIES: dict[str, Callable[[_Draw], Layout]] = {
    "single_drawer": _single_drawer, "drawer_stack": _drawer_stack_family, "drawer_grid": _drawer_grid,
    "single_door": _single_door, "double_door": _double_door, "long_door": _long_door,
    "drawers_over_doors": _drawers_over_doors, "door_beside_drawers": _door_beside_drawers, "wardrobe": _wardrobe,
    "double_door_rows": _double_door_rows, "stacked_doors": _stacked_doors, "tall_drawer_stack": _tall_drawer_stack,
    "drawer_row": _drawer_row, "stack_beside_door": _stack_beside_door,
}


def sample_layout(rng: np.random.Generator, cfg: GeneratorConfig, t: float, plinth: float) -> Layout:
    """Pick a layout family, then its size and tree."""
    draw = _Draw(rng, cfg, float(rng.uniform(*cfg.depth_range)), t, 2 * t + plinth)
    family = cfg.invalid_layouts if rng.random() < cfg.invalid_fraction else cfg.valid_layouts
    unknown = [name for name, _ in family if name not in FAMILIES]
    if unknown:
        raise ValueError(f"GeneratorConfig names unknown layout families {unknown}; known: {sorted(FAMILIES)}")
    p = np.array([wt for _, wt in family])
    layout = FAMILIES[family[rng.choice(len(family), p=p / p.sum())][0]](draw)
    layout.width = float(np.clip(layout.width, *cfg.width_range))
    layout.height = float(np.clip(layout.height, *cfg.height_range))
    return layout
