"""How closely a compiled cabinet's collision geometry follows its visual surface.

`cabinet_fidelity(source_dir, cabinet_dir, config)` reads the source (world frame, metres, every joint
at 0) and the compiled `cabinet.xml` (MuJoCo, at qpos0, i.e. the same pose) and measures, per class
(handle meshes / everything else), on points sampled evenly by area:

- visual -> collision: distance from a visual surface point to the union of the part's collision
  geoms of that class (0 inside a geom): where the collision geometry misses the surface;
- collision -> visual: distance from a point on the boundary of that union (points inside another
  geom of the same part, or on a face it shares with one, are not on the boundary) to the visual surface of the class: where the
  collision geometry stands off the surface (thickened plates, hulls bridging a concavity);

the same from the front, where a finger or a camera meets the surface: rays along +x over each part's
footprint (1 cm apart, 50 x 50 at most; 2 mm apart over a handle); per ray, the larger of the distance
from the first collision hit to the visual surface and from the first visual hit to the collision
geoms, by the class of the visual surface hit (handle, door/drawer front, carcass: a hull closing a
carcass opening shows here); median, p99 and the share of rays within 1 / 2 mm;

and, per part with a handle, the bar-to-panel gap: rays along +x (into the cabinet, whose front faces
-x) over the handle's footprint; on each ray the free distance between the back of the handle and the
next surface of the part; the largest over the rays is the gap a finger can enter, for the visual
meshes and for the collision geoms.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import trimesh

from opend_mj.assets.config import CompilerConfig
from opend_mj.assets.sources import read_source


def _geom_mesh(model: mujoco.MjModel, data: mujoco.MjData, g: int) -> trimesh.Trimesh:
    """A collision geom as a convex triangle mesh in the world frame."""
    kind = int(model.geom_type[g])
    if kind == int(mujoco.mjtGeom.mjGEOM_BOX):
        local = trimesh.creation.box(extents=2 * model.geom_size[g])
        verts = np.asarray(local.vertices)
    elif kind == int(mujoco.mjtGeom.mjGEOM_MESH):
        m = int(model.geom_dataid[g])
        a, n = int(model.mesh_vertadr[m]), int(model.mesh_vertnum[m])
        verts = np.asarray(model.mesh_vert[a:a + n], dtype=float)
    else:
        raise ValueError(f"geom {g}: unexpected collision geom type {kind}")
    world = verts @ data.geom_xmat[g].reshape(3, 3).T + data.geom_xpos[g]
    return trimesh.convex.convex_hull(world)


def _inside_any(points: np.ndarray, hulls: list[trimesh.Trimesh], skip: int = -1, tol: float = 0.0) -> np.ndarray:
    """Points inside at least one hull or within `tol` outside its faces, hull `skip` left out."""
    inside = np.zeros(len(points), dtype=bool)
    for k, h in enumerate(hulls):
        if k == skip or not len(points):
            continue
        normals = np.asarray(h.face_normals)
        offsets = np.einsum("ij,ij->i", normals, np.asarray(h.triangles_center))
        inside |= (points @ normals.T - offsets).max(axis=1) < tol
    return inside


def _sample(mesh: trimesh.Trimesh, count: int, rng) -> np.ndarray:
    if count <= 0 or mesh.area <= 0:
        return np.zeros((0, 3))
    pts, _ = trimesh.sample.sample_surface(mesh, count, seed=int(rng.integers(1 << 31)))
    return np.asarray(pts)


def _distance(points: np.ndarray, mesh: trimesh.Trimesh) -> np.ndarray:
    if not len(points):
        return np.zeros(0)
    _, dist, _ = trimesh.proximity.closest_point(mesh, points)
    return np.asarray(dist)


def _concat(meshes: list[trimesh.Trimesh]) -> trimesh.Trimesh | None:
    meshes = [m for m in meshes if len(m.faces)]
    return trimesh.util.concatenate(meshes) if meshes else None


def _visual_mesh(pieces) -> trimesh.Trimesh | None:
    if not pieces:
        return None
    return trimesh.Trimesh(np.vstack([p.vertices for p in pieces]),
                           np.vstack([p.faces + o for p, o in zip(pieces, np.cumsum([0] + [len(p.vertices) for p in pieces])[:-1])]),
                           process=False)


def _ray_hits(mesh: trimesh.Trimesh, origins: np.ndarray) -> list[np.ndarray]:
    """x of every crossing of each +x ray with the mesh."""
    dirs = np.tile([1.0, 0.0, 0.0], (len(origins), 1))
    locs, ray_idx, _ = trimesh.ray.ray_triangle.RayMeshIntersector(mesh).intersects_location(
        origins, dirs, multiple_hits=True)
    out = [[] for _ in range(len(origins))]
    for x, r in zip(locs[:, 0], ray_idx):
        out[r].append(x)
    return [np.sort(np.array(v)) for v in out]


def _bar_gap(handle: trimesh.Trimesh, panel: trimesh.Trimesh | None, box: tuple[np.ndarray, np.ndarray],
             spacing: float = 0.001, max_rays: int = 40) -> float | None:
    """The largest free distance along +x between the back of the handle and the panel behind it."""
    if panel is None:
        return None
    lo, hi = box
    ny = int(np.clip((hi[1] - lo[1]) / spacing, 2, max_rays))
    nz = int(np.clip((hi[2] - lo[2]) / spacing, 2, max_rays))
    ys, zs = np.linspace(lo[1], hi[1], ny + 2)[1:-1], np.linspace(lo[2], hi[2], nz + 2)[1:-1]
    yy, zz = np.meshgrid(ys, zs)
    origins = np.column_stack([np.full(yy.size, lo[0] - 0.05), yy.ravel(), zz.ravel()])
    h_hits, p_hits = _ray_hits(handle, origins), _ray_hits(panel, origins)
    best = None
    for hh, ph in zip(h_hits, p_hits):
        if not len(hh):
            continue
        back = hh.max()
        behind = ph[ph >= back - 1e-5]
        if not len(behind):
            continue
        gap = max(float(behind.min() - back), 0.0)
        best = gap if best is None else max(best, gap)
    return best


def _first_hits(mesh: trimesh.Trimesh | None, origins: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """x of the first +x hit of each ray (inf where none) and the triangle it hits (-1 where none)."""
    x, tri = np.full(len(origins), np.inf), np.full(len(origins), -1)
    if mesh is None or not len(origins):
        return x, tri
    dirs = np.tile([1.0, 0.0, 0.0], (len(origins), 1))
    locs, rays, tris = trimesh.ray.ray_triangle.RayMeshIntersector(mesh).intersects_location(
        origins, dirs, multiple_hits=False)
    x[rays], tri[rays] = locs[:, 0], tris
    return x, tri


def _front_rays(vis_parts: tuple[trimesh.Trimesh, int], hulls: list[trimesh.Trimesh], spacing: float,
                max_rays: int = 50, box=None) -> dict[str, np.ndarray]:
    """Front-ray deviations of one part: `vis_parts` is (visual mesh, number of handle faces, which come
    first); rays over `box` (default the mesh's bounds). Per ray: the larger of the distance from the
    collision hit to the visual surface and from the visual hit to the collision geoms (0 inside one), so
    that a ray grazing a thickened plate counts the thickening, not the depth behind the plate."""
    vis, n_handle = vis_parts
    col = _concat(hulls)
    lo, hi = vis.bounds if box is None else box
    ny = int(np.clip((hi[1] - lo[1]) / spacing, 1, max_rays))
    nz = int(np.clip((hi[2] - lo[2]) / spacing, 1, max_rays))
    ys, zs = np.linspace(lo[1], hi[1], ny + 2)[1:-1], np.linspace(lo[2], hi[2], nz + 2)[1:-1]
    yy, zz = np.meshgrid(ys, zs)
    origins = np.column_stack([np.full(yy.size, lo[0] - 0.05), yy.ravel(), zz.ravel()])
    xv, tv = _first_hits(vis, origins)
    xc, _ = _first_hits(col, origins)
    seen = np.isfinite(xv)
    dev = np.zeros(len(origins))
    hv = seen.copy()
    if col is None:
        dev[hv] = np.inf
    elif hv.any():
        pv = origins[hv] + np.outer(xv[hv] - origins[hv, 0], [1.0, 0.0, 0.0])
        d = _distance(pv, col)
        d[_inside_any(pv, hulls)] = 0.0
        dev[hv] = d
    hc = seen & np.isfinite(xc)
    if hc.any():
        pc = origins[hc] + np.outer(xc[hc] - origins[hc, 0], [1.0, 0.0, 0.0])
        dev[hc] = np.maximum(dev[hc], _distance(pc, vis))
    dev = dev[seen]
    is_handle = (tv[seen] < n_handle)
    return {"handle": dev[is_handle], "rest": dev[~is_handle]}


def cabinet_fidelity(source_dir: Path, cabinet_dir: Path, config: CompilerConfig = CompilerConfig(),
                     handle_samples: int = 2000, rest_samples: int = 4000, front_spacing: float = 0.01,
                     seed: int = 0) -> dict:
    """Fidelity figures of one compiled cabinet (metres); see the module docstring."""
    rng = np.random.default_rng(seed)
    source = read_source(Path(source_dir), config.scale, config.max_mesh_faces)
    model = mujoco.MjModel.from_xml_path(str(Path(cabinet_dir) / "cabinet.xml"))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)

    per_class = {"handle": {"v2c": [], "c2v": []}, "rest": {"v2c": [], "c2v": []}}
    visuals, collisions = {}, {}
    for part in source.parts:
        b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, part.name)
        geoms = [g for g in range(model.ngeom) if model.geom_bodyid[g] == b
                 and (model.geom_contype[g] or model.geom_conaffinity[g])]
        names = {g: mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or "" for g in geoms}
        cls_geoms = {"handle": [g for g in geoms if names[g].startswith("handle_")],
                     "rest": [g for g in geoms if not names[g].startswith("handle_")]}
        cls_vis = {"handle": _visual_mesh(part.handles),
                   "rest": _visual_mesh([v for v in part.visuals if not v.is_handle])}
        for cls in ("handle", "rest"):
            vis = cls_vis[cls]
            hulls = [_geom_mesh(model, data, g) for g in cls_geoms[cls]]
            visuals[(part.name, cls)], collisions[(part.name, cls)] = vis, hulls
            if vis is None:
                continue
            total = handle_samples if cls == "handle" else rest_samples
            pts = _sample(vis, max(200, int(total * min(1.0, vis.area / max(_area(source, cls), 1e-12)))), rng)
            col = _concat(hulls)
            if col is None:
                per_class[cls]["v2c"].append(np.full(len(pts), np.inf))
                continue
            d = _distance(pts, col)
            d[_inside_any(pts, hulls)] = 0.0
            per_class[cls]["v2c"].append(d)
            boundary = []
            for k, h in enumerate(hulls):
                hp = _sample(h, max(20, int(len(pts) * 0.5 * h.area / max(vis.area, 1e-12))), rng)
                # points on a face shared with a neighbour (a cut plane) are inside the union too
                boundary.append(hp[~_inside_any(hp, hulls, skip=k, tol=2e-5)])
            per_class[cls]["c2v"].append(_distance(np.vstack(boundary), vis))

    result: dict = {}
    for cls, d in per_class.items():
        v2c = np.concatenate(d["v2c"]) if d["v2c"] else np.zeros(0)
        c2v = np.concatenate(d["c2v"]) if d["c2v"] else np.zeros(0)
        fin = v2c[np.isfinite(v2c)]
        result[cls] = {
            "vis_to_col_max": float(v2c.max()) if len(v2c) else None,
            "vis_to_col_p99": float(np.percentile(v2c, 99)) if len(v2c) else None,
            "col_to_vis_max": float(c2v.max()) if len(c2v) else None,
            "col_to_vis_p99": float(np.percentile(c2v, 99)) if len(c2v) else None,
            "uncovered": int((~np.isfinite(v2c)).sum()),
            "samples": int(len(v2c) + len(c2v)),
        }
        result[cls]["max"] = float(max([x for x in (fin.max() if len(fin) else None,
                                                     result[cls]["col_to_vis_max"]) if x is not None], default=0.0))
    front = {"handle": [], "front": [], "carcass": []}
    for part in source.parts:
        handles = [v for v in part.visuals if v.is_handle]
        rest = [v for v in part.visuals if not v.is_handle]
        vis = _visual_mesh(handles + rest)
        if vis is None:
            continue
        n_handle = int(sum(len(v.faces) for v in handles))
        hulls = collisions[(part.name, "handle")] + collisions[(part.name, "rest")]
        dev = _front_rays((vis, n_handle), hulls, front_spacing)
        front["handle"].append(dev["handle"])
        if handles:  # a finer grid over the handles' own footprint
            hb = _visual_mesh(handles).bounds
            front["handle"].append(_front_rays((vis, n_handle), hulls, 0.002, box=hb, max_rays=40)["handle"])
        front["carcass" if part.joint is None else "front"].append(dev["rest"])
    result["front_rays"] = {}
    for cls, devs in front.items():
        d = np.concatenate(devs) if devs else np.zeros(0)
        result["front_rays"][cls] = {
            "rays": int(len(d)),
            "p50": float(np.median(d)) if len(d) else None,
            "p99": float(np.percentile(d, 99)) if len(d) else None,
            "within_1mm": float((d <= 0.001 + 1e-5).mean()) if len(d) else None,
            "within_2mm": float((d <= 0.002 + 1e-5).mean()) if len(d) else None,
        }
    gaps = []
    for part in source.parts:
        hv, pv = visuals.get((part.name, "handle")), visuals.get((part.name, "rest"))
        if hv is None:
            continue
        hc, pc = _concat(collisions[(part.name, "handle")]), _concat(collisions[(part.name, "rest")])
        box = (hv.bounds[0], hv.bounds[1])
        g_vis = _bar_gap(hv, pv, box)
        g_col = _bar_gap(hc, pc, box) if hc is not None else None
        gaps.append({"link": part.name, "visual": g_vis, "collision": g_col})
    result["bar_gaps"] = gaps
    kept = [g for g in gaps if g["visual"] is not None and g["visual"] >= 0.005]
    result["min_bar_gap_visual"] = min((g["visual"] for g in kept), default=None)
    result["min_bar_gap_collision"] = min(((g["collision"] or 0.0) for g in kept), default=None)
    return result


def _area(source, cls: str) -> float:
    total = 0.0
    for part in source.parts:
        for v in part.visuals:
            if v.is_handle == (cls == "handle"):
                tri = v.vertices[v.faces]
                total += 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum()
    return total
