"""Plane-split decomposition of non-convex pieces (the default decomposer).

A piece whose convex hull strays from its own surface by more than a tolerance is cut by a plane
(across one of its box axes, where the children's hulls are smallest), the halves are split into
connected pieces, and each is cut again until every hull lies within the tolerance of the surface
(or a hull budget is spent). Distances are measured against points sampled on the piece's surface
(a k-d tree), so the check is cheap; the sampling makes it err on the side of cutting more.
"""

from __future__ import annotations

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from opend_mj.assets.meshes.geometry import QHull, fast_box, oriented_box, pieces, row_cross, weld


#: Planar holes narrower than this (m) count as closed in the splitter (a board or a knob modelled
#: without its hidden face); wider ones (a carcass opening) stay open.
_CAP_WIDTH = 0.05

#: Most surface points the splitter measures a piece's hulls against (its spacing grows beyond).
_MAX_SURFACE_POINTS = 150000


#: Surface points per hull when the splitter compares candidate cuts by deviation (1500 for the hulls kept).
_CANDIDATE_POINTS = 600

#: Points this close (m) to a cut plane lie on the face shared by the hulls on both sides of it.
_PLANE_EPS = 1e-5


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
    area2 = np.linalg.norm(row_cross(ab, c - a), axis=1)
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


def covers_hull(vertices: np.ndarray, faces: np.ndarray, hull: QHull | trimesh.Trimesh, tolerance: float) -> bool:
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
    if covers_hull(vertices, faces, hull0, tolerance / 4):
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
    area = float(0.5 * np.linalg.norm(row_cross(tri_v[1::3] - tri_v[0::3], tri_v[2::3] - tri_v[0::3]), axis=1).sum())
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
