"""Does the open hand fit between the floor and the door at a grasp pose? The hand's own shape
(its collision geoms in the grasp-site frame, from its model ``hands/<name>/hand.xml``, with the
fingers at a given pose) against two planes the planner knows: the floor (z = 0, where the room
stands) and the panel the handle stands on (seen in depth).

A pose "clears" when every collision geom of the hand stays ``margin`` (m) above the floor and
``margin`` in front of the panel. The planner uses it to choose how a hand comes at a handle close
to the floor and to its door (:meth:`~opend_mj.policy.planner.grasp.Grasping.choose_grasp`):
the Franka gripper's body is 20 cm long across a horizontal bar, so a bar 4 cm above the floor
and 2-3 cm off its door is taken from above, its fingers one in front of the bar and one behind it.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from opend_mj.transforms import quat_to_mat

#: world z of the floor every room stands on (m)
FLOOR_Z = 0.0


class HandOutline:
    """A hand's collision geoms in its grasp-site frame at one finger pose: each geom as a centre,
    an orientation and a support rule, so that the farthest point of the hand along any direction
    (its support) is exact for boxes, spheres and capsules (other shapes: their bounding box)."""

    def __init__(self, xml_path: str, site: str, joint_names: tuple, fingers: tuple):
        import mujoco

        model = mujoco.MjModel.from_xml_path(str(xml_path))
        data = mujoco.MjData(model)
        for name, q in zip(joint_names, fingers):
            data.qpos[model.jnt_qposadr[model.joint(name).id]] = q
        mujoco.mj_kinematics(model, data)
        sid = model.site(site).id
        s_pos, s_mat = data.site_xpos[sid].copy(), data.site_xmat[sid].reshape(3, 3).copy()
        self.centres, self.axes, self.half, self.radius, self.segment = [], [], [], [], []
        for g in range(model.ngeom):
            if model.geom_contype[g] == 0 and model.geom_conaffinity[g] == 0:
                continue  # visual only
            mat = s_mat.T @ data.geom_xmat[g].reshape(3, 3)
            centre = s_mat.T @ (data.geom_xpos[g] - s_pos)
            gtype, size = int(model.geom_type[g]), model.geom_size[g]
            half, radius, segment = np.zeros(3), 0.0, 0.0
            if gtype == mujoco.mjtGeom.mjGEOM_BOX:
                half = size.copy()
            elif gtype == mujoco.mjtGeom.mjGEOM_SPHERE:
                radius = float(size[0])
            elif gtype == mujoco.mjtGeom.mjGEOM_CAPSULE:
                radius, segment = float(size[0]), float(size[1])
            else:  # cylinders, ellipsoids, meshes: their local bounding box
                aabb = model.geom_aabb[g]
                centre = centre + mat @ aabb[:3]
                half = aabb[3:].copy()
            self.centres.append(centre)
            self.axes.append(mat)
            self.half.append(half)
            self.radius.append(radius)
            self.segment.append(segment)
        self.centres = np.array(self.centres)
        self.axes = np.array(self.axes)
        self.half = np.array(self.half)
        self.radius = np.array(self.radius)
        self.segment = np.array(self.segment)

    def support(self, direction) -> float:
        """The largest ``direction . p`` (m) over the hand's points ``p`` (site frame)."""
        d = np.asarray(direction, float)
        local = np.einsum("gij,i->gj", self.axes, d)  # the direction in each geom's frame
        reach = (np.abs(local) * self.half).sum(axis=1) + self.radius + self.segment * np.abs(local[:, 2])
        return float(np.max(self.centres @ d + reach))


@lru_cache(maxsize=64)
def hand_outline(xml_path: str, site: str, joint_names: tuple, fingers: tuple) -> HandOutline:
    """A cached :class:`HandOutline` (fingers rounded by the caller)."""
    return HandOutline(xml_path, site, joint_names, fingers)


def outline_for(spec, fingers) -> HandOutline:
    """The outline of the hand ``spec`` names, its fingers at ``fingers`` (joint units)."""
    from opend_mj.sim.hands import get_hand

    entry = get_hand(spec.name)
    return hand_outline(str(entry.xml_path), spec.grasp_site, tuple(spec.joint_names),
                        tuple(round(float(q), 4) for q in fingers))


def clearances(outline: HandOutline, pos, quat, panel_x: float) -> tuple[float, float]:
    """(height of the hand's lowest point above the floor, distance of its point nearest the panel
    in front of the panel), m, with the grasp site at ``pos`` and orientation ``quat`` (world)."""
    rot = quat_to_mat(np.asarray(quat, float))  # site axes in world columns
    pos = np.asarray(pos, float)
    lowest = pos[2] - outline.support(rot.T @ np.array([0.0, 0.0, -1.0]))
    nearest = panel_x - (pos[0] + outline.support(rot.T @ np.array([1.0, 0.0, 0.0])))
    return float(lowest - FLOOR_Z), float(nearest)
