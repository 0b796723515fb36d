"""A hand's description (``hands/<name>/spec.json``) and the grasp-site <-> root pose helpers.

Pure numpy: importing it loads no simulator."""

from __future__ import annotations

import dataclasses
import functools
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from opend_mj.transforms import mat_to_quat, quat_to_mat


# --------------------------------------------------------------------------------------------------
# Spec
# --------------------------------------------------------------------------------------------------
@dataclass
class HandSpec:
    """Everything a task or planner needs to know about a hand, saved as ``spec.json``."""

    name: str
    dof: int
    joint_names: list[str]
    actuator_names: list[str]
    open_pose: list[float]
    grasp_profiles: dict[str, list[float]]
    grasp_site: str = "grasp_site"
    root_body: str = "palm"
    #: grasp-site pose in the root-body frame (position, quaternion w x y z).
    grasp_site_pos: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    grasp_site_quat: list[float] = field(default_factory=lambda: [1.0, 0.0, 0.0, 0.0])
    pregrasp_profiles: dict[str, list[float]] = field(default_factory=dict)
    joint_ranges: dict[str, list[float]] = field(default_factory=dict)
    joint_roles: dict[str, str] = field(default_factory=dict)
    hand_type: str = "dexterous"
    #: touch sensors (MuJoCo ``touch``: normal force inside a site around a finger or palm geom),
    #: sensor name -> the part it belongs to (``palm``, ``thumb``, a finger name)
    touch_sensors: dict[str, str] = field(default_factory=dict)
    #: extra distance (m) along the approach axis to stop short of the handle (0: site at centre).
    approach_offset: float = 0.0
    #: seconds to ramp from open to closed targets.
    close_time: float = 0.5
    mass: float = 0.0
    convention: str = ""
    notes: str = ""
    #: the hand's name in tables and pages ("Franka gripper"); empty: its ``name``
    title: str = ""
    #: where the hand comes in listings (the registry, tables, ``make results``): by ``order``, then
    #: by name; a hand without one comes after those that have one
    order: int | None = None

    def __post_init__(self) -> None:
        if self.dof != len(self.joint_names) or self.dof != len(self.actuator_names):
            raise ValueError(f"hand {self.name!r}: dof {self.dof} does not match "
                             f"{len(self.joint_names)} joints / {len(self.actuator_names)} actuators")
        for key in ("horizontal", "vertical"):
            if key not in self.grasp_profiles:
                raise ValueError(f"hand {self.name!r}: grasp_profiles needs {key!r}")
        for key, prof in list(self.grasp_profiles.items()) + list(self.pregrasp_profiles.items()):
            if len(prof) != len(self.actuator_names):
                raise ValueError(f"hand {self.name!r}: profile {key!r} has {len(prof)} targets, "
                                 f"expected {len(self.actuator_names)}")
        if len(self.open_pose) != len(self.actuator_names):
            raise ValueError(f"hand {self.name!r}: open_pose has wrong length")

    @property
    def display_title(self) -> str:
        """``title``, else ``name``."""
        return self.title or self.name

    def grasp_profile(self, orientation: str) -> np.ndarray:
        return np.asarray(self.grasp_profiles[orientation], dtype=float)

    def pregrasp_profile(self, orientation: str) -> np.ndarray:
        return np.asarray(self.pregrasp_profiles.get(orientation, self.open_pose), dtype=float)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "HandSpec":
        """A spec from its JSON form; an unknown key is an error (keys starting with ``_`` are notes)."""
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(k for k in data if k not in names and not k.startswith("_"))
        if unknown:
            raise ValueError(f"unknown key {unknown[0]!r} (known: {', '.join(sorted(names))})")
        return cls(**{k: v for k, v in data.items() if k in names})

    def save(self, path: str | os.PathLike) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=2) + "\n")

    @classmethod
    def load(cls, path: str | os.PathLike) -> "HandSpec":
        """Read ``path`` (``spec.json``); a clear error naming the file where it is not a valid spec."""
        from opend_mj.sim.hands.settings import read_json_object

        data = read_json_object(path, "spec")
        try:
            return cls.from_dict(data)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{path}: {exc}") from exc




def orientation_for_handle(orientation: str, approach=(1.0, 0.0, 0.0)) -> np.ndarray:
    """Grasp-site quaternion for a handle approached along ``approach`` (default +x world).

    horizontal: site x (handle axis) = horizontal, perpendicular to the approach (+y world for the
    default approach), so the open fingers point up (+z world).
    vertical: site x = -z world, so the open fingers point to the +y side.
    """
    z = np.asarray(approach, dtype=float)
    z /= np.linalg.norm(z)
    if orientation == "horizontal":
        x = np.cross((0.0, 0.0, 1.0), z)
        if np.linalg.norm(x) < 1e-6:
            raise ValueError("horizontal handle needs a non-vertical approach")
    elif orientation == "vertical":
        x = np.array([0.0, 0.0, -1.0])
        x = x - z * (x @ z)
        if np.linalg.norm(x) < 1e-6:
            raise ValueError("vertical handle needs a non-vertical approach")
    else:
        raise ValueError(f"orientation must be 'horizontal' or 'vertical', not {orientation!r}")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return mat_to_quat(np.column_stack([x, y, z]))


@functools.lru_cache(maxsize=64)
def _site_offset_rotation_t(grasp_site_quat: tuple) -> np.ndarray:
    """Transpose of the site's rotation in the root frame (read-only; cached per hand)."""
    r = quat_to_mat(grasp_site_quat).T.copy()
    r.flags.writeable = False
    return r


def grasp_pose_to_root_pose(spec: HandSpec, site_pos, site_quat) -> tuple[np.ndarray, np.ndarray]:
    """Root (= mocap) pose that puts the grasp site at ``site_pos`` with orientation ``site_quat``."""
    r_site = quat_to_mat(site_quat)
    r_root = r_site @ _site_offset_rotation_t(tuple(float(x) for x in spec.grasp_site_quat))
    root_pos = np.asarray(site_pos, float) - r_root @ np.asarray(spec.grasp_site_pos, float)
    return root_pos, mat_to_quat(r_root)


def root_pose_to_grasp_pose(spec: HandSpec, root_pos, root_quat) -> tuple[np.ndarray, np.ndarray]:
    r_root = quat_to_mat(root_quat)
    pos = np.asarray(root_pos, float) + r_root @ np.asarray(spec.grasp_site_pos, float)
    return pos, mat_to_quat(r_root @ quat_to_mat(spec.grasp_site_quat))

