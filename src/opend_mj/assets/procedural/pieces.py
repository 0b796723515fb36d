"""Convex pieces (boxes, cylinders) in metres and their closed, outward-oriented triangle meshes."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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


def translate_piece(p: Piece, d: tuple[float, float, float]) -> Piece:
    """The piece moved by ``d`` (m)."""
    dv = np.asarray(d)
    if isinstance(p, Box):
        return Box(tuple(np.asarray(p.lo) + dv), tuple(np.asarray(p.hi) + dv))
    return Cylinder(tuple(np.asarray(p.p0) + dv), tuple(np.asarray(p.p1) + dv), p.radius)


def bounds_of(pieces: list[Piece]) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned bounds (m) of a list of pieces."""
    bs = [piece_bounds(p) for p in pieces]
    return np.min([b[0] for b in bs], axis=0), np.max([b[1] for b in bs], axis=0)
