"""Hull primitives: welding and connected pieces, convex hulls (qhull), oriented boxes, convexity,
thickening, and one collision `Hull` (a box primitive or a vertex cloud) from a point set."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from opend_mj.assets.config import CompilerConfig


@dataclass
class Hull:
    """One convex collision piece in body coordinates: a box primitive or a vertex cloud."""

    vertices: np.ndarray  # (n, 3) hull vertices (the hull of these is the shape)
    box: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # centre, rotation (3x3), half sizes

    @property
    def volume(self) -> float:
        if self.box is not None:
            return float(8.0 * np.prod(self.box[2]))
        return float(trimesh_hull(self.vertices).volume)


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


def trimesh_hull(points: np.ndarray) -> trimesh.Trimesh:
    """trimesh's convex hull of a point set (exact volume, area and mass properties).

    trimesh checks the hull's orientation by its volume, and computes a centre of mass with it that
    divides by 0 for a flat hull; that centre is never used, so numpy's warning is silenced here."""
    with np.errstate(divide="ignore", invalid="ignore"):
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
        cross = row_cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
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


def row_cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
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
    e_all = row_cross(n_all, d_all)
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
        hull = trimesh_hull(vertices)
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
        hull = trimesh_hull(points)
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
