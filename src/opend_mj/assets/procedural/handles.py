"""Sampling handles: a style per target type, then bar, arched or knob pieces on a panel."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from opend_mj.assets.procedural.config import HANDLE_KINDS, GeneratorConfig
from opend_mj.assets.procedural.pieces import Box, Cylinder, Piece


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


def handle_style(rng: np.random.Generator, cfg: GeneratorConfig, target: str,
                 kind: str | None = None) -> HandleStyle:
    """The handle design of one target type (``kind`` forced, else drawn by the type's weights)."""
    if kind is None:
        p = cfg.drawer_handle_kinds if target == "drawer" else cfg.door_handle_kinds
        kind = HANDLE_KINDS[rng.choice(3, p=list(p))]
    if kind == "knob":
        orient = "none"
    elif target == "drawer":
        orient = "vertical" if rng.random() < cfg.drawer_vertical_share else "horizontal"
    else:
        orient = "horizontal" if rng.random() < cfg.door_horizontal_share else "vertical"
    return HandleStyle(
        kind=kind,
        orientation=orient,
        diameter=float(rng.uniform(*cfg.bar_diameter_range)),
        clearance=float(rng.uniform(*cfg.bar_gap_range)),
        square=bool(rng.random() < cfg.square_bar_share),
        arch_style="u" if rng.random() < cfg.u_arch_share else "trapezoid",
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
    if rng.random() < cfg.knob_rim_share:
        pieces.append(Cylinder((x, y, z0), (x, y, z0 + 0.003), stem_r * 1.8))
    return pieces


def make_handle(rng: np.random.Generator, cfg: GeneratorConfig, st: HandleStyle, panel_lo: np.ndarray,
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
    # a long bar runs most of its panel (real long pulls span 60-95 % of it); others anywhere in range
    frac = cfg.long_bar_min_frac + (1 - cfg.long_bar_min_frac) * st.length_frac if kind == "bar" and st.long \
        else st.length_frac
    length = min_len + frac * (max_len - min_len)
    u = np.array([1.0, 0.0, 0.0]) if orient == "horizontal" else np.array([0.0, 1.0, 0.0])
    # keep the handle inside the panel
    lo_c = panel_lo[:2] + margin + (u[:2] * length / 2)
    hi_c = panel_hi[:2] - margin - (u[:2] * length / 2)
    c[:2] = np.clip(c[:2], lo_c, np.maximum(lo_c, hi_c))
    if kind == "bar":
        return _bar_pieces(c, u, z0, length, st, rng), kind, orient
    return _arched_pieces(c, u, z0, length, st), kind, orient
