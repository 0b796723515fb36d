"""Can each target of a compiled cabinet be opened where the benchmark puts it: standing in a room?

`check_in_room(cabinet_dir)` places the cabinet in a `RoomArena` exactly as `OpenCabinetTask` does
(attached at the room's cabinet site, the project's physics options and time step, gravity on; no
hand) and, for each target in turn, starts from every part closed and pushes the target's joint
open with a bounded generalised force (`FeasibilityConfig.drawer_force` N on a slide,
`door_torque` N m on a hinge) for at most `seconds`. A target is feasible when it reaches `reach`
of its joint range and its moving subtree touched nothing outside the cabinet (the room's floor is
the only other geom that collides) while it moved. Otherwise it gets a named reason:

- ``blocked_by_room``: the moving part touched a geom that is not the cabinet's, or passed more than
  `floor_tolerance` below the floor before reaching `reach` (a flap hinged at floor level);
- ``jammed``: it stayed below `reach` of its range touching only the cabinet's own parts (the
  source's geometry holds it: a neighbour overlaps its path, a drawer runs into the back panel).

The forces are those a hand applies comfortably (30 N, 15 N m); the joints' damping and friction
come from the compiler (`CompilerConfig.drawer/door`), so every feasible part opens well inside the
time limit. `opend build-assets` runs this check on every built cabinet and excludes infeasible
targets from the manifest with their reason (`opend_mj.assets.dataset`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os

os.environ.setdefault("MUJOCO_GL", "egl")

from dataclasses import dataclass, field  # noqa: E402
from pathlib import Path  # noqa: E402

import mujoco  # noqa: E402
import numpy as np  # noqa: E402
from dm_control import mjcf  # noqa: E402

from opend_mj.sim.cabinet import Cabinet  # noqa: E402
from opend_mj.sim.physics import PHYSICS  # noqa: E402
from opend_mj.sim.rooms import RoomArena  # noqa: E402

#: Bump when the check's outcome changes for the same cabinet and config (invalidates stored reports).
FEASIBILITY_VERSION = 1

#: Reasons a target is excluded (the manifest's `excluded_targets[].reason`).
BLOCKED_BY_ROOM = "blocked_by_room"
JAMMED = "jammed"


@dataclass(frozen=True)
class FeasibilityConfig:
    """The push that every target must survive in its room."""

    #: Generalised force on a drawer's slide joint (N) and torque on a door's hinge (N m).
    drawer_force: float = 30.0
    door_torque: float = 15.0
    #: Longest push (s of simulated time); a free part reaches its range in well under a second.
    seconds: float = 3.0
    #: Fraction of the joint range the target must reach.
    reach: float = 0.9
    #: Room type and seed of the scene (the floor is the same plane at z = 0 in every room).
    room: int = 0
    seed: int = 0
    #: Physics step (s): the task's.
    timestep: float = PHYSICS.timestep
    #: Deepest the moving part's collision geometry may pass below the floor on its way to `reach`
    #: (m). Moving parts have no floor contact (`RoomArena.attach_cabinet`); a front that stands on
    #: the floor reaches 0-2 mm below it (hulls are thickened to 4 mm about flat panels), while a
    #: flap hinged at floor level swings centimetres into it and cannot open in a real room.
    floor_tolerance: float = 0.005

    def digest(self) -> str:
        blob = json.dumps(dataclasses.asdict(self), sort_keys=True).encode()
        return hashlib.sha256(blob).hexdigest()[:12]


@dataclass
class TargetFeasibility:
    """How one target fared under the push."""

    joint: str
    kind: str
    #: Largest fraction of the joint range reached, and the simulated seconds to reach `reach`.
    reached: float
    seconds: float | None
    #: Geoms outside the cabinet (room) that the moving part touched, and the cabinet's own bodies it
    #: touched while below `reach` (names without the `cabinet/` prefix).
    room_contacts: list[str] = field(default_factory=list)
    cabinet_contacts: list[str] = field(default_factory=list)
    #: Lowest point of the moving part's collision geometry (m above the floor) from closed until it
    #: reached `reach` of its range (the whole push if it never did).
    min_clearance: float = float("nan")
    reason: str | None = None
    message: str | None = None

    @property
    def feasible(self) -> bool:
        return self.reason is None

    def as_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["feasible"] = self.feasible
        d["reached"] = round(self.reached, 4)
        d["min_clearance"] = None if not np.isfinite(self.min_clearance) else round(self.min_clearance, 5)
        return d


def _subtree(model, root: int) -> set[int]:
    """Body ids of `root` and every body below it."""
    out = {root}
    for b in range(root + 1, model.nbody):
        if int(model.body_parentid[b]) in out:
            out.add(b)
    return out


def _geom_lowest(physics, geoms: np.ndarray) -> float:
    """Lowest world z of a set of collision geoms (boxes by their corners, meshes by their vertices)."""
    m, d = physics.model, physics.data
    low = np.inf
    for g in geoms:
        R = d.geom_xmat[g].reshape(3, 3)
        if int(m.geom_type[g]) == int(mujoco.mjtGeom.mjGEOM_BOX):
            low = min(low, float(d.geom_xpos[g, 2] - np.abs(R[2]) @ m.geom_size[g]))
        elif int(m.geom_type[g]) == int(mujoco.mjtGeom.mjGEOM_MESH):
            mid = int(m.geom_dataid[g])
            a, n = int(m.mesh_vertadr[mid]), int(m.mesh_vertnum[mid])
            low = min(low, float(d.geom_xpos[g, 2] + (m.mesh_vert[a:a + n] @ R.T)[:, 2].min()))
        else:
            low = min(low, float(d.geom_xpos[g, 2] - m.geom_rbound[g]))
    return low


def check_in_room(cabinet_dir: Path, config: FeasibilityConfig = FeasibilityConfig(),
                  joints: list[str] | None = None) -> list[TargetFeasibility]:
    """Push each target (or those in `joints`) open in a room; one result per target."""
    arena = RoomArena(room=config.room, seed=config.seed)
    cabinet = Cabinet(Path(cabinet_dir))
    arena.attach_cabinet(cabinet)
    arena.mjcf_model.option.timestep = config.timestep
    physics = mjcf.Physics.from_mjcf_model(arena.mjcf_model)
    m, d = physics.model, physics.data
    cab_bodies = {int(physics.bind(b).element_id) for b in cabinet.mjcf_model.find_all("body")}
    in_cabinet = np.array([int(m.geom_bodyid[g]) in cab_bodies for g in range(m.ngeom)])
    colliding = (m.geom_contype != 0) | (m.geom_conaffinity != 0)
    prefix = cabinet.mjcf_model.model + "/"
    steps = int(round(config.seconds / config.timestep))
    results = []
    for target in cabinet.targets:
        if joints is not None and target.joint not in joints:
            continue
        physics.reset()
        cabinet.close_all(physics)
        physics.forward()
        jb = physics.bind(cabinet.joint_element(target.joint))
        dof, qadr = int(jb.dofadr), int(jb.qposadr)
        body = int(physics.bind(cabinet.mjcf_model.find("body", target.link)).element_id)
        moving = _subtree(m, body)
        own = np.array([int(m.geom_bodyid[g]) in moving for g in range(m.ngeom)]) & colliding
        own_geoms = np.flatnonzero(own)
        push = config.drawer_force if target.kind == "drawer" else config.door_torque
        room_hits: set[str] = set()
        cab_hits: set[str] = set()
        best, when, lowest = 0.0, None, _geom_lowest(physics, own_geoms)
        for k in range(steps):
            d.qfrc_applied[:] = 0.0
            d.qfrc_applied[dof] = push * target.open_sign
            physics.step()
            frac = target.range_ratio(float(d.qpos[qadr]))
            best = max(best, frac)
            if frac < config.reach or when is None:
                lowest = min(lowest, _geom_lowest(physics, own_geoms))
            for c in d.contact[: d.ncon]:
                g1, g2 = int(c.geom1), int(c.geom2)
                if own[g1] == own[g2]:
                    continue
                other = g2 if own[g1] else g1
                if not in_cabinet[other]:
                    room_hits.add(m.id2name(other, "geom") or f"geom{other}")
                elif frac < config.reach:
                    name = m.id2name(int(m.geom_bodyid[other]), "body") or f"body{other}"
                    cab_hits.add(name.removeprefix(prefix))
            if when is None and frac >= config.reach:
                when = (k + 1) * config.timestep
                if room_hits:
                    break
            if when is not None and k * config.timestep >= when + 0.2:
                break  # reached, and held a moment longer to see what it touches at the end
        d.qfrc_applied[:] = 0.0
        r = TargetFeasibility(joint=target.joint, kind=target.kind, reached=best, seconds=when,
                              room_contacts=sorted(room_hits), cabinet_contacts=sorted(cab_hits),
                              min_clearance=lowest)
        if room_hits or lowest < -config.floor_tolerance:
            r.reason = BLOCKED_BY_ROOM
            r.message = (f"{target.joint} ({target.kind}) "
                         + (f"touches {', '.join(r.room_contacts)}" if room_hits else "passes below the floor")
                         + " while it opens "
                         f"(reached {best:.0%} of its range; lowest point {lowest * 1000:+.1f} mm from the floor)")
        elif best < config.reach:
            r.reason = JAMMED
            r.message = (f"{target.joint} ({target.kind}) reaches only {best:.0%} of its range under "
                         f"{push:g} {'N' if target.kind == 'drawer' else 'N m'} in {config.seconds:g} s; "
                         f"touching {', '.join(r.cabinet_contacts) or 'nothing'}")
        results.append(r)
    return results


def feasibility_report(cabinet_dir: Path, config: FeasibilityConfig = FeasibilityConfig()) -> dict:
    """The check as stored in `cabinet.json["feasibility"]`: its key and one record per target."""
    return {"key": feasibility_key(config), "config": dataclasses.asdict(config),
            "targets": [r.as_dict() for r in check_in_room(cabinet_dir, config)]}


def feasibility_key(config: FeasibilityConfig = FeasibilityConfig()) -> str:
    """What a stored report must match to be reused: the config and `FEASIBILITY_VERSION`."""
    return f"{config.digest()}-v{FEASIBILITY_VERSION}"


@dataclass(frozen=True)
class RoomCheck:
    """The check as `opend build-assets` calls it (picklable for worker processes): `key` names the
    settings, calling it on a cabinet folder returns `feasibility_report`."""

    config: FeasibilityConfig = FeasibilityConfig()

    @property
    def key(self) -> str:
        return feasibility_key(self.config)

    def __call__(self, cabinet_dir: Path) -> dict:
        return feasibility_report(cabinet_dir, self.config)
