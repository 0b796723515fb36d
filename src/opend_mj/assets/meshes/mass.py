"""Mass properties of a union of collision hulls (uniform density)."""

from __future__ import annotations

import numpy as np

from opend_mj.assets.meshes.geometry import Hull, trimesh_hull


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
            mesh = trimesh_hull(hull.vertices)
            mesh.density = density
            # trimesh divides by the volume for the centre of mass even when it is 0 (a flat hull):
            # that centre is never used (the hull is skipped below), so its warning says nothing
            with np.errstate(divide="ignore", invalid="ignore"):
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
