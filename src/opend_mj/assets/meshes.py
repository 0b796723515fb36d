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
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from opend_mj.assets.config import CoacdParams, CompilerConfig


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


def load_mesh_file(path: Path) -> list[tuple[trimesh.Trimesh, object]]:
    """Load an OBJ (or any trimesh format) as (mesh, visual) parts, one per material.

    Raises MeshError for missing, empty, NaN or degenerate meshes.
    """
    if not path.is_file():
        raise MeshError(f"{path}: mesh file is missing")
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


def pieces(vertices: np.ndarray, faces: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Split a welded mesh into vertex-connected pieces (robust to non-manifold edges)."""
    n = len(vertices)
    parent = np.arange(n)

    def find(i: int) -> int:
        root = i
        while parent[root] != root:
            root = parent[root]
        while parent[i] != root:
            parent[i], i = root, parent[i]
        return root

    for a, b, c in faces:
        ra, rb, rc = find(a), find(b), find(c)
        parent[rb] = ra
        parent[find(rc)] = ra
    roots = np.array([find(i) for i in range(n)])
    face_root = roots[faces[:, 0]]
    out = []
    for root in np.unique(face_root):
        f = faces[face_root == root]
        used, local = np.unique(f, return_inverse=True)
        out.append((vertices[used], local.reshape(-1, 3)))
    return out


def _hull(points: np.ndarray) -> trimesh.Trimesh:
    return trimesh.convex.convex_hull(points, qhull_options="QbB Pp QJ")


def oriented_box(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Minimum-volume-ish oriented box: (centre, rotation columns = box axes, half sizes)."""
    points = np.asarray(points, dtype=float)
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


def thicken(points: np.ndarray, min_thickness: float) -> np.ndarray:
    """Return hull points with a minimum extent of `min_thickness` along the thinnest box axis."""
    centre, rot, half = oriented_box(points)
    axis = int(np.argmin(half))
    if 2 * half[axis] >= min_thickness:
        return points
    normal = rot[:, axis]
    local = (points - centre) @ normal
    flat = points - np.outer(local, normal)
    offset = 0.5 * min_thickness * normal
    return np.vstack([flat + offset, flat - offset])


def to_hull(points: np.ndarray, config: CompilerConfig) -> Hull | None:
    """Make one collision hull from a point set: thickened, and a box primitive when box-shaped."""
    if len(points) < 3:
        return None
    if float(np.linalg.norm(np.ptp(points, axis=0))) < config.min_piece_size:
        return None
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


def collision_hulls(
    vertices: np.ndarray,
    faces: np.ndarray,
    config: CompilerConfig,
    cache_dir: Path | None,
    stats: DecompositionStats | None = None,
) -> list[Hull]:
    """Convex collision hulls for one merged mesh (a link's body or one handle)."""
    stats = stats if stats is not None else DecompositionStats()
    hulls: list[Hull] = []
    rest_v: list[np.ndarray] = []
    rest_f: list[np.ndarray] = []
    offset = 0

    def classify(pv: np.ndarray, pf: np.ndarray, allow_flat: bool = True) -> bool:
        """Keep a piece as one hull if it is convex (or flat); return False if it is not."""
        size = float(np.linalg.norm(np.ptp(pv, axis=0)))
        if size < config.min_piece_size:
            stats.dropped_pieces += 1
            return True
        _, _, half = oriented_box(pv)
        flat = 2 * float(np.min(half)) < config.min_thickness
        if flat and not allow_flat:
            return False
        if not (flat or is_convex_piece(pv, pf, config.convex_tolerance)):
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
    pool_offset = 0
    for raw_v, raw_f in pieces(vertices, faces):
        pv, pf = weld(raw_v, raw_f)
        if len(pf) >= 4 and classify(pv, pf, allow_flat=False):
            continue
        pool_v.append(raw_v)
        pool_f.append(raw_f + pool_offset)
        pool_offset += len(raw_v)
    # Pass 2: what is left (surface soups with split vertices) is welded as a whole and split again.
    if pool_v:
        wv, wf = weld(np.vstack(pool_v), np.vstack(pool_f))
        for pv, pf in pieces(wv, wf):
            if classify(pv, pf):
                continue
            rest_v.append(pv)
            rest_f.append(pf + offset)
            offset += len(pv)
    if rest_v:
        rv, rf = np.vstack(rest_v), np.vstack(rest_f)
        stats.decomposed_pieces += len(rest_v)
        for points in coacd_decompose(rv, rf, config.coacd, cache_dir):
            hull = to_hull(points, config)
            if hull is not None:
                hulls.append(hull)
                stats.coacd_hulls += 1
    return hulls


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
