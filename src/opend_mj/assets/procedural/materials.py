"""Colours and Phong materials of procedural cabinets (carcass palettes, handle finishes)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from opend_mj.assets.procedural.config import GeneratorConfig


PALETTES: dict[str, list[tuple[float, float, float]]] = {
    "wood": [(0.72, 0.55, 0.36), (0.36, 0.24, 0.15), (0.55, 0.30, 0.17), (0.85, 0.74, 0.57),
             (0.80, 0.64, 0.42), (0.62, 0.45, 0.30)],
    "white": [(0.93, 0.93, 0.91), (0.90, 0.88, 0.83)],
    "grey": [(0.62, 0.62, 0.62), (0.42, 0.43, 0.45), (0.25, 0.26, 0.28)],
    "black": [(0.08, 0.08, 0.08)],
    "colour": [(0.55, 0.65, 0.52), (0.15, 0.22, 0.38), (0.60, 0.72, 0.82), (0.60, 0.16, 0.13),
               (0.86, 0.73, 0.32), (0.75, 0.55, 0.60)],
}
HANDLE_FINISHES = {
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


def pick_colour(rng: np.random.Generator, cfg: GeneratorConfig) -> tuple[float, float, float]:
    """A carcass colour: a palette by ``cfg.palette_weights``, one of its colours, +-0.03 per channel."""
    names = [name for name, _ in cfg.palette_weights]
    p = np.array([weight for _, weight in cfg.palette_weights])
    pal = PALETTES[names[rng.choice(len(names), p=p / p.sum())]]
    base = np.array(pal[rng.integers(len(pal))])
    return tuple(float(c) for c in np.clip(base + rng.uniform(-0.03, 0.03, 3), 0.0, 1.0))
