"""The hand registry: one :class:`HandModel` per name (the four built-in ones in ``hands/<name>/``,
shipped with the package (`opend_mj.resources`), and any a user registers).
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass, field
from pathlib import Path

from opend_mj import resources
from opend_mj.sim.hands.settings import (
    GRASP_FILE,
    PLANNER_FILE,
    GraspProfile,
    HandPlannerConfig,
)
from opend_mj.sim.hands.spec import HandSpec

#: The built-in hands' folder: the package's copy when installed, the clone's ``hands/`` otherwise.
HANDS_DIR = resources.hands_dir()
BUILTIN_HANDS = ("franka", "allegro", "shadow", "skeleton")

@dataclass(frozen=True)
class HandModel:
    """One hand, everything of it: its folder (``hands/<name>/`` or a user's), the MJCF without a
    freejoint (``hand.xml``), its description (``spec.json``), its grasp tuning (``grasp.json``; None
    where no search wrote one) and the planner's numbers for it (``planner.json``, else the defaults
    of its type). :func:`get_hand` returns it; nothing else reads a hand's files."""

    name: str
    folder: Path
    xml_path: Path
    spec: HandSpec
    grasp: GraspProfile | None = None
    planner: HandPlannerConfig = field(default_factory=HandPlannerConfig)

    @property
    def grasp_file(self) -> Path:
        """Where ``opend search-grasp`` writes this hand's grasp tuning."""
        return self.folder / GRASP_FILE


#: The former name of :class:`HandModel`.
HandEntry = HandModel

_REGISTRY: dict[str, HandModel] = {}


def load_hand_folder(folder: str | os.PathLike, name: str | None = None, xml_path: str | os.PathLike | None = None,
                     spec: HandSpec | dict | str | os.PathLike | None = None) -> HandModel:
    """A hand from its folder: ``hand.xml`` (or ``xml_path``), ``spec.json`` (or ``spec``), and the
    ``grasp.json`` and ``planner.json`` beside them where present. Every file is checked as it is
    read: a missing model or spec, or an unknown key in a settings file, is an error naming the file."""
    folder = Path(folder).resolve()
    xml_path = Path(xml_path).resolve() if xml_path is not None else folder / "hand.xml"
    if not xml_path.is_file():
        raise FileNotFoundError(f"{xml_path}: no hand model here")
    if spec is None:
        spec = folder / "spec.json"
    if isinstance(spec, (str, os.PathLike)):
        spec = HandSpec.load(spec)
    elif isinstance(spec, dict):
        spec = HandSpec.from_dict(spec)
    name = name or spec.name
    if spec.name != name:
        spec = dataclasses.replace(spec, name=name)
    grasp = GraspProfile.load(folder / GRASP_FILE) if (folder / GRASP_FILE).is_file() else None
    planner_path = folder / PLANNER_FILE
    planner = HandPlannerConfig.load(planner_path) if planner_path.is_file() else HandPlannerConfig.for_type(spec.hand_type)
    return HandModel(name=name, folder=folder, xml_path=xml_path, spec=spec, grasp=grasp, planner=planner)


def register_hand(name: str, xml_path: str | os.PathLike, spec: HandSpec | dict | str | os.PathLike,
                  *, grasp: GraspProfile | None = None, planner: HandPlannerConfig | None = None,
                  overwrite: bool = False) -> HandModel:
    """Register a hand: any MJCF (no freejoint/mocap in it) plus a spec (HandSpec, dict or JSON
    path). The MJCF must contain ``spec.root_body``, ``spec.grasp_site`` and the named joints and
    actuators. Its grasp tuning and planner numbers are ``grasp`` and ``planner`` where given, else
    the ``grasp.json`` and ``planner.json`` in the MJCF's folder, else the defaults of the hand's
    type. Returns the model; ``get_hand(name)`` and ``Hand(name)`` then find it."""
    xml_path = Path(xml_path).resolve()
    if not xml_path.is_file():
        raise FileNotFoundError(xml_path)
    if name in _REGISTRY and not overwrite and _REGISTRY[name].xml_path != xml_path:
        raise ValueError(f"hand {name!r} is already registered (pass overwrite=True)")
    model = load_hand_folder(xml_path.parent, name=name, xml_path=xml_path, spec=spec)
    if grasp is not None:
        model = dataclasses.replace(model, grasp=grasp)
    if planner is not None:
        model = dataclasses.replace(model, planner=planner)
    _REGISTRY[name] = model
    return model


def _ensure_builtin() -> None:
    for n in BUILTIN_HANDS:
        if n not in _REGISTRY and (HANDS_DIR / n / "hand.xml").is_file():
            _REGISTRY[n] = load_hand_folder(HANDS_DIR / n, name=n)


def get_hand(name: str) -> HandModel:
    """The hand registered as ``name`` (the built-in ones load from ``hands/<name>/`` on first use)."""
    _ensure_builtin()
    if name not in _REGISTRY:
        raise KeyError(f"unknown hand {name!r}; known: {', '.join(list_hands())}")
    return _REGISTRY[name]


def list_hands() -> list[str]:
    _ensure_builtin()
    return list(_REGISTRY)


def load_spec(name: str) -> HandSpec:
    """The spec of a registered (or built-in) hand."""
    return get_hand(name).spec
