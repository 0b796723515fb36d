"""A compiled cabinet as a dm_control Entity, and the open-ratio rules of the success checker."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from dm_control import composer, mjcf

from opend_mj.assets.layout import CABINET_JSON, CABINET_XML


class CabinetError(ValueError):
    """A compiled cabinet folder that cannot be loaded (missing or corrupt files)."""


@dataclass(frozen=True)
class Target:
    """One door or drawer of a compiled cabinet (a view of its cabinet.json record)."""

    joint: str
    link: str
    kind: str  # "door" | "drawer"
    instruction: str
    lower: float
    upper: float
    closed: float
    open_sign: int
    open_travel: float
    drawer_length: float | None
    handle_box: tuple[np.ndarray, np.ndarray]
    handle_orientation: str
    handle_geoms: tuple[str, ...]
    record: dict

    @classmethod
    def from_record(cls, r: dict) -> "Target":
        return cls(
            joint=r["joint"], link=r["link"], kind=r["type"], instruction=r["instruction"],
            lower=r["range"][0], upper=r["range"][1], closed=r["closed_value"], open_sign=r["open_sign"],
            open_travel=r["open_travel"], drawer_length=r.get("drawer_length"),
            handle_box=(np.asarray(r["handle"]["box_min"]), np.asarray(r["handle"]["box_max"])),
            handle_orientation=r["handle"]["orientation"], handle_geoms=tuple(r["handle"].get("geoms", ())),
            record=r,
        )

    def opening(self, q: float) -> float:
        """Joint displacement in the opening direction (m or rad), 0 when closed."""
        return (q - self.closed) * self.open_sign

    @property
    def open_span(self) -> float:
        """What `open_ratio` divides the opening by: the drawer's length (m) or pi (rad, a door)."""
        if self.kind == "drawer":
            return max(self.drawer_length or self.open_travel, 1e-9)
        return math.pi

    @property
    def range_span(self) -> float:
        """What `range_ratio` divides the opening by: the joint's travel to fully open (m or rad)."""
        return max(self.open_travel, 1e-9)

    def open_ratio(self, q: float) -> float:
        """The paper's open ratio: drawer delta / drawer length, door angle / 180 degrees."""
        return max(0.0, self.opening(q)) / self.open_span

    def range_ratio(self, q: float) -> float:
        """Fraction of the joint range opened (the original code's measure, before doubling for doors)."""
        return max(0.0, self.opening(q)) / self.range_span


def load_cabinet_info(cabinet_dir: Path) -> dict:
    path = Path(cabinet_dir) / CABINET_JSON
    try:
        info = json.loads(path.read_text())
        info["targets"]  # noqa: B018 (presence check)
        return info
    except FileNotFoundError as exc:
        raise CabinetError(f"{path}: missing (is {cabinet_dir} a compiled cabinet?)") from exc
    except (json.JSONDecodeError, KeyError, TypeError) as exc:
        raise CabinetError(f"{path}: corrupt cabinet description ({exc})") from exc


def moving_bodies(mjcf_root) -> list:
    """Bodies of an MJCF model that move: every body with a joint, and the bodies below it."""
    out = []

    def walk(body, moving: bool) -> None:
        moving = moving or bool(body.find_all("joint", immediate_children_only=True))
        if moving:
            out.append(body)
        for child in body.find_all("body", immediate_children_only=True):
            walk(child, moving)

    for top in mjcf_root.worldbody.find_all("body", immediate_children_only=True):
        walk(top, False)
    return out


class Cabinet(composer.Entity):
    """A compiled cabinet (`cabinets/<id>/cabinet.xml` + `cabinet.json`), fixed to the floor."""

    def _build(self, cabinet_dir: Path) -> None:
        self.directory = Path(cabinet_dir)
        self.info = load_cabinet_info(self.directory)
        xml_path = self.directory / CABINET_XML
        try:
            self._mjcf_root = mjcf.from_path(str(xml_path))
        except Exception as exc:
            raise CabinetError(f"{xml_path}: cannot be loaded ({type(exc).__name__}: {exc})") from exc
        self._mjcf_root.model = "cabinet"
        self.targets = [Target.from_record(r) for r in self.info["targets"]]
        self._joints = {}
        for t in self.targets:
            joint = self._mjcf_root.find("joint", t.joint)
            if joint is None:
                raise CabinetError(f"{xml_path}: target joint {t.joint} missing from the model")
            self._joints[t.joint] = joint

    @property
    def mjcf_model(self):
        return self._mjcf_root

    @property
    def id(self) -> str:
        return self.info["id"]

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return np.asarray(self.info["bounds"]["min"]), np.asarray(self.info["bounds"]["max"])

    def moving_bodies(self) -> list:
        """MJCF bodies that move: every body with a joint, and the bodies below it."""
        return moving_bodies(self._mjcf_root)

    def target(self, joint: str) -> Target:
        for t in self.targets:
            if t.joint == joint:
                return t
        raise KeyError(f"cabinet {self.id} has no target joint {joint!r}; "
                       f"targets: {[t.joint for t in self.targets]}")

    def joint_element(self, joint: str):
        return self._joints[joint]

    def joint_values(self, physics) -> dict[str, float]:
        """Target joint values, read through qpos addresses cached per compiled model."""
        model = physics.model.ptr
        if getattr(self, "_qpos_cache", (None,))[0] is not model:
            names = list(self._joints)
            addresses = [int(physics.bind(self._joints[n]).qposadr) for n in names]
            self._qpos_cache = (model, names, addresses)
        _, names, addresses = self._qpos_cache
        qpos = physics.data.qpos
        return {n: float(qpos[a]) for n, a in zip(names, addresses)}

    def close_all(self, physics) -> None:
        """Reset-time only: every target closed and at rest."""
        for t in self.targets:
            b = physics.bind(self._joints[t.joint])
            b.qpos = t.closed
            b.qvel = 0.0
