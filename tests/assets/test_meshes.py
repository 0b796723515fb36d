"""Mesh processing for real cabinets: the plane-split decomposition, the cheap oriented box, and the
physics check that opens the parts in front of a blocked drawer first."""

from __future__ import annotations

import mujoco
import numpy as np
import trimesh

from opend_mj.assets.checks import check_cabinet, drive_through_range
from opend_mj.assets.meshes import QHull, fast_box, split_decompose, weld


def _union(*boxes: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray]:
    mesh = trimesh.util.concatenate(boxes)
    return weld(np.asarray(mesh.vertices), np.asarray(mesh.faces))


def _box(extents, centre) -> trimesh.Trimesh:
    return trimesh.creation.box(extents=extents, transform=trimesh.transformations.translation_matrix(centre))


def _surface_distance(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    return trimesh.proximity.closest_point(trimesh.Trimesh(vertices, faces, process=False), points)[1]


def test_split_of_a_solid_l_shape_needs_few_hulls_and_follows_the_surface():
    """A closed L-shaped bracket (a knob's stand-off): a cut's faces are shared by the hulls on both
    sides: a few hulls within 1 mm do, the budget is not spent (when cut faces counted as surface, no
    hull of a solid piece could get within 1 mm and every piece took the whole budget)."""
    # a 60 x 16 x 16 mm bar and a 16 x 16 x 40 mm post, one closed surface soup (open where they meet)
    v, f = _union(_box([0.06, 0.016, 0.016], [0.0, 0.0, 0.0]), _box([0.016, 0.016, 0.04], [0.022, 0.0, 0.028]))
    hulls, worst = split_decompose(v, f, tolerance=0.001, min_thickness=0.004, max_hulls=16, min_size=0.004)
    assert len(hulls) <= 8, len(hulls)
    assert worst <= 0.0015
    # every hull stays within the L: its vertices lie inside the bar or the post (1 mm slack)
    for h in hulls:
        inside_bar = np.all(np.abs(h - [0.0, 0.0, 0.0]) <= [0.031, 0.009, 0.009], axis=1)
        inside_post = np.all(np.abs(h - [0.022, 0.0, 0.028]) <= [0.009, 0.009, 0.021], axis=1)
        assert np.all(inside_bar | inside_post)


def test_split_keeps_a_curved_bar_within_tolerance():
    """A U-shaped bar handle (a bent tube): hulls follow the bend within the tolerance."""
    path = np.array([[0, -0.06, 0], [0.02, -0.06, 0], [0.03, -0.05, 0], [0.03, 0.05, 0], [0.02, 0.06, 0],
                     [0, 0.06, 0]], dtype=float)
    from shapely.geometry import Point

    tube = trimesh.creation.sweep_polygon(Point(0, 0).buffer(0.005, 8), path)
    v, f = weld(np.asarray(tube.vertices), np.asarray(tube.faces))
    hulls, worst = split_decompose(v, f, tolerance=0.001, min_thickness=0.002, max_hulls=16, min_size=0.004)
    assert len(hulls) <= 16
    assert worst <= 0.0015
    # the gap between the bar's two legs (x < 0.02, |y| < 0.05) stays free of hulls beyond the tube
    probe = np.array([[0.0, y, 0.0] for y in np.linspace(-0.04, 0.04, 9)])
    for h in hulls:
        hull = QHull(h)
        inside = (probe @ hull.face_normals.T - hull.offsets).max(axis=1) < 0
        assert not inside.any()


def test_fast_box_is_exact_for_a_rotated_box_and_a_plate():
    rng = np.random.default_rng(0)
    rot = trimesh.transformations.random_rotation_matrix(rng.random(3))
    box = trimesh.creation.box(extents=[0.3, 0.02, 0.5], transform=rot)
    _, _, half = fast_box(np.asarray(box.vertices))
    assert np.allclose(np.sort(half), [0.01, 0.15, 0.25], atol=1e-9)
    plate = np.column_stack([rng.random(20) * 0.4, rng.random(20) * 0.2, np.zeros(20)])
    _, rot_p, half_p = fast_box(plate)
    assert np.min(half_p) < 1e-12 and abs(abs(rot_p[:, int(np.argmin(half_p))][2]) - 1) < 1e-9


_BLOCKED = """
<mujoco>
  <compiler angle="radian"/>
  <option timestep="0.002"/>
  <worldbody>
    <body name="carcass">
      <geom type="box" size="0.3 0.3 0.01" pos="0.3 0 0"/>
    </body>
    <body name="door" pos="0 -0.25 0.1">
      <joint name="door" type="hinge" axis="0 0 1" range="0 1.57" damping="1.5" frictionloss="60"/>
      <geom type="box" size="0.01 0.25 0.08" pos="0 0.25 0" mass="2"/>
    </body>
    <body name="drawer" pos="0.03 0 0.1">
      <joint name="drawer" type="slide" axis="-1 0 0" range="0 0.3" damping="8" frictionloss="2"/>
      <geom type="box" size="0.015 0.2 0.06" pos="0.005 0 0" mass="3"/>
    </body>
  </worldbody>
  <contact><exclude body1="carcass" body2="door"/><exclude body1="carcass" body2="drawer"/></contact>
</mujoco>
"""


def test_a_drawer_behind_a_door_is_checked_with_the_door_opened_first():
    """The drive pushes the closed door (too stiff for the drawer to push open) and the drawer stalls;
    the check opens the door it pushed
    (with the same physics, no teleporting) and the drawer then runs its full range."""
    model = mujoco.MjModel.from_xml_string(_BLOCKED)
    alone = drive_through_range(model, "drawer")
    assert alone.pushed == ["door"]
    check = check_cabinet(model)
    drawer = next(d for d in check.drives if d.joint == "drawer")
    assert drawer.opened_first == ["door"] and drawer.ok(), (alone, drawer)
    assert check.ok, check.failures


# --------------------------------------------------------------------------------------------------
# Handle pieces through `collision_hulls`: the hulls follow the handle's surface within 1 mm


def _hull_meshes(hulls) -> list[trimesh.Trimesh]:
    out = []
    for h in hulls:
        if h.box is not None:
            centre, rot, half = h.box
            corners = trimesh.creation.box(extents=2 * half).vertices @ rot.T + centre
            out.append(trimesh.convex.convex_hull(corners))
        else:
            out.append(trimesh.convex.convex_hull(h.vertices))
    return out


def _standoff(hulls, surface: trimesh.Trimesh) -> float:
    """Largest distance from the boundary of the union of the hulls to the surface (as the fidelity
    metric measures it: points inside another hull, or on a face shared with one, are not boundary)."""
    from opend_mj.assets.fidelity import _inside_any

    meshes = _hull_meshes(hulls)
    worst = 0.0
    for k, m in enumerate(meshes):
        pts, _ = trimesh.sample.sample_surface(m, 3000, seed=k)
        pts = np.vstack([pts, m.vertices])
        pts = pts[~_inside_any(pts, meshes, skip=k, tol=2e-5)]
        if len(pts):
            worst = max(worst, float(trimesh.proximity.closest_point(surface, pts)[1].max()))
    return worst


def _inside(points: np.ndarray, hulls) -> np.ndarray:
    from opend_mj.assets.fidelity import _inside_any

    return _inside_any(points, _hull_meshes(hulls))


def _c_bar(thickness: float = 0.012) -> trimesh.Trimesh:
    """A closed C-shaped bar handle: a 120 x 10 mm bar on two 25 mm posts (the door is at x = 35 mm)."""
    from shapely.geometry import Polygon

    u = Polygon([(0, 0), (0.035, 0), (0.035, 0.01), (0.01, 0.01), (0.01, 0.11), (0.035, 0.11), (0.035, 0.12),
                 (0, 0.12)])
    return trimesh.creation.extrude_polygon(u, thickness)


def test_a_bar_handle_keeps_its_gap_and_its_solid_within_1_mm():
    from opend_mj.assets.config import CompilerConfig
    from opend_mj.assets.meshes import DecompositionStats, collision_hulls

    bar = _c_bar()
    stats = DecompositionStats()
    hulls = collision_hulls(np.asarray(bar.vertices), np.asarray(bar.faces), CompilerConfig(), None, stats,
                            handle=True)
    assert stats.decomposed_pieces == 1 and len(hulls) <= 8, (stats, len(hulls))
    assert _standoff(hulls, bar) <= 0.001
    # the gap between bar and door is free for fingers; the bar and posts are solid
    gap = np.array([[x, y, 0.006] for x in (0.012, 0.02, 0.033) for y in (0.015, 0.06, 0.105)])
    assert not _inside(gap, hulls).any()
    solid = np.array([[0.005, 0.06, 0.006], [0.02, 0.005, 0.006], [0.02, 0.115, 0.006]])
    assert _inside(solid, hulls).all()


def test_a_handle_modelled_without_a_face_is_cut_as_a_solid():
    """The bar without the faces of its posts against the door (PartNet often leaves a hidden face out):
    the open faces are closed and every cut section too, so the hulls stay solid instead of falling
    apart into thin walls (which left the inside empty and stood off both sides of every wall)."""
    from opend_mj.assets.config import CompilerConfig
    from opend_mj.assets.meshes import collision_hulls

    bar = _c_bar()
    back = np.abs(bar.triangles_center[:, 0] - 0.035) < 1e-9
    assert back.sum() == 4
    v, f = weld(np.asarray(bar.vertices), np.asarray(bar.faces)[~back])
    hulls = collision_hulls(v, f, CompilerConfig(), None, handle=True)
    assert _standoff(hulls, bar) <= 0.001
    solid = np.array([[0.005, 0.06, 0.006], [0.02, 0.005, 0.006], [0.02, 0.115, 0.006]])
    assert _inside(solid, hulls).all()
    gap = np.array([[x, y, 0.006] for x in (0.012, 0.02, 0.033) for y in (0.015, 0.06, 0.105)])
    assert not _inside(gap, hulls).any()


def test_a_thin_handle_flange_stays_within_1_mm():
    """A 0.5 mm flange on a block: its hull is thickened to handle_split_thickness (1 mm), not to the
    4 mm of flat plates, so it stands 0.25 mm off each face instead of 1.75 mm."""
    from shapely.geometry import Polygon

    from opend_mj.assets.config import CompilerConfig
    from opend_mj.assets.meshes import collision_hulls

    shape = Polygon([(0, 0), (0.01, 0), (0.01, 0.01), (0.0005, 0.01), (0.0005, 0.04), (0, 0.04)])
    piece = trimesh.creation.extrude_polygon(shape, 0.02)
    hulls = collision_hulls(np.asarray(piece.vertices), np.asarray(piece.faces), CompilerConfig(), None,
                            handle=True)
    assert _standoff(hulls, piece) <= 0.001
