"""Collision hulls of one merged mesh: convex pieces kept as they are, the rest decomposed."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from opend_mj.assets.config import CompilerConfig
from opend_mj.assets.meshes.cache import DecompositionStats, cached_split
from opend_mj.assets.meshes.coacd_adapter import coacd_rest
from opend_mj.assets.meshes.geometry import Hull, trimesh_hull, is_convex_piece, oriented_box, pieces, to_hull, weld
from opend_mj.assets.meshes.splitter import covers_hull


def collision_hulls(
    vertices: np.ndarray,
    faces: np.ndarray,
    config: CompilerConfig,
    cache_dir: Path | None,
    stats: DecompositionStats | None = None,
    groups: np.ndarray | None = None,
    handle: bool = False,
    memo: dict | None = None,
) -> list[Hull]:
    """Convex collision hulls for one merged mesh (a link's body or its handles).

    `groups` (one id per face, e.g. the source file) keeps pieces of different files apart when a
    surface soup has to be welded; `handle` selects the handle tolerance and thickness.
    """
    stats = stats if stats is not None else DecompositionStats()
    hulls: list[Hull] = []

    def classify(pv: np.ndarray, pf: np.ndarray) -> bool:
        """Keep a closed piece as one hull if it is convex; return False if it is not."""
        size = float(np.linalg.norm(np.ptp(pv, axis=0)))
        if size < config.min_piece_size:
            stats.dropped_pieces += 1
            return True
        _, _, half = oriented_box(pv)
        if 2 * float(np.min(half)) < config.min_thickness:
            return False
        if not is_convex_piece(pv, pf, config.convex_tolerance):
            return False
        hull = to_hull(pv, config)
        if hull is not None:
            hulls.append(hull)
            stats.convex_pieces += 1
        return True

    # Pass 1: pieces as the file connects them (procedural boxes, closed parts of real meshes).
    # Pieces are welded only within themselves, so touching panels that share corner positions stay
    # separate convex pieces.
    pool_v: list[np.ndarray] = []
    pool_f: list[np.ndarray] = []
    pool_g: list[np.ndarray] = []
    pool_offset = 0
    face_group = np.zeros(len(faces), dtype=np.int64) if groups is None else np.asarray(groups)
    vertex_group = np.zeros(len(vertices), dtype=np.int64)
    vertex_group[faces.reshape(-1)] = np.repeat(face_group, 3)
    for raw_v, raw_f, used in pieces(vertices, faces, return_index=True):
        # (welding only removes faces: a piece of fewer than 4 faces cannot pass, skip the weld)
        if len(raw_f) >= 4:
            pv, pf = weld(raw_v, raw_f)
            if len(pf) >= 4 and classify(pv, pf):
                continue
        pool_v.append(raw_v)
        pool_f.append(raw_f + pool_offset)
        pool_g.append(np.full(len(raw_f), vertex_group[used[0]]))
        pool_offset += len(raw_v)
    if not pool_v:
        return hulls
    pv_all, pf_all, pg_all = np.vstack(pool_v), np.vstack(pool_f), np.concatenate(pool_g)
    if config.decomposer == "coacd":
        coacd_rest(pv_all, pf_all, config, cache_dir, stats, hulls)
        return hulls

    # Pass 2: what is left (surface soups, flat panels, non-convex parts) is welded per source file,
    # split into connected pieces, and each piece is cut into hulls that follow its surface.
    if handle:
        tolerance, thickness, budget = config.handle_tolerance, config.handle_min_thickness, config.handle_max_hulls
        split_thickness = config.handle_split_thickness
        fill = 0.0
    else:
        tolerance, thickness, budget = config.surface_tolerance, config.min_thickness, config.max_hulls_per_piece
        split_thickness = thickness
        fill = config.fill_panels
    hull_config = config if thickness == config.min_thickness else _with_thickness(config, thickness)
    split_config = config if split_thickness == config.min_thickness else _with_thickness(config, split_thickness)
    for g in np.unique(pg_all):
        sel = pg_all == g
        used, local = np.unique(pf_all[sel], return_inverse=True)
        wv, wf = weld(pv_all[used], local.reshape(-1, 3))
        for pv, pf in pieces(wv, wf):
            if float(np.linalg.norm(np.ptp(pv, axis=0))) < config.min_piece_size:
                stats.dropped_pieces += 1
                continue
            flat = len(pv) < 4 or 2 * float(np.min(oriented_box(pv)[2])) < config.min_thickness
            if len(pv) < 4 or (flat and covers_hull(pv, pf, trimesh_hull(pv), tolerance / 4)):
                # a lone triangle or a convex flat plate: one thickened plate, as it is (by the exact
                # path: procedural knob faces take it, and their compiled output stays as it was)
                hull = to_hull(pv, hull_config)
                if hull is not None:
                    hulls.append(hull)
                    stats.convex_pieces += 1
                continue
            stats.decomposed_pieces += 1
            split = cached_split(pv, pf, tolerance, split_thickness, budget, config.min_piece_size, fill, cache_dir,
                                 memo, stats, by_deviation=handle)
            for points in split:
                # a piece that is one hull (e.g. a procedural knob face) compiles like a convex piece
                hull = to_hull(points, hull_config, fast=False) if len(split) == 1 else \
                    to_hull(points, split_config, fast=True)
                if hull is not None:
                    hulls.append(hull)
                    stats.split_hulls += 1
    return hulls


def _with_thickness(config: CompilerConfig, thickness: float) -> CompilerConfig:
    import dataclasses

    return dataclasses.replace(config, min_thickness=thickness)
