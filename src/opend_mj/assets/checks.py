"""Physics checks of a compiled cabinet in MuJoCo alone (used by the tests and by the asset benchmark).

Each check takes an `mujoco.MjModel` of one cabinet (e.g. `load_cabinet(dir)`) and returns figures, not
verdicts; the `*_ok` helpers and `check_cabinet` apply the thresholds a benchmark user relies on:

- `rest_contacts`: contacts between the cabinet's own parts with every joint closed (should be none);
- `gravity_drift`: how far each door/drawer joint moves, as a fraction of its range, when the cabinet
  stands under gravity with nothing touching it (should stay below 1 %);
- `drive_through_range`: a door or drawer driven open by a generalised force on its joint (a PD law
  whose gains follow the joint's own inertia) and then closed again; how far it got, how far it came
  back, how far past its limits it went, and how much the other joints moved meanwhile; a part that
  other parts block when closed (a drawer behind a pair of doors) is driven again with the parts it
  pushed opened first and held open, by the same law (`check_cabinet`);
- `steps_per_second`: `mj_step` throughput with every movable part given a small initial velocity.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import mujoco
import numpy as np

#: The joints a benchmark user drives: hinge (door) and slide (drawer) joints of the cabinet.
MOVABLE = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))


def load_cabinet(path: Path | str) -> mujoco.MjModel:
    """The compiled cabinet model: `path` is a cabinet folder or its cabinet.xml."""
    path = Path(path)
    if path.is_dir():
        path = path / "cabinet.xml"
    return mujoco.MjModel.from_xml_path(str(path))


def movable_joints(model: mujoco.MjModel) -> list[str]:
    """Names of the hinge and slide joints of a model (the doors and drawers of a cabinet)."""
    return [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
            for j in range(model.njnt) if int(model.jnt_type[j]) in MOVABLE]


def _joint(model: mujoco.MjModel, name: str) -> tuple[int, int, int, float, float]:
    j = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
    if j < 0:
        raise KeyError(f"no joint named {name!r}")
    lo, hi = (float(x) for x in model.jnt_range[j])
    return j, int(model.jnt_qposadr[j]), int(model.jnt_dofadr[j]), lo, hi


def _rest_value(lo: float, hi: float) -> float:
    """The closed position of a joint: 0 where the range holds it (PartNet), else the nearer limit."""
    return float(np.clip(0.0, lo, hi))


def rest_contacts(model: mujoco.MjModel) -> list[tuple[str, str]]:
    """Geom pairs in contact when every joint is at its closed value (after `mj_forward`)."""
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    pairs = []
    for i in range(data.ncon):
        con = data.contact[i]
        pairs.append(tuple(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or f"geom{g}"
                           for g in (con.geom1, con.geom2)))
    return pairs


def gravity_drift(model: mujoco.MjModel, seconds: float = 5.0) -> dict[str, float]:
    """Largest displacement of each door/drawer joint over `seconds` under gravity, as a range fraction."""
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    joints = {n: _joint(model, n) for n in movable_joints(model)}
    start = {n: float(data.qpos[q]) for n, (_, q, _, _, _) in joints.items()}
    worst = dict.fromkeys(joints, 0.0)
    steps = int(round(seconds / model.opt.timestep))
    for _ in range(steps):
        mujoco.mj_step(model, data)
        for n, (_, q, _, lo, hi) in joints.items():
            worst[n] = max(worst[n], abs(float(data.qpos[q]) - start[n]) / (hi - lo))
    if not np.all(np.isfinite(data.qpos)):
        return dict.fromkeys(joints, float("inf"))
    return worst


@dataclass
class DriveResult:
    """What happened when one joint was driven open and closed again (fractions of its range)."""

    joint: str
    range: tuple[float, float]
    #: Furthest the joint got from its closed value towards the open limit.
    reached: float
    #: Distance from the closed value after driving it back (0 = fully closed again).
    returned: float
    #: Largest excursion past either limit.
    overshoot: float
    #: Largest motion of any other movable joint meanwhile, and which joint it was.
    others_moved: float = 0.0
    other_joint: str | None = None
    seconds: float = 0.0
    finite: bool = True
    #: Other joints that moved by more than 1 % of their range meanwhile (the parts this one pushed).
    pushed: list = field(default_factory=list)
    #: Joints driven open (and held there) before this one: the parts that block it when closed.
    opened_first: list = field(default_factory=list)

    def ok(self, reach: float = 0.95, back: float = 0.05, overshoot: float = 0.03) -> bool:
        return self.finite and self.reached >= reach and self.returned <= back and self.overshoot <= overshoot

    def as_dict(self) -> dict:
        return asdict(self)


def drive_through_range(
    model: mujoco.MjModel,
    joint_name: str,
    seconds: float = 3.0,
    frequency: float = 2.0,
    margin: float = 0.05,
    open_first: list[str] | None = None,
) -> DriveResult:
    """Drive one joint open and closed with a generalised force on its dof (nothing else acts on it).

    The force is a PD law towards a set point `margin` (range fraction) beyond the open limit, then
    beyond the closed value, with gains for natural frequency `frequency` (Hz) from the joint's
    inertia (so the joint's limit, not the controller, is what stops it) plus a feed-forward of the
    joint's frictionloss. Each phase lasts `seconds` of simulated time. The joints in `open_first`
    are driven open the same way first, one after the other, and held open by their law meanwhile.
    """
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    held = [_drive_law(model, data, n) for n in (open_first or [])]
    for k, law in enumerate(held):
        for _ in range(int(round(seconds / model.opt.timestep))):
            for other in held[:k + 1]:
                other(data, open_=True)
            mujoco.mj_step(model, data)
    _, qadr, dadr, lo, hi = _joint(model, joint_name)
    span = hi - lo
    closed = _rest_value(lo, hi)
    open_value = hi if (hi - closed) >= (closed - lo) else lo
    sign = 1.0 if open_value >= closed else -1.0
    travel = abs(open_value - closed)
    others = {n: _joint(model, n) for n in movable_joints(model) if n != joint_name and n not in (open_first or [])}
    other_start = {n: float(data.qpos[q]) for n, (_, q, _, _, _) in others.items()}

    full = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, full)
    inertia = float(full[dadr, dadr])  # joint-space inertia incl. armature
    omega = 2 * np.pi * frequency
    kp, kd = inertia * omega**2, 2.0 * inertia * omega
    friction = float(model.dof_frictionloss[dadr])

    reached = overshoot = others_moved = 0.0
    other_joint = None
    moved = dict.fromkeys(others, 0.0)
    steps = int(round(seconds / model.opt.timestep))
    for goal in (open_value + sign * margin * span, closed - sign * margin * span):
        for _ in range(steps):
            q, qd = float(data.qpos[qadr]), float(data.qvel[dadr])
            force = kp * (goal - q) - kd * qd
            force += friction * np.sign(goal - q)
            data.qfrc_applied[dadr] = force
            for law in held:
                law(data, open_=True)
            mujoco.mj_step(model, data)
            q = float(data.qpos[qadr])
            reached = max(reached, sign * (q - closed) / travel)
            overshoot = max(overshoot, (q - hi) / span, (lo - q) / span)
            for n, (_, oq, _, olo, ohi) in others.items():
                m = abs(float(data.qpos[oq]) - other_start[n]) / (ohi - olo)
                moved[n] = max(moved[n], m)
                if m > others_moved:
                    others_moved, other_joint = m, n
    finite = bool(np.all(np.isfinite(data.qpos)))
    returned = abs(float(data.qpos[qadr]) - closed) / travel
    return DriveResult(joint=joint_name, range=(lo, hi), reached=reached, returned=returned,
                       overshoot=max(overshoot, 0.0), others_moved=others_moved, other_joint=other_joint,
                       seconds=2 * seconds, finite=finite, pushed=[n for n, m in moved.items() if m > 0.01],
                       opened_first=list(open_first or []))


def _drive_law(model: mujoco.MjModel, data: mujoco.MjData, joint_name: str, frequency: float = 2.0,
               margin: float = 0.05):
    """The PD law of `drive_through_range` for one joint, as a function that sets its applied force."""
    full = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, full)
    _, qadr, dadr, lo, hi = _joint(model, joint_name)
    closed = _rest_value(lo, hi)
    open_value = hi if (hi - closed) >= (closed - lo) else lo
    sign = 1.0 if open_value >= closed else -1.0
    inertia = float(full[dadr, dadr])
    omega = 2 * np.pi * frequency
    kp, kd, friction = inertia * omega**2, 2.0 * inertia * omega, float(model.dof_frictionloss[dadr])

    def apply(d: mujoco.MjData, open_: bool = True) -> None:
        goal = (open_value + sign * margin * (hi - lo)) if open_ else (closed - sign * margin * (hi - lo))
        q = float(d.qpos[qadr])
        d.qfrc_applied[dadr] = kp * (goal - q) - kd * float(d.qvel[dadr]) + friction * np.sign(goal - q)

    return apply


def steps_per_second(model: mujoco.MjModel, steps: int = 2000, speed: float = 0.3) -> float:
    """`mj_step` throughput of the cabinet alone, every door/drawer started moving at `speed` (rad or m/s)."""
    data = mujoco.MjData(model)
    for n in movable_joints(model):
        _, _, dadr, lo, hi = _joint(model, n)
        closed = _rest_value(lo, hi)
        data.qvel[dadr] = speed if (hi - closed) >= (closed - lo) else -speed
    mujoco.mj_forward(model, data)
    start = time.perf_counter()
    for _ in range(steps):
        mujoco.mj_step(model, data)
    return steps / (time.perf_counter() - start)


@dataclass
class CabinetCheck:
    """All rest and drive checks of one cabinet, with a verdict."""

    rest_contacts: list = field(default_factory=list)
    drift: dict = field(default_factory=dict)
    drives: list = field(default_factory=list)
    #: Thresholds (fractions of a joint's range).
    max_drift: float = 0.01
    reach: float = 0.95

    @property
    def failures(self) -> list[str]:
        out = []
        if self.rest_contacts:
            out.append(f"{len(self.rest_contacts)} contacts at rest, e.g. {self.rest_contacts[0]}")
        out += [f"{j} drifts {d:.1%} of its range under gravity" for j, d in self.drift.items()
                if not d < self.max_drift]
        out += [f"{d.joint} reached {d.reached:.0%} and came back to {d.returned:.0%} of its range"
                + (f" (with {', '.join(d.opened_first)} opened first)" if d.opened_first else "")
                for d in self.drives if not d.ok(self.reach)]
        return out

    @property
    def ok(self) -> bool:
        return not self.failures


def check_cabinet(model: mujoco.MjModel, joints: list[str] | None = None, drift_seconds: float = 5.0) -> CabinetCheck:
    """Rest contacts, gravity drift and a drive through the range of each joint in `joints` (default all)."""
    joints = movable_joints(model) if joints is None else joints
    drives = []
    for j in joints:
        d = drive_through_range(model, j)
        if not d.ok() and d.pushed:  # blocked by parts in front of it: open those first, as a user would
            again = drive_through_range(model, j, open_first=d.pushed)
            d = again if again.reached > d.reached else d
        drives.append(d)
    return CabinetCheck(
        rest_contacts=rest_contacts(model),
        drift=gravity_drift(model, drift_seconds),
        drives=drives,
    )
