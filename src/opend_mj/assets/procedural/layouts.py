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


def sample_layout(rng: np.random.Generator, cfg: GeneratorConfig, t: float, plinth: float) -> Layout:
    """Pick a layout family, then its size and tree."""
    d = float(rng.uniform(*cfg.depth_range))
    frame = 2 * t + plinth

    def rows_h(n_rows: int, row_h: tuple[float, float]) -> float:
        return _size_for_rows(rng, cfg, n_rows, row_h, frame + (n_rows - 1) * t)

    u = rng.uniform

    def single_drawer():
        w = u(0.35, 0.8)
        if rng.random() < cfg.nightstand_share:  # nightstand: drawer over an open shelf
            h = rows_h(2, (0.14, 0.3))
            return Layout("drawer_over_shelf", w, h, d, _rows((1.0, Leaf("drawer")), (1.6, Leaf("open"))), True)
        return Layout("single_drawer", w, rows_h(1, (0.2, 0.35)), d, _rows((1.0, Leaf("drawer"))), True)

    def drawer_stack():
        n = int(rng.choice([k for k, _ in cfg.drawer_stack_sizes], p=[w for _, w in cfg.drawer_stack_sizes]))
        return Layout(f"drawer_stack_{n}", u(0.35, 1.0), rows_h(n, (0.1, 0.3)), d, _drawer_stack(rng, cfg, n), True)

    def drawer_grid():
        shapes = cfg.drawer_grid_shapes
        cols, rows = shapes[rng.choice(len(shapes), p=[w for _, w in shapes])][0]
        w = u(max(0.6, cols * 0.3), 1.2)
        tree = _cols(*[(1.0, _drawer_stack(rng, cfg, rows) if rows > 1 else Leaf("drawer")) for _ in range(cols)])
        if rows > 1:  # identical rows in every column (same handle levels)
            tree = _cols(*[(1.0, tree.children[0][1]) for _ in range(cols)])
        return Layout(f"drawer_grid_{cols}x{rows}", w, rows_h(rows, (0.12, 0.25)), d, tree, True)

    def single_door():
        hinge = "left" if rng.random() < cfg.left_hinge_share else "right"
        h = u(0.4, 1.8)
        tree: Leaf | Split = Leaf("door", hinge)
        return Layout("single_door", u(0.3, 0.6), h, d, tree, True)

    def double_door():
        return Layout("double_door", u(0.6, 1.2), u(0.4, 1.8), d, Leaf("double_door"), True)

    def long_door():
        """A wide, low cabinet with one side-hinged door across its whole width (never a flap), under an
        open shelf half of the time: the TV and sideboard cabinets of the real OpenD training set (18 of
        their 126 side-hinged doors are 0.95-1.25 m wide and 0.35-0.67 m tall, the only door of their
        cabinet; no real flap is that wide).
        Not among the default families (`GeneratorConfig.valid_layouts`): `opend generate --family`."""
        hinge = "left" if rng.random() < cfg.left_hinge_share else "right"
        w = u(0.95, 1.2)
        if rng.random() < 0.5:
            return Layout("long_door_under_shelf", w, u(0.6, 0.9), d,
                          _rows((u(0.4, 0.8), Leaf("open")), (1.0, Leaf("door", hinge))), True, flaps=False)
        return Layout("long_door", w, u(0.4, 0.7), d, Leaf("door", hinge), True, flaps=False)

    def drawers_over_doors():
        w = u(0.45, 1.2)
        double = w > 0.65
        n_top = 2 if (double and w > 0.8 and rng.random() < cfg.paired_top_drawers_share) else 1
        top = _cols(*[(1.0, Leaf("drawer")) for _ in range(n_top)]) if n_top > 1 else Leaf("drawer")
        bottom = Leaf("double_door") if double else Leaf("door", "left" if rng.random() < cfg.left_hinge_share
                                                           else "right")
        h = u(0.65, 1.2)
        ratio = u(0.22, 0.35)
        name = f"drawer{'s' if n_top > 1 else ''}_over_{'double_door' if double else 'door'}"
        return Layout(name, w, h, d, _rows((ratio, top), (1 - ratio, bottom)), True)

    def door_beside_drawers():
        w = u(0.7, 1.2)
        sizes = cfg.door_beside_stack_sizes
        n = int(rng.choice([k for k, _ in sizes], p=[w for _, w in sizes]))
        h = rows_h(n, (0.12, 0.25))
        stack = _drawer_stack(rng, cfg, n)
        if rng.random() < cfg.left_hinge_share:
            tree = _cols((1.0, Leaf("door", "left")), (u(0.7, 1.0), stack))
        else:
            tree = _cols((u(0.7, 1.0), stack), (1.0, Leaf("door", "right")))
        return Layout(f"door_beside_{n}_drawers", w, h, d, tree, True)

    def wardrobe():
        w = u(0.7, 1.2)
        h = u(1.3, 1.8)
        n = int(rng.choice([1, 2]))
        bottom = _drawer_stack(rng, cfg, n) if n > 1 else Leaf("drawer")
        tree = _rows((u(0.7, 0.8), Leaf("double_door")), (0.1 * n + u(0.0, 0.05), bottom))
        return Layout(f"wardrobe_{n}_drawers", w, h, d, tree, True)

    def double_door_rows():
        w = u(0.6, 1.1)
        h = u(1.2, 1.8)
        return Layout("double_door_rows", w, h, d, _rows((u(0.8, 1.2), Leaf("double_door")), (1.0, Leaf("double_door"))), True)

    def stacked_doors():
        hinge = "left" if rng.random() < cfg.left_hinge_share else "right"
        return Layout("stacked_doors", u(0.35, 0.6), u(1.0, 1.8), d,
                      _rows((u(0.6, 1.0), Leaf("door", hinge)), (1.0, Leaf("door", hinge))), True)

    # ---- layouts that the language rule cannot describe
    def tall_drawer_stack():
        n = int(rng.integers(6, 9))
        return Layout(f"tall_drawer_stack_{n}", u(0.3, 0.8), rows_h(n, (0.08, 0.18)), d, _drawer_stack(rng, cfg, n), False)

    def drawer_row():
        n = int(rng.integers(6, 9))
        w = u(max(0.8, n * 0.13 + 0.1), 1.2)
        return Layout(f"drawer_row_{n}", w, rows_h(1, (0.12, 0.25)), d,
                      _cols(*[(1.0, Leaf("drawer")) for _ in range(n)]), False)

    def stack_beside_door():
        n = int(rng.integers(6, 8))
        w = u(0.7, 1.2)
        h = rows_h(n, (0.08, 0.16))
        stack = _drawer_stack(rng, cfg, n)
        if rng.random() < cfg.left_hinge_share:
            tree = _cols((1.0, Leaf("door", "left")), (u(0.7, 1.0), stack))
        else:
            tree = _cols((u(0.7, 1.0), stack), (1.0, Leaf("door", "right")))
        return Layout(f"door_beside_{n}_drawers", w, h, d, tree, False)

    families: dict[str, Callable[[], Layout]] = {
        "single_drawer": single_drawer, "drawer_stack": drawer_stack, "drawer_grid": drawer_grid,
        "single_door": single_door, "double_door": double_door, "long_door": long_door,
        "drawers_over_doors": drawers_over_doors,
        "door_beside_drawers": door_beside_drawers, "wardrobe": wardrobe, "double_door_rows": double_door_rows,
        "stacked_doors": stacked_doors, "tall_drawer_stack": tall_drawer_stack, "drawer_row": drawer_row,
        "stack_beside_door": stack_beside_door,
    }
    family = cfg.invalid_layouts if rng.random() < cfg.invalid_fraction else cfg.valid_layouts
    unknown = [name for name, _ in family if name not in families]
    if unknown:
        raise ValueError(f"GeneratorConfig names unknown layout families {unknown}; known: {sorted(families)}")
    p = np.array([wt for _, wt in family])
    layout = families[family[rng.choice(len(family), p=p / p.sum())][0]]()
    layout.width = float(np.clip(layout.width, *cfg.width_range))
    layout.height = float(np.clip(layout.height, *cfg.height_range))
    return layout
