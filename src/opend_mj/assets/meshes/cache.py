"""The splitter's on-disk cache (keyed by piece shape up to translation, settings and
`SPLIT_VERSION`) and the counts of what a decomposition did."""

from __future__ import annotations

import hashlib
import io
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from opend_mj.assets.meshes.splitter import split_decompose


#: Bump when `split_decompose` gives other hulls for the same input (invalidates its cache).
SPLIT_VERSION = 5


@dataclass
class DecompositionStats:
    """Counts of what the decomposition of a cabinet's meshes did (pieces, hulls, cache hits, time)."""

    convex_pieces: int = 0
    decomposed_pieces: int = 0
    coacd_hulls: int = 0
    dropped_pieces: int = 0
    #: Hulls made by the plane-split decomposition of non-convex pieces (real meshes).
    split_hulls: int = 0
    #: Non-convex pieces whose decomposition came from the cache.
    cache_hits: int = 0
    #: Largest estimated distance (m) of a split hull from the visual surface it stands for.
    max_deviation: float = 0.0
    #: Seconds in the plane-split decomposition (cache misses only).
    split_seconds: float = 0.0


def _piece_key(vertices: np.ndarray, faces: np.ndarray, extra: str) -> tuple[str, np.ndarray]:
    """Cache key of a piece up to translation (copies of one part share it), and the shift used."""
    shift = np.round(vertices.min(axis=0), 5)
    key = hashlib.sha256()
    key.update(np.ascontiguousarray(np.round(vertices - shift, 6)).tobytes())
    key.update(np.ascontiguousarray(faces.astype(np.int64)).tobytes())
    key.update(extra.encode())
    return key.hexdigest()[:32], shift


def cached_split(
    vertices: np.ndarray,
    faces: np.ndarray,
    tolerance: float,
    min_thickness: float,
    max_hulls: int,
    min_size: float,
    fill_panels: float,
    cache_dir: Path | None,
    memo: dict | None = None,
    stats: DecompositionStats | None = None,
    by_deviation: bool = False,
) -> list[np.ndarray]:
    """`split_decompose`, cached on disk (and in `memo`) by piece shape, settings and SPLIT_VERSION."""
    import time

    stats = stats if stats is not None else DecompositionStats()
    extra = repr((SPLIT_VERSION, tolerance, min_thickness, max_hulls, min_size, fill_panels)
                 + ((by_deviation,) if by_deviation else ()))
    key, shift = _piece_key(vertices, faces, extra)
    local = None
    if memo is not None and key in memo:
        local, worst = memo[key]
        stats.cache_hits += 1
    cache_file = cache_dir / "split" / key[:2] / f"{key}.npz" if cache_dir else None
    if local is None and cache_file is not None and cache_file.is_file():
        try:
            with np.load(cache_file) as data:
                worst = float(data["worst"])
                local = [data[k] for k in sorted((k for k in data.files if k != "worst"), key=lambda s: int(s[1:]))]
            stats.cache_hits += 1
        except (OSError, ValueError, KeyError):
            local = None
    if local is None:
        start = time.perf_counter()
        hulls, worst = split_decompose(vertices - shift, faces, tolerance, min_thickness, max_hulls, min_size,
                                       fill_panels, by_deviation)
        stats.split_seconds += time.perf_counter() - start
        local = hulls
        if cache_file is not None:
            try:
                cache_file.parent.mkdir(parents=True, exist_ok=True)
                buffer = io.BytesIO()
                np.savez_compressed(buffer, worst=np.array(worst), **{f"h{i}": h for i, h in enumerate(hulls)})
                tmp = cache_file.with_suffix(f".{os.getpid()}.tmp")
                tmp.write_bytes(buffer.getvalue())
                tmp.replace(cache_file)
            except OSError:
                pass  # a read-only cache is no reason to fail a build
    if memo is not None:
        memo[key] = (local, worst)
    stats.max_deviation = max(stats.max_deviation, worst)
    return [h + shift for h in local]
