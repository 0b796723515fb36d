"""A hand in a scene: the dm_control entity, its mocap attachment and its touch sensors."""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

import numpy as np

# Off-screen rendering goes through EGL (Mesa works without a GPU); must be set before mujoco loads.
os.environ.setdefault("MUJOCO_GL", "egl")

from dm_control import composer, mjcf  # noqa: E402

from opend_mj.sim.hands.registry import get_hand  # noqa: E402
from opend_mj.sim.hands.spec import HandSpec, grasp_pose_to_root_pose  # noqa: E402
from opend_mj.transforms import mat_to_quat  # noqa: E402

#: The mocap weld: soft enough not to fight contacts, stiff enough to pull a stiff drawer
#: (time constant 20 ms, critically damped; ~0.5 mm static offset per 10 N on a 1 kg hand).
WELD_SOLREF = (0.02, 1.0)
WELD_SOLIMP = (0.95, 0.99, 0.001, 0.5, 2.0)



class Hand(composer.Entity):
    """A hand as a composer Entity, loaded from its registered MJCF (``hands/<name>/hand.xml``)."""

    def _build(self, name: str = "allegro") -> None:
        entry = get_hand(name)
        self._spec = entry.spec
        self._mjcf_root = mjcf.from_path(str(entry.xml_path))
        self._mjcf_root.model = "hand"  # names in the arena: hand/palm, hand/ff_pip, ...
        self._root_body = self._mjcf_root.find("body", self._spec.root_body)
        if self._root_body is None:
            raise ValueError(f"hand {name!r}: no body {self._spec.root_body!r}")
        self._grasp_site = self._mjcf_root.find("site", self._spec.grasp_site)
        if self._grasp_site is None:
            raise ValueError(f"hand {name!r}: no site {self._spec.grasp_site!r}")
        self._joints = [self._mjcf_root.find("joint", j) for j in self._spec.joint_names]
        self._actuators = [self._mjcf_root.find("actuator", a) for a in self._spec.actuator_names]
        if any(j is None for j in self._joints) or any(a is None for a in self._actuators):
            raise ValueError(f"hand {name!r}: spec names joints/actuators missing from the MJCF")
        if self._mjcf_root.find_all("joint") and any(
                j.tag == "freejoint" or getattr(j, "type", None) == "free"
                for j in self._mjcf_root.find_all("joint")):
            raise ValueError(f"hand {name!r}: the hand MJCF must not contain a freejoint")

    @property
    def mjcf_model(self):
        return self._mjcf_root

    @property
    def spec(self) -> HandSpec:
        return self._spec

    @property
    def root_body(self):
        return self._root_body

    @property
    def actuators(self):
        return list(self._actuators)

    @property
    def joints(self):
        return list(self._joints)

    @property
    def grasp_site(self):
        return self._grasp_site

    def set_finger_targets(self, physics, targets) -> None:
        physics.bind(self._actuators).ctrl = np.asarray(targets, dtype=float)

    def set_finger_qpos(self, physics, qpos) -> None:
        """Reset-time only: put the finger joints at ``qpos`` (e.g. the open pose)."""
        physics.bind(self._joints).qpos = np.asarray(qpos, dtype=float)
        physics.bind(self._joints).qvel = 0.0


@dataclass
class MocapHandle:
    """Names and helpers for a hand attached with :func:`attach_with_mocap`.

    Full names (``name``) are the ones in the compiled model, e.g. ``hand/palm``."""

    hand: Hand
    mocap_body: Any  # mjcf element in the arena
    weld: Any  # mjcf equality element
    freejoint: Any  # mjcf freejoint element on the attachment frame

    @property
    def mocap_body_name(self) -> str:
        return self.mocap_body.full_identifier

    @property
    def weld_name(self) -> str:
        return self.weld.full_identifier

    @property
    def root_body_name(self) -> str:
        return self.hand.root_body.full_identifier

    @property
    def grasp_site_name(self) -> str:
        return self.hand.grasp_site.full_identifier

    @property
    def freejoint_name(self) -> str:
        return self.freejoint.full_identifier

    def mocap_id(self, physics) -> int:
        bid = physics.model.name2id(self.mocap_body.full_identifier, "body")
        return int(physics.model.body_mocapid[bid])

    def move(self, physics, pos, quat=None) -> None:
        """Move the mocap target (the only way the root moves after reset)."""
        mid = self.mocap_id(physics)
        physics.data.mocap_pos[mid] = pos
        if quat is not None:
            physics.data.mocap_quat[mid] = quat

    def mocap_pose(self, physics) -> tuple[np.ndarray, np.ndarray]:
        mid = self.mocap_id(physics)
        return physics.data.mocap_pos[mid].copy(), physics.data.mocap_quat[mid].copy()

    def reset_pose(self, physics, pos, quat) -> None:
        """Reset-time only: place the hand root and the mocap body at the same pose, at rest."""
        self.move(physics, pos, quat)
        fj = physics.bind(self.freejoint)
        fj.qpos = np.concatenate([np.asarray(pos, float), np.asarray(quat, float)])
        fj.qvel = 0.0

    def move_grasp_site(self, physics, site_pos, site_quat) -> None:
        """Move the mocap so that the grasp site (at rest) lands at ``site_pos``/``site_quat``."""
        self.move(physics, *grasp_pose_to_root_pose(self.hand.spec, site_pos, site_quat))

    def root_pose(self, physics) -> tuple[np.ndarray, np.ndarray]:
        b = physics.bind(self.hand.root_body)
        return b.xpos.copy(), b.xquat.copy()

    def grasp_site_pose(self, physics) -> tuple[np.ndarray, np.ndarray]:
        s = physics.bind(self.hand.grasp_site)
        return s.xpos.copy(), mat_to_quat(s.xmat.reshape(3, 3))


def touch_parts(spec: HandSpec) -> tuple[str, ...]:
    """The parts a hand feels touch on (palm, thumb, each finger; sorted), then ``other`` (a hand
    geom without a touch site): the order of `HandTouch.vector` and of the ``touch`` observation."""
    return tuple(sorted(set(spec.touch_sensors.values()))) + ("other",)


def touch_geoms(hand: Hand, physics) -> dict[int, str]:
    """The geoms that carry the hand's touch sensors (``touch_<geom>`` in ``spec.touch_sensors``):
    geom id in ``physics``'s model -> the part it belongs to (palm, thumb, a finger)."""
    model = hand.mjcf_model
    geoms: dict[int, str] = {}
    for name, part in hand.spec.touch_sensors.items():
        geom = model.find("geom", name[len("touch_"):]) if name.startswith("touch_") else None
        if geom is not None:
            geoms[int(physics.bind(geom).element_id)] = part
    return geoms


class HandTouch:
    """What the hand feels: the normal force (N) on each of its parts from things that are not the
    hand (a thumb pressing on a finger is not touch). Part of the hand's own state, as its touch
    sensors would report it with self-contact filtered out."""

    def __init__(self, hand: Hand, physics):
        import mujoco

        self._mj_contact_force = mujoco.mj_contactForce
        model = hand.mjcf_model
        self.parts = touch_parts(hand.spec)
        self._index = {p: i for i, p in enumerate(self.parts)}
        self._m, self._d = physics.model.ptr, physics.data.ptr
        self._geom_part = {geom: self._index[part] for geom, part in touch_geoms(hand, physics).items()}
        hand_bodies = {int(b) for b in physics.bind(model.find_all("body")).element_id}
        self._hand_geom = np.isin(self._m.geom_bodyid, list(hand_bodies))
        self._force6 = np.zeros(6)
        #: part index of each geom of the model (the last part, "other", for geoms without a sensor)
        self._part_of_geom = np.full(self._m.ngeom, len(self.parts) - 1, dtype=np.intp)
        for geom, part in self._geom_part.items():
            self._part_of_geom[geom] = part
        #: With elliptic cones (or frictionless contacts only) a contact's normal force is its first
        #: constraint force, which is what mj_contactForce copies: `vector_from` reads it for all
        #: contacts at once. Pyramidal cones decode the force from the pyramid's edges: `vector`.
        self._elliptic = int(self._m.opt.cone) == int(mujoco.mjtCone.mjCONE_ELLIPTIC)

    def vector(self, above: float | None = None) -> np.ndarray:
        """Force per part, in `parts` order (0: the part touches nothing). ``above`` (world z, m):
        only contacts at or above this height (a skin that says where it is touched: a press
        lower down is on the floor, not a handle)."""
        return self.vector_from(self._d.contact, above)

    def vector_reference(self, above: float | None = None) -> np.ndarray:
        """`vector` one contact at a time through ``mj_contactForce`` (the reference; any cone)."""
        m, d = self._m, self._d
        force = np.zeros(len(self.parts))
        other = len(self.parts) - 1
        for i in range(d.ncon):
            c = d.contact[i]
            g1, g2 = int(c.geom1), int(c.geom2)
            h1, h2 = self._hand_geom[g1], self._hand_geom[g2]
            if h1 == h2 or (above is not None and float(c.pos[2]) < above):
                continue
            self._mj_contact_force(m, d, i, self._force6)
            force[self._geom_part.get(g1 if h1 else g2, other)] += abs(float(self._force6[0]))
        return force

    def vector_from(self, contact, above: float | None = None) -> np.ndarray:
        """`vector` from the step's contact list (``data.contact``, read once by the caller), without
        a Python loop over contacts: the same forces, summed per part in contact order (bincount adds
        in index order, as the loop does), so the same numbers to the bit. ``above``: see `vector`."""
        if not len(contact.geom1):
            return np.zeros(len(self.parts))
        if not self._elliptic and int(np.max(contact.dim)) > 1:
            return self.vector_reference(above)
        g1, g2, adr = contact.geom1, contact.geom2, contact.efc_address
        h1, h2 = self._hand_geom[g1], self._hand_geom[g2]
        mixed = h1 != h2
        if above is not None:
            mixed = mixed & (contact.pos[:, 2] >= above)
        if not mixed.any():
            return np.zeros(len(self.parts))
        adr = adr[mixed]
        force = np.where(adr >= 0, self._d.efc_force[np.maximum(adr, 0)], 0.0)
        parts = self._part_of_geom[np.where(h1[mixed], g1[mixed], g2[mixed])]
        return np.bincount(parts, weights=np.abs(force), minlength=len(self.parts))

    def read(self, above: float | None = None) -> dict[str, float]:
        """Force per part that feels any, by part name (what the planner and agents read);
        ``above``: see `vector`."""
        return touch_dict(self.parts, self.vector(above))


def touch_dict(parts, forces) -> dict[str, float]:
    """``{part: force}`` of the parts that feel a force (the ``touch`` observation as a dict)."""
    return {p: float(f) for p, f in zip(parts, forces) if f > 0.0}


def attach_with_mocap(arena_mjcf, hand: Hand, *, solref=WELD_SOLREF, solimp=WELD_SOLIMP,
                      mocap_name: str = "hand_mocap") -> MocapHandle:
    """Attach ``hand`` to ``arena_mjcf`` (an mjcf RootElement or a composer Arena) as a free entity
    and drive its root with a mocap body through a soft 6-DoF weld.

    The weld's relpose is the identity: the hand root coincides with the mocap body at rest."""
    root = getattr(arena_mjcf, "mjcf_model", arena_mjcf)
    frame = root.attach(hand.mjcf_model)
    freejoint = frame.add("freejoint")
    mocap = root.worldbody.add("body", name=mocap_name, mocap="true")
    mocap.add("site", name=f"{mocap_name}_site", size=[0.004], rgba=[0, 1, 0, 0.3], group=5)
    weld = root.equality.add("weld", name=f"{mocap_name}_weld", body1=mocap, body2=hand.root_body,
                             relpose=[0, 0, 0, 1, 0, 0, 0], solref=list(solref),
                             solimp=list(solimp))
    return MocapHandle(hand=hand, mocap_body=mocap, weld=weld, freejoint=freejoint)

