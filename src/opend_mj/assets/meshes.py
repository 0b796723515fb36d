"""Mesh processing for the compiler: pieces, convexity, decomposition, thin hulls and boxes.

Real PartNet-Mobility meshes are surface soups: faces stored twice (double-sided), many disconnected
pieces, flat panels of zero thickness. The pipeline here turns any such soup into a list of convex
hulls that MuJoCo accepts:

1. weld vertices by position and split into vertex-connected pieces;
2. keep a piece that is already convex as one hull (procedural cabinets are all convex pieces);
3. send what is left through CoACD (cached by content hash);
4. thicken hulls thinner than a few millimetres, and turn box-shaped hulls into box primitives.
"""

from __future__ import annotations

import hashlib
import io
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from opend_mj.assets.config import CoacdParams, CompilerConfig

#: Bump when `split_decompose` gives other hulls for the same input (invalidates its cache).
SPLIT_VERSION = 5

#: Planar holes narrower than this (m) count as closed in the splitter (a board or a knob modelled
#: without its hidden face); wider ones (a carcass opening) stay open.
_CAP_WIDTH = 0.05

#: Most surface points the splitter measures a piece's hulls against (its spacing grows beyond).
_MAX_SURFACE_POINTS = 150000


#: Surface points per hull when the splitter compares candidate cuts by deviation (1500 for the hulls kept).
_CANDIDATE_POINTS = 600

#: Points this close (m) to a cut plane lie on the face shared by the hulls on both sides of it.
_PLANE_EPS = 1e-5


class MeshError(ValueError):
    """A mesh file that cannot be used; the message names the file and the problem."""


@dataclass
class Hull:
    """One convex collision piece in body coordinates: a box primitive or a vertex cloud."""

    vertices: np.ndarray  # (n, 3) hull vertices (the hull of these is the shape)
    box: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # centre, rotation (3x3), half sizes

    @property
    def volume(self) -> float:
        if self.box is not None:
            return float(8.0 * np.prod(self.box[2]))
        return float(_hull(self.vertices).volume)


def load_mesh_file(path: Path, max_faces: int | None = None) -> list[tuple[trimesh.Trimesh, object]]:
    """Load an OBJ (or any trimesh format) as (mesh, visual) parts, one per material.

    Raises MeshError for missing, empty, NaN or degenerate meshes, and for OBJ files with more than
    `max_faces` faces (counted before parsing, so a huge file cannot stall a worker).
    """
    if not path.is_file():
        raise MeshError(f"{path}: mesh file is missing")
    if max_faces is not None and path.suffix.lower() == ".obj":
        count = 0
        with open(path, "rb") as fh:
            for line in fh:
                if line.startswith(b"f "):
                    count += max(1, len(line.split()) - 3)
        if count > max_faces:
            raise MeshError(f"{path}: mesh has {count} faces, more than the limit of {max_faces} "
                            f"(CompilerConfig.max_mesh_faces)")
    try:
        loaded = trimesh.load(path, process=False)
    except Exception as exc:  # trimesh raises many exception types for bad files
        raise MeshError(f"{path}: cannot be read as a mesh ({type(exc).__name__}: {exc})") from exc
    geoms = list(loaded.geometry.values()) if isinstance(loaded, trimesh.Scene) else [loaded]
    parts = [g for g in geoms if isinstance(g, trimesh.Trimesh) and len(g.faces) > 0]
    if not parts:
        raise MeshError(f"{path}: mesh is empty (no faces)")
    for g in parts:
        if not np.all(np.isfinite(g.vertices)):
            raise MeshError(f"{path}: mesh has NaN or infinite vertex coordinates")
    _attach_textures(path, parts)
    area = sum(float(g.area) for g in parts)
    if not area > 0.0:
        raise MeshError(f"{path}: mesh is degenerate (all faces have zero area)")
    return [(g, g.visual) for g in parts]


def _attach_textures(obj_path: Path, parts: list[trimesh.Trimesh]) -> None:
    """Load `map_Kd` textures that trimesh's resolver skipped (PartNet uses `../images/...`)."""
    missing = [g for g in parts if getattr(getattr(g.visual, "material", None), "image", 1) is None]
    if not missing:
        return
    textures: dict[str, Path] = {}
    try:
        lines = obj_path.read_text(errors="replace").splitlines()
    except OSError:
        return
    for mtllib in (ln.split(None, 1)[1].strip() for ln in lines if ln.startswith("mtllib ")):
        mtl = obj_path.parent / mtllib
        if not mtl.is_file():
            continue
        current = None
        for ln in mtl.read_text(errors="replace").splitlines():
            fields = ln.strip().split(None, 1)
            if len(fields) == 2 and fields[0] == "newmtl":
                current = fields[1].strip()
            elif len(fields) == 2 and fields[0] == "map_Kd" and current:
                textures[current] = (mtl.parent / fields[1].strip().split()[-1]).resolve()
    from PIL import Image

    for g in missing:
        image_path = textures.get(g.visual.material.name)
        if image_path is not None and image_path.is_file() and getattr(g.visual, "uv", None) is not None:
            try:
                g.visual.material.image = Image.open(image_path).convert("RGB")
            except OSError:
                pass


def weld(vertices: np.ndarray, faces: np.ndarray, decimals: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """Merge vertices with equal positions, drop degenerate and duplicate (incl. flipped) faces."""
    rounded = np.round(vertices, decimals)
    unique, inverse = np.unique(rounded, axis=0, return_inverse=True)
    faces = inverse.reshape(-1)[faces]
    keep = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    faces = faces[keep]
    if len(faces):
        _, first = np.unique(np.sort(faces, axis=1), axis=0, return_index=True)
        faces = faces[np.sort(first)]
    return unique, faces


def pieces(vertices: np.ndarray, faces: np.ndarray, return_index: bool = False) -> list[tuple]:
    """Split a welded mesh into vertex-connected pieces (robust to non-manifold edges).

    Each piece is (vertices, faces), plus the indices of its vertices in `vertices` if `return_index`.
    """
    n = len(vertices)
    parent = list(range(n))  # a Python list and Python ints: the union-find loop is pure Python

    def find(i: int) -> int:
        root = i
        while parent[root] != root:
            root = parent[root]
        while parent[i] != root:
            parent[i], i = root, parent[i]
        return root

    for a, b, c in np.asarray(faces).tolist():
        ra, rb, rc = find(a), find(b), find(c)
        parent[rb] = ra
        parent[find(rc)] = ra
    roots = np.array([find(i) for i in range(n)], dtype=np.int64)
    face_root = roots[faces[:, 0]]
    out = []
    for root in np.unique(face_root):
        f = faces[face_root == root]
        used, local = np.unique(f, return_inverse=True)
        out.append((vertices[used], local.reshape(-1, 3), used) if return_index else
                   (vertices[used], local.reshape(-1, 3)))
    return out


def _hull(points: np.ndarray) -> trimesh.Trimesh:
    return trimesh.convex.convex_hull(points, qhull_options="QbB Pp QJ")


class QHull:
    """A convex hull straight from qhull (scipy), without trimesh's mesh processing.

    What the splitter and the real-mesh path need: vertices, triangles, outward unit normals and plane
    offsets (n . x <= offset inside), facet areas, area and volume, all in the input's coordinates.
    """

    def __init__(self, points: np.ndarray):
        from scipy.spatial import ConvexHull

        points = np.asarray(points, dtype=float)
        try:
            h = ConvexHull(points, qhull_options="QbB Pp QJ")  # (QbB: qhull's own figures are scaled)
        except Exception:  # QbB refuses a set with no extent along an axis (an axis-aligned plate)
            h = ConvexHull(points, qhull_options="Pp QJ")
        self.vertices = points[np.sort(h.vertices)]
        tri = points[h.simplices]
        self.faces = h.simplices
        self.triangles = tri
        cross = _cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        norm = np.linalg.norm(cross, axis=1)
        self.area_faces = 0.5 * norm
        normals = cross / np.where(norm > 0, norm, 1.0)[:, None]
        inner = self.vertices.mean(axis=0)
        flip = np.einsum("ij,ij->i", normals, tri[:, 0] - inner) < 0
        normals[flip] *= -1
        self.face_normals = normals
        self.offsets = np.einsum("ij,ij->i", normals, tri[:, 0])
        self.area = float(self.area_faces.sum())
        self.volume = float(np.einsum("ij,ij->i", normals, tri[:, 0] - inner) @ self.area_faces) / 3.0
        self.points = points


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of (n, 3) arrays (np.cross has a large per-call overhead)."""
    return np.column_stack([a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1], a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
                            a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]])


def fast_box(points: np.ndarray, hull: QHull | None = None, candidates: int = 4) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A small oriented box (centre, rotation columns = box axes, half sizes), cheaply.

    Like trimesh's `oriented_bounds` (one box face on a hull facet), but only over the principal axes
    and the normals of the `candidates` largest hull facets, each with the in-plane directions of the
    other candidates and of its facets' edges: exact for boxes and plates, close to the smallest box
    otherwise, all frames in one vectorised pass.
    """
    points = np.asarray(points, dtype=float)
    mean = points.mean(axis=0)
    if hull is None and len(points) >= 4:
        try:
            hull = QHull(points)
        except Exception:  # degenerate sets: principal axes alone
            hull = None
    verts = (hull.vertices if hull is not None else points) - mean
    _, vecs = np.linalg.eigh(verts.T @ verts)
    normals = [vecs[:, 0], vecs[:, 1], vecs[:, 2]]
    edge_dirs: list[np.ndarray] = [np.zeros((0, 3))] * 3
    if hull is not None:
        fn, tri = hull.face_normals, hull.triangles
        for f in np.argsort(-hull.area_faces)[:8 * candidates]:
            n = fn[f]
            if abs(float(n @ n) - 1.0) > 1e-6:
                continue
            if any(abs(float(n @ m)) > 0.999 for m in normals[3:]):
                continue
            normals.append(n)
            same = np.flatnonzero(np.abs(fn @ n) > 0.999)[:8]
            t = tri[same]
            edge_dirs.append(np.vstack([t[:, 1] - t[:, 0], t[:, 2] - t[:, 1], t[:, 0] - t[:, 2]]))
            if len(normals) == 3 + candidates:
                break
    normals_arr = np.array(normals)
    frames_n, frames_d = [], []
    for i, n in enumerate(normals_arr):
        d = np.vstack([normals_arr, edge_dirs[i]])
        d = d - np.outer(d @ n, n)
        length = np.linalg.norm(d, axis=1)
        d = d[length > 1e-9] / length[length > 1e-9, None]
        frames_n.append(np.broadcast_to(n, d.shape))
        frames_d.append(d)
    n_all, d_all = np.vstack(frames_n), np.vstack(frames_d)
    e_all = _cross(n_all, d_all)
    ok = np.abs(np.linalg.norm(e_all, axis=1) - 1.0) < 1e-6  # (a zero normal of a degenerate facet)
    n_all, d_all, e_all = n_all[ok], d_all[ok], e_all[ok]
    rots = np.stack([d_all, e_all, n_all], axis=2)  # (frames, 3, 3): columns are the box axes
    local = np.einsum("vi,fij->fvj", verts, rots)
    lo, hi = local.min(axis=1), local.max(axis=1)
    ext = hi - lo
    k = int(np.argmin(np.prod(ext + 1e-6 * float(ext.max()), axis=1)))  # (flat sets: the smallest rectangle)
    rot, lo, hi = rots[k], lo[k], hi[k]
    return mean + rot @ ((lo + hi) / 2), rot, (hi - lo) / 2


#: Recent `oriented_box` results by input bytes: the pipeline asks for the box of one point set more than
#: once (a piece's flatness check, then `thicken`); the box is a pure function of the points.
_BOX_MEMO: dict[bytes, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
_BOX_MEMO_SIZE = 512


def oriented_box(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Minimum-volume-ish oriented box: (centre, rotation columns = box axes, half sizes)."""
    points = np.asarray(points, dtype=float)
    key = repr(points.shape).encode() + np.ascontiguousarray(points).tobytes()
    hit = _BOX_MEMO.get(key)
    if hit is None:
        hit = _oriented_box(points)
        if len(_BOX_MEMO) >= _BOX_MEMO_SIZE:
            del _BOX_MEMO[next(iter(_BOX_MEMO))]
        _BOX_MEMO[key] = tuple(np.array(a, copy=True) for a in hit)
        return hit
    return tuple(a.copy() for a in hit)


def _oriented_box(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    try:
        to_origin, extents = trimesh.bounds.oriented_bounds(points)
        transform = np.linalg.inv(to_origin)
        return transform[:3, 3].copy(), transform[:3, :3].copy(), np.asarray(extents) / 2.0
    except Exception:  # degenerate sets (collinear, coplanar slivers): principal axes instead
        mean = points.mean(axis=0)
        _, _, vt = np.linalg.svd(points - mean, full_matrices=True)
        rot = vt.T
        local = (points - mean) @ rot
        lo, hi = local.min(axis=0), local.max(axis=0)
        return mean + rot @ ((lo + hi) / 2), rot, (hi - lo) / 2


def is_convex_piece(vertices: np.ndarray, faces: np.ndarray, tolerance: float) -> bool:
    """True if a piece is (nearly) a closed convex surface: its hull adds almost nothing.

    Watertight pieces compare volumes; open surfaces (real scans are rarely closed) compare the area
    they cover with the hull's area and require every vertex to lie on the hull.
    """
    if len(vertices) < 4:
        return False
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    try:
        hull = _hull(vertices)
    except Exception:
        return False
    if hull.volume <= 0:
        return False
    if mesh.is_watertight and mesh.is_winding_consistent:
        return abs(hull.volume - abs(mesh.volume)) <= tolerance * hull.volume
    if mesh.area < (1.0 - 2 * tolerance) * hull.area or mesh.area > (1.0 + 2 * tolerance) * hull.area:
        return False
    scale = float(np.linalg.norm(np.ptp(vertices, axis=0)))
    closest = trimesh.proximity.ProximityQuery(hull).signed_distance(vertices)
    return bool(np.all(np.abs(closest) <= tolerance * scale))


def thicken(points: np.ndarray, min_thickness: float, box=None) -> np.ndarray:
    """Return hull points with a minimum extent of `min_thickness` along the thinnest box axis."""
    centre, rot, half = oriented_box(points) if box is None else box
    axis = int(np.argmin(half))
    if 2 * half[axis] >= min_thickness:
        return points
    normal = rot[:, axis]
    local = (points - centre) @ normal
    flat = points - np.outer(local, normal)
    offset = 0.5 * min_thickness * normal
    return np.vstack([flat + offset, flat - offset])


def to_hull(points: np.ndarray, config: CompilerConfig, fast: bool = False) -> Hull | None:
    """Make one collision hull from a point set: thickened, and a box primitive when box-shaped.

    `fast` uses qhull and `fast_box` directly (the real-mesh path) instead of trimesh's hull and
    exact oriented bounds (kept for convex pieces, so that procedural cabinets compile as before).
    """
    if len(points) < 3:
        return None
    if float(np.linalg.norm(np.ptp(points, axis=0))) < config.min_piece_size:
        return None
    if fast:
        return _to_hull_fast(np.asarray(points, dtype=float), config)
    points = thicken(points, config.min_thickness)
    try:
        hull = _hull(points)
    except Exception:
        return None
    centre, rot, half = oriented_box(hull.vertices)
    half = np.maximum(half, config.min_thickness / 2)
    box_volume = 8.0 * float(np.prod(half))
    if hull.volume > 0 and box_volume <= (1.0 + config.box_tolerance) * hull.volume:
        return Hull(vertices=hull.vertices, box=(centre, rot, half))
    return Hull(vertices=np.asarray(hull.vertices))


def _to_hull_fast(points: np.ndarray, config: CompilerConfig) -> Hull | None:
    try:
        hull = QHull(points)
        box = fast_box(points, hull)
    except Exception:
        hull, box = None, fast_box(points)
    if 2 * float(np.min(box[2])) < config.min_thickness:
        points = thicken(points, config.min_thickness, box)
        try:
            hull = QHull(points)
        except Exception:
            return None
        box = fast_box(hull.vertices, hull)
    if hull is None:
        return None
    centre, rot, half = box
    half = np.maximum(half, config.min_thickness / 2)
    box_volume = 8.0 * float(np.prod(half))
    if hull.volume > 0 and box_volume <= (1.0 + config.box_tolerance) * hull.volume:
        return Hull(vertices=hull.vertices, box=(centre, rot, half))
    return Hull(vertices=hull.vertices)


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


@dataclass
class DecompositionStats:
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


# --------------------------------------------------------------------------------------------------
# Plane-split decomposition of non-convex pieces
#
# A piece whose convex hull strays from its own surface by more than a tolerance is cut by a plane
# (across one of its box axes, where the children's hulls are smallest), the halves are split into
# connected pieces, and each is cut again until every hull lies within the tolerance of the surface
# (or a hull budget is spent). Distances are measured against points sampled on the piece's surface
# (a k-d tree), so the check is cheap; the sampling makes it err on the side of cutting more.


def _surface_points(vertices: np.ndarray, faces: np.ndarray, spacing: float, rng) -> np.ndarray:
    """Points on a triangle soup no further than about `spacing` apart: vertices, edges and faces."""
    tri = vertices[faces]
    pts = [vertices]
    for a, b in ((0, 1), (1, 2), (2, 0)):
        length = np.linalg.norm(tri[:, b] - tri[:, a], axis=1)
        n = np.ceil(length / spacing).astype(int)
        if n.sum() > 1:
            idx = np.repeat(np.arange(len(tri)), n)
            t = rng.random(len(idx))
            pts.append(tri[idx, a] + t[:, None] * (tri[idx, b] - tri[idx, a]))
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    n = np.ceil(2.0 * area / spacing**2).astype(int)
    idx = np.repeat(np.arange(len(tri)), n)
    if len(idx):
        r1, r2 = rng.random(len(idx)), rng.random(len(idx))
        flip = r1 + r2 > 1
        r1[flip], r2[flip] = 1 - r1[flip], 1 - r2[flip]
        t = tri[idx]
        pts.append(t[:, 0] + r1[:, None] * (t[:, 1] - t[:, 0]) + r2[:, None] * (t[:, 2] - t[:, 0]))
    return np.vstack(pts)


def _grid_points(vertices: np.ndarray, faces: np.ndarray, spacing: float) -> np.ndarray:
    """Points covering a triangle soup: every surface point lies within spacing / sqrt(2) of one.

    Per triangle, lines parallel to its longest edge `spacing` apart, each with points `spacing`
    apart from end to end (slivers cost their length, not their length squared).
    """
    tri = vertices[faces]
    edges = np.stack([tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 1], tri[:, 0] - tri[:, 2]], axis=1)
    lengths = np.linalg.norm(edges, axis=2)
    k = np.argmax(lengths, axis=1)
    rows = np.arange(len(tri))
    a, b, c = tri[rows, k], tri[rows, (k + 1) % 3], tri[rows, (k + 2) % 3]
    base = lengths[rows, k]
    ab = b - a
    area2 = np.linalg.norm(_cross(ab, c - a), axis=1)
    height = np.where(base > 0, area2 / np.where(base > 0, base, 1.0), 0.0)
    n_lines = np.ceil(height / spacing).astype(np.int64) + 1  # lines at v = j / (n_lines - 1), apex included
    line_tri = np.repeat(rows, n_lines)
    j = np.arange(len(line_tri)) - np.repeat(np.cumsum(n_lines) - n_lines, n_lines)
    v = np.where(n_lines[line_tri] > 1, j / np.maximum(n_lines[line_tri] - 1, 1), 0.0)
    start = a[line_tri] + v[:, None] * (c[line_tri] - a[line_tri])
    end = b[line_tri] + v[:, None] * (c[line_tri] - b[line_tri])
    n_pts = np.ceil((1 - v) * base[line_tri] / spacing).astype(np.int64) + 1
    pt_line = np.repeat(np.arange(len(line_tri)), n_pts)
    i = np.arange(len(pt_line)) - np.repeat(np.cumsum(n_pts) - n_pts, n_pts)
    t = np.where(n_pts[pt_line] > 1, i / np.maximum(n_pts[pt_line] - 1, 1), 0.0)
    return start[pt_line] + t[:, None] * (end[pt_line] - start[pt_line])


def _hull_points(points: np.ndarray, spacing: float, rng, cap: int = 20000) -> tuple[QHull, np.ndarray]:
    hull = QHull(points)
    area = float(hull.area)
    if area > 0 and area / spacing**2 > cap:
        spacing = float(np.sqrt(area / cap))
    return hull, _surface_points(hull.points, hull.faces, spacing, rng)


def _slice(vertices: np.ndarray, faces: np.ndarray, normal: np.ndarray, origin: np.ndarray):
    """The part of a mesh on the positive side of a plane (faces cut at the plane), or None."""
    try:
        out = trimesh.intersections.slice_faces_plane(vertices, faces, normal, origin)
    except Exception:  # a plane that misses the mesh, or degenerate cut triangles
        return None
    v, f = out[0], out[1]
    if f is None or len(f) == 0:
        return None
    return np.asarray(v, dtype=float), np.asarray(f, dtype=np.int64)


def _split_volume(points: np.ndarray, min_thickness: float) -> float:
    """Volume of a child's hull as it will be compiled (flat children thickened): the cut cost."""
    if len(points) < 4:
        return 0.0
    try:
        hull = QHull(points)
    except Exception:
        return 0.0
    return float(hull.volume) + 0.5 * min_thickness * float(hull.area)


def _covered(vertices: np.ndarray, faces: np.ndarray, hull: QHull | trimesh.Trimesh, tolerance: float) -> bool:
    """True if the piece's faces cover every facet plane of its hull (the hull is the piece itself)."""
    exact = isinstance(hull, trimesh.Trimesh)  # (the flat-plate test: trimesh's hull and exact box, as before)
    normals = np.asarray(hull.face_normals)
    offsets = np.einsum("ij,ij->i", normals, np.asarray(hull.triangles_center)) if exact else hull.offsets
    sign = np.where((normals[:, 0] < -1e-9) | ((np.abs(normals[:, 0]) <= 1e-9) & (normals[:, 1] < -1e-9)) |
                    ((np.abs(normals[:, 0]) <= 1e-9) & (np.abs(normals[:, 1]) <= 1e-9) & (normals[:, 2] < 0)), -1.0, 1.0)
    planes = np.column_stack([normals * sign[:, None], offsets * sign])
    key = np.round(planes / [1e-3, 1e-3, 1e-3, tolerance], 0)
    _, plane_of, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    plane_of = plane_of.reshape(-1)
    n_planes = int(plane_of.max()) + 1
    hull_area = np.bincount(plane_of, weights=np.asarray(hull.area_faces), minlength=n_planes)
    rep = np.zeros((n_planes, 4))
    rep[plane_of] = planes
    tri = vertices[faces]
    dist = np.abs(np.einsum("fvk,pk->fvp", tri, rep[:, :3]) - rep[None, None, :, 3]).max(axis=1)  # (faces, planes)
    on = dist <= tolerance
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    first = np.where(on.any(axis=1), on.argmax(axis=1), -1)
    covered = np.bincount(first[first >= 0], weights=area[first >= 0], minlength=n_planes)
    # The box (for `flat`) only matters when the coverage lies between half and all of the hull's area.
    if np.all(covered >= 0.995 * hull_area):
        return True
    if not np.all(covered >= 0.995 * (hull_area / 2)):
        return False
    box = oriented_box(np.asarray(hull.vertices)) if exact else fast_box(hull.vertices, hull)
    flat = float(np.min(box[2])) * 2 <= tolerance
    need = hull_area / 2 if flat else hull_area
    return bool(np.all(covered >= 0.995 * need))


def _caps(vertices: np.ndarray, faces: np.ndarray, size: float, width: float = 0.0, flat: float = 0.0) -> np.ndarray:
    """Fan triangles closing open boundaries no wider than `size` (an open tube end, a missing cap),
    and planar ones (within `flat`) narrower than `width` in one direction (a board's missing edge face)."""
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    uniq, counts = np.unique(edges, axis=0, return_counts=True)
    boundary = uniq[counts == 1]
    if not len(boundary):
        return np.zeros((0, 3, 3))
    used, local = np.unique(boundary, return_inverse=True)
    local = local.reshape(-1, 2)
    out = []
    for bv, be in pieces(vertices[used], np.column_stack([local, local[:, 1]])):
        centre = bv.mean(axis=0)
        close = float(np.linalg.norm(bv - centre, axis=1).max()) <= size
        if not close and width > 0 and len(bv) >= 3:
            _, _, vt = np.linalg.svd(bv - centre, full_matrices=False)
            local = (bv - centre) @ vt.T
            close = float(np.ptp(local[:, 2])) <= flat and float(np.ptp(local[:, 1])) <= width
        if close:
            out.append(np.stack([bv[be[:, 0]], bv[be[:, 1]], np.broadcast_to(centre, (len(be), 3))], axis=1))
    return np.concatenate(out) if out else np.zeros((0, 3, 3))


def split_decompose(
    vertices: np.ndarray,
    faces: np.ndarray,
    tolerance: float,
    min_thickness: float,
    max_hulls: int,
    min_size: float,
    fill_panels: float = 0.0,
    by_deviation: bool = False,
) -> tuple[list[np.ndarray], float]:
    """Cut one welded, connected, non-convex piece into convex point sets within `tolerance` (m).

    Returns the hull point sets and the largest estimated hull-to-surface distance that is left
    (above `tolerance` only where the hull budget `max_hulls` ran out). Open boundaries narrower than
    `cap` (an open tube end) count as closed. `fill_panels` > 0 keeps, as one solid, a piece no thicker
    than that whose vertices all lie on its hull: a board modelled by some of its faces only.
    Each cut is the one (across a box axis, at the middle or through the farthest hull point) whose
    children's hulls have the least volume, or with `by_deviation` the least deviation from the surface
    (ties: volume), which costs a measurement per candidate and follows bends and flares more closely.
    """
    import heapq

    rng = np.random.default_rng(0)
    hull0 = QHull(vertices)
    if _covered(vertices, faces, hull0, tolerance / 4):
        return [np.asarray(hull0.vertices)], 0.0
    box0 = fast_box(vertices, hull0)
    if fill_panels > 0:
        thickness = 2 * float(np.min(box0[2]))
        if min_thickness <= thickness <= fill_panels and _on_hull(vertices, hull0, tolerance):
            return [np.asarray(hull0.vertices)], 0.0
    caps = _caps(vertices, faces, max(fill_panels, 0.03), width=_CAP_WIDTH, flat=tolerance)
    # The surface as points within spacing / sqrt(2) of every surface point: a hull point's distance to
    # them exceeds its distance to the surface by at most that; where the surface is too large for
    # tolerance / 2 spacing (over _MAX_SURFACE_POINTS), the acceptance allows for the coarser cover.
    tri_v = np.vstack([vertices[faces]] + ([caps] if len(caps) else [])).reshape(-1, 3)
    tri_f = np.arange(len(tri_v)).reshape(-1, 3)
    if len(caps):
        # the caps become faces of the piece: a cut through a closed piece leaves closed children
        vertices, faces = weld(tri_v, tri_f, decimals=7)
    area = float(0.5 * np.linalg.norm(_cross(tri_v[1::3] - tri_v[0::3], tri_v[2::3] - tri_v[0::3]), axis=1).sum())
    spacing = max(tolerance / 2.0, float(np.sqrt(area / _MAX_SURFACE_POINTS)))
    tree = cKDTree(_grid_points(tri_v, tri_f, spacing))
    accept = tolerance + max(0.0, (spacing - tolerance / 2.0) / np.sqrt(2.0))
    axes = box0[1].T
    done: list[list] = []  # [pv, pf, hull, planes, shared samples, dev, far]
    heap: list = []
    counter = 0

    def measure(samples: np.ndarray) -> tuple[float, np.ndarray | None]:
        if not len(samples):
            return 0.0, None
        # within the tolerance the bounded query is all it takes; beyond it (the slow queries: a
        # far point has many surface points around it) a few hundred points give the worst one
        dist = tree.query(samples, distance_upper_bound=accept)[0]
        out = np.flatnonzero(~np.isfinite(dist))
        if len(out):
            out = out[::-(-len(out) // 256)]
            far_dist = tree.query(samples[out])[0]
            k = int(out[int(np.argmax(far_dist))])
            return float(far_dist.max()), samples[k]
        k = int(np.argmax(dist))
        return float(dist[k]), samples[k]

    def hull_samples(pv, planes, cap=1500):
        """The piece's hull and its surface points: those measured now, and those on a cut plane (shared
        with the hulls on the other side, measured where no other hull covers them)."""
        hull, samples = _hull_points(pv, tolerance, rng, cap=cap)
        # Hull facets on a cut plane are shared with the hull on the other side (inside the union of
        # the hulls, not its boundary): their points are measured where no hull on the other side
        # covers them (a cross-section whose hull spans a concavity or a gap).
        shared = np.zeros(len(samples), dtype=bool)
        for normal, offset in planes:
            side = 1.0 if float(np.median(pv @ normal)) >= offset else -1.0
            shared |= side * (samples @ normal - offset) <= _PLANE_EPS
        return hull, samples[~shared], samples[shared]

    def cut(pv, pf, planes, axis, c, a, b, cap=1500):
        """The pieces on both sides of a cut, each [pv, pf, hull, planes, shared, dev, far], and the
        largest deviation among them."""
        child_planes = planes + ((axis, c),)
        sides = []
        for cv, cf in (a, b):
            # the cross-sections closed again: the walls of a solid stay one piece, whose hull is solid
            wv, wf = weld(cv, cf, decimals=7)
            if len(wf):
                wv, wf = _close_section(wv, wf, axis, c)
            out = []
            for qv, qf in pieces(wv, wf) if len(wf) else []:
                if float(np.linalg.norm(np.ptp(qv, axis=0))) < min_size or len(qv) < 4:
                    continue
                try:
                    hull, free, shared = hull_samples(qv, child_planes, cap)
                except Exception:
                    continue
                out.append([qv, qf, hull, child_planes, shared, free])
            sides.append(out)
        recs, worst_child = [], 0.0
        for out in sides:
            for qv, qf, hull, cplanes, shared, free in out:
                dev, far = measure(free)
                recs.append([qv, qf, hull, cplanes, shared, dev, qv[0] if far is None else far])
                worst_child = max(worst_child, dev)
        return recs, worst_child

    def push(rec):
        nonlocal counter
        pv, pf, hull, planes, shared, dev, far = rec
        heapq.heappush(heap, (-dev, counter, pv, pf, hull, far, planes, shared))
        counter += 1

    def run() -> None:
        while heap:
            negdev, _, pv, pf, hull, far, planes, shared = heapq.heappop(heap)
            dev = -negdev
            if dev <= accept or len(done) + len(heap) + 2 > max_hulls:
                done.append([pv, pf, hull, planes, shared, dev, far])
                continue
            best = None
            # the surface point nearest the farthest hull point: the bottom of the concavity it bridges
            near = tree.data[tree.query(far)[1]]
            for axis in axes:
                t = pv @ axis
                lo, hi = float(t.min()), float(t.max())
                if hi - lo < 2 * min_size:
                    continue
                cuts = [lo + 0.5 * (hi - lo)]
                tk = float(far @ axis)
                if lo + 0.1 * (hi - lo) < tk < hi - 0.1 * (hi - lo):
                    cuts.append(tk)
                tn = float(near @ axis)
                if lo + min_size <= tn <= hi - min_size and all(abs(tn - c) > 1e-6 for c in cuts):
                    cuts.append(tn)
                for c in cuts:
                    origin = axis * c
                    a = _slice(pv, pf, axis, origin)
                    b = _slice(pv, pf, -axis, origin)
                    if a is None or b is None:
                        continue
                    cost = _split_volume(a[0], min_thickness) + _split_volume(b[0], min_thickness)
                    if by_deviation:  # the cut that leaves the smallest deviation (then volume), on fewer points
                        cost = (round(cut(pv, pf, planes, axis, c, a, b, _CANDIDATE_POINTS)[1] / (tolerance / 4)), cost)
                    if best is None or cost < best[0]:
                        best = (cost, a, b, (axis, c))
            if best is None:
                done.append([pv, pf, hull, planes, shared, dev, far])
                continue
            for rec in cut(pv, pf, planes, *best[3], best[1], best[2])[0]:
                push(rec)

    try:
        hull0s = hull_samples(vertices, ())
        dev0, far0 = measure(hull0s[1])
        push([vertices, faces, hull0s[0], (), hull0s[2], dev0, vertices[0] if far0 is None else far0])
    except Exception:
        return [np.asarray(hull0.vertices)], 0.0
    run()
    # Points on a cut plane that no other hull covers are on the boundary of the union: measure them,
    # and cut again the hulls they put beyond the tolerance (while the budget lasts).
    for _ in range(8):
        redo = []
        boxes = [(rec[2].vertices.min(axis=0) - 2 * _PLANE_EPS, rec[2].vertices.max(axis=0) + 2 * _PLANE_EPS)
                 for rec in done]
        for i, rec in enumerate(done):
            open_ = rec[4]
            for j, other in enumerate(done):
                if not len(open_):
                    break
                lo, hi = boxes[j]
                if j == i or np.any(open_.min(axis=0) > hi) or np.any(open_.max(axis=0) < lo):
                    continue
                h = other[2]
                open_ = open_[(open_ @ h.face_normals.T - h.offsets).max(axis=1) > 2 * _PLANE_EPS]
            dev, far = measure(open_)
            if dev > rec[5]:
                rec[5], rec[6] = dev, far
                if dev > accept:
                    redo.append(i)
        if not redo or len(done) + 1 > max_hulls:
            break
        for i in sorted(redo, reverse=True):
            push(done.pop(i))
        n_before = len(done) + len(heap)
        run()
        if len(done) <= n_before:  # nothing was cut again (the budget is spent)
            break
    worst = max((rec[5] for rec in done), default=0.0)
    return [np.asarray(rec[2].vertices) for rec in done], worst


def _close_section(vertices: np.ndarray, faces: np.ndarray, axis: np.ndarray, offset: float) -> tuple[np.ndarray, np.ndarray]:
    """Fan triangles over each connected run of open boundary edges that lies on the cut plane.

    They lie inside the hull of their own vertices (the piece's hull is unchanged) and keep the walls
    of a cut solid connected: without them a cut closed surface falls apart into open walls, each
    taken as its own thin hull, and the solid between them is lost."""
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    uniq, counts = np.unique(edges, axis=0, return_counts=True)
    boundary = uniq[counts == 1]
    if not len(boundary):
        return vertices, faces
    on = np.abs(vertices @ axis - offset) <= 1e-6
    boundary = boundary[on[boundary[:, 0]] & on[boundary[:, 1]]]
    if len(boundary) < 3:
        return vertices, faces
    used, local = np.unique(boundary, return_inverse=True)
    local = local.reshape(-1, 2)
    new_v, new_f = [vertices], [faces]
    n = len(vertices)
    for group_v, group_e, group_used in pieces(np.arange(len(used), dtype=float)[:, None].repeat(3, axis=1),
                                               np.column_stack([local, local[:, 1]]), return_index=True):
        if len(group_e) < 3:
            continue
        ids = used[group_used]
        centre = vertices[ids].mean(axis=0)
        new_v.append(centre[None])
        new_f.append(np.column_stack([ids[group_e[:, 0]], ids[group_e[:, 1]], np.full(len(group_e), n)]))
        n += 1
    return np.vstack(new_v), np.vstack(new_f)


def _on_hull(points: np.ndarray, hull: QHull, tolerance: float) -> bool:
    """True if every point lies within `tolerance` of the hull's boundary (none sits deep inside)."""
    normals = hull.face_normals
    offsets = hull.offsets
    depth = offsets[None, :] - points @ normals.T  # >= 0 inside, per facet plane
    return bool(np.all(depth.min(axis=1) <= tolerance))


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
        _coacd_rest(pv_all, pf_all, config, cache_dir, stats, hulls)
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
            if len(pv) < 4 or (flat and _covered(pv, pf, _hull(pv), tolerance / 4)):
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


def _coacd_rest(rv, rf, config, cache_dir, stats, hulls) -> None:
    """The former path: everything that is not convex in one CoACD run (config.decomposer == "coacd")."""
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


def mass_properties(hulls: list[Hull], density: float) -> tuple[float, np.ndarray, np.ndarray]:
    """Mass, centre of mass and inertia tensor (about the centre of mass) of a union of hulls."""
    total_mass = 0.0
    first_moment = np.zeros(3)
    second = np.zeros((3, 3))  # inertia about the origin
    for hull in hulls:
        if hull.box is not None:
            centre, rot, half = hull.box
            mass = density * 8.0 * float(np.prod(half))
            d = 2 * half
            local = mass / 12.0 * np.diag([d[1] ** 2 + d[2] ** 2, d[0] ** 2 + d[2] ** 2, d[0] ** 2 + d[1] ** 2])
            inertia_c = rot @ local @ rot.T
        else:
            mesh = _hull(hull.vertices)
            mesh.density = density
            mass = float(mesh.mass)
            centre = np.asarray(mesh.center_mass)
            inertia_c = np.asarray(mesh.moment_inertia)
        if mass <= 0:
            continue
        total_mass += mass
        first_moment += mass * centre
        second += inertia_c + mass * (np.dot(centre, centre) * np.eye(3) - np.outer(centre, centre))
    if total_mass <= 0:
        return 0.0, np.zeros(3), np.eye(3) * 1e-6
    com = first_moment / total_mass
    inertia = second - total_mass * (np.dot(com, com) * np.eye(3) - np.outer(com, com))
    return total_mass, com, inertia
