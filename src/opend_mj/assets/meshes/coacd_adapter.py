"""The CoACD path (``CompilerConfig.decomposer == "coacd"``): convex decomposition by CoACD, cached
on disk by mesh content and parameters. The default decomposer is the plane splitter (`splitter`)."""

from __future__ import annotations

import hashlib
import io
from pathlib import Path

import numpy as np

from opend_mj.assets.config import CoacdParams
from opend_mj.assets.meshes.geometry import is_convex_piece, oriented_box, pieces, to_hull, weld


def coacd_decompose(
    vertices: np.ndarray, faces: np.ndarray, params: CoacdParams, cache_dir: Path | None
) -> list[np.ndarray]:
    """CoACD convex decomposition, cached on disk by mesh content and parameters."""
    key = hashlib.sha256()
    key.update(np.ascontiguousarray(np.round(vertices, 6)).tobytes())
    key.update(np.ascontiguousarray(faces.astype(np.int64)).tobytes())
    key.update(repr(params).encode())
    cache_file = cache_dir / f"coacd-{key.hexdigest()[:24]}.npz" if cache_dir else None
    if cache_file is not None and cache_file.is_file():
        with np.load(cache_file) as data:
            return [data[k] for k in sorted(data.files, key=lambda s: int(s[1:]))]
    import coacd  # heavy import; only real (non-convex) meshes need it

    coacd.set_log_level("error")
    parts = coacd.run_coacd(
        coacd.Mesh(np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int32)),
        threshold=params.threshold,
        max_convex_hull=params.max_convex_hull,
        preprocess_mode=params.preprocess_mode,
        preprocess_resolution=params.preprocess_resolution,
        resolution=params.resolution,
        mcts_nodes=params.mcts_nodes,
        mcts_iterations=params.mcts_iterations,
        mcts_max_depth=params.mcts_max_depth,
        seed=params.seed,
    )
    hulls = [np.asarray(v, dtype=np.float64) for v, _ in parts]
    if cache_file is not None:
        cache_dir.mkdir(parents=True, exist_ok=True)
        buffer = io.BytesIO()
        np.savez_compressed(buffer, **{f"h{i}": h for i, h in enumerate(hulls)})
        tmp = cache_file.with_suffix(".tmp")
        tmp.write_bytes(buffer.getvalue())
        tmp.replace(cache_file)
    return hulls


def coacd_rest(rv, rf, config, cache_dir, stats, hulls) -> None:
    """Hulls of pieces that are not convex from one CoACD run over all of them (``config.decomposer ==
    "coacd"``); convex and flat pieces become one hull each, as on the splitter path."""
    wv, wf = weld(rv, rf)
    rest_v, rest_f, offset = [], [], 0
    for pv, pf in pieces(wv, wf):
        size = float(np.linalg.norm(np.ptp(pv, axis=0)))
        if size < config.min_piece_size:
            stats.dropped_pieces += 1
            continue
        _, _, half = oriented_box(pv)
        flat = 2 * float(np.min(half)) < config.min_thickness
        if flat or is_convex_piece(pv, pf, config.convex_tolerance):
            hull = to_hull(pv, config)
            if hull is not None:
                hulls.append(hull)
                stats.convex_pieces += 1
            continue
        rest_v.append(pv)
        rest_f.append(pf + offset)
        offset += len(pv)
    if rest_v:
        stats.decomposed_pieces += len(rest_v)
        for points in coacd_decompose(np.vstack(rest_v), np.vstack(rest_f), config.coacd, cache_dir):
            hull = to_hull(points, config)
            if hull is not None:
                hulls.append(hull)
                stats.coacd_hulls += 1
