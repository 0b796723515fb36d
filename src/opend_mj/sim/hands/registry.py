"""The hand registry: one :class:`HandModel` per name: the hands found in the hands folder (every
``<folder>/<name>/`` with a ``hand.xml`` and a ``spec.json``; :func:`hands_folder`: the shipped
``hands/`` (`opend_mj.resources.hands_dir`), or the folder ``$OPEND_HANDS_DIR`` names), and any a user
registers (:func:`register_hand`).

A hand is listed in one place, its own folder: its name is the folder's, its title and its place in
listings are ``title`` and ``order`` in its ``spec.json``. Everything that lists hands (`opend report`,
the expert tables, ``hands/build_hands.py``, ``opend hands``) asks :func:`list_hands` and
:attr:`HandModel.title`; adding a hand is adding its folder.
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

#: The shipped hands' folder: the package's copy when installed, the clone's ``hands/`` otherwise.
HANDS_DIR = resources.hands_dir()
#: The environment variable naming a folder of hands to use instead of :data:`HANDS_DIR` (a folder
#: laid out like ``hands/``: one subfolder per hand).
HANDS_DIR_ENV = "OPEND_HANDS_DIR"


def hands_folder() -> Path:
    """The folder the registry finds its hands in: ``$OPEND_HANDS_DIR`` where set, else :data:`HANDS_DIR`."""
    other = os.environ.get(HANDS_DIR_ENV)
    return Path(other).expanduser().resolve() if other else HANDS_DIR


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

    @property
    def title(self) -> str:
        """The hand's name in tables and pages (``spec.json``'s ``title``, else its name)."""
        return self.spec.display_title


#: Every hand by name, those of the hands folder and those registered.
_REGISTRY: dict[str, HandModel] = {}
#: The hands folder :data:`_FOUND` was read from, and what was found there (name -> model, in order).
_FOUND_IN: Path | None = None
_FOUND: dict[str, HandModel] = {}


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


def _listing_key(model: HandModel) -> tuple:
    order = model.spec.order
    return (order is None, order if order is not None else 0, model.name)


def find_hands(folder: str | os.PathLike) -> list[HandModel]:
    """The hands in ``folder``: every subfolder with a ``hand.xml`` and a ``spec.json``, named after
    the subfolder, ordered by their ``spec.json``'s ``order`` (then by name)."""
    folder = Path(folder)
    subfolders = sorted(d for d in folder.iterdir() if (d / "hand.xml").is_file() and (d / "spec.json").is_file()) \
        if folder.is_dir() else []
    return sorted((load_hand_folder(d, name=d.name) for d in subfolders), key=_listing_key)


def _ensure_builtin() -> None:
    """Read the hands folder (again where :func:`hands_folder` changed since it was read): its hands
    replace those of the folder read before; a hand registered under the same name is kept."""
    global _FOUND_IN
    folder = hands_folder()
    if _FOUND_IN != folder:
        for name, model in _FOUND.items():
            if _REGISTRY.get(name) is model:
                del _REGISTRY[name]
        _FOUND.clear()
        _FOUND.update((model.name, model) for model in find_hands(folder))
        _FOUND_IN = folder
    for name, model in _FOUND.items():  # (also where one was taken out of the registry since)
        _REGISTRY.setdefault(name, model)


def builtin_hands() -> list[str]:
    """The names of the hands in the hands folder (:func:`hands_folder`), in their order."""
    _ensure_builtin()
    return list(_FOUND)


def get_hand(name: str) -> HandModel:
    """The hand registered as ``name`` (those of the hands folder load from ``<folder>/<name>/`` on
    first use)."""
    _ensure_builtin()
    if name not in _REGISTRY:
        raise KeyError(f"unknown hand {name!r}; known: {', '.join(list_hands())}")
    return _REGISTRY[name]


def list_hands() -> list[str]:
    """Every hand's name: those of the hands folder in their order, then the registered ones."""
    _ensure_builtin()
    found = [n for n in _FOUND if n in _REGISTRY]
    return found + [n for n in _REGISTRY if n not in _FOUND]


def load_spec(name: str) -> HandSpec:
    """The spec of a registered (or built-in) hand."""
    return get_hand(name).spec
