"""Handle solvers: find the instructed handle's box in the front camera image.

One small interface, :class:`~opend_mj.policy.handle_box.HandleSolver`::

    solver.solve(rgb, depth, instruction, camera_view) -> HandleBox | None

``rgb`` is (H, W, 3) uint8, ``depth`` (H, W) float metres (planar), ``instruction`` the language
instruction ("second top left drawer"), ``camera_view`` an :class:`opend_mj.sim.camera.CameraView`
(intrinsics and pose). ``None`` means "no handle found" (the episode fails at the locate stage).

Solvers are made through a registry, ``get_solver(name, **options)``; a later module adds
``fasterrcnn`` and ``cliport`` with :func:`register_solver`. The registry also names how a learned
solver's model is trained (:func:`get_trainer`, :func:`register_trainer`: `opend train`). The
``oracle`` solver returns the simulator's ground-truth box of the target handle; it gets that box
through its constructor (``ground_truth``: a callable returning ``(u0, v0, u1, v1)`` or ``None``),
never through globals.

From an agent (`opend_mj.policy.agents`), :func:`locate` asks a shipped solver for the instructed
handle in an observation and returns its box and world point as the planner would act on them::

    from opend_mj.policy.solvers import locate
    found = locate(obs, solver="fasterrcnn")   # None: no handle found
    found.box, found.point                     # HandleBox (pixels), (3,) world metres
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from opend_mj.policy.handle_box import HandleBox, HandleSolver


class OracleSolver:
    """Ground truth: the simulator's image box of the target's handle.

    ``ground_truth`` is a callable that returns the target handle's box ``(u0, v0, u1, v1)`` (or
    ``None`` if it is out of view), e.g. ``lambda: task.handle_boxes(physics)[task.target.joint]``.
    """

    name = "oracle"
    needs_ground_truth = True
    #: its boxes are exact: the planner does not refine them
    exact = True

    def __init__(self, ground_truth: Callable[[], tuple[float, float, float, float] | None] | None = None):
        if ground_truth is None:
            raise ValueError("the oracle solver needs ground_truth= (a callable returning the target's box)")
        self._ground_truth = ground_truth

    def solve(self, rgb, depth, instruction, camera_view) -> HandleBox | None:
        box = self._ground_truth()
        if box is None:
            return None
        return HandleBox(*map(float, box))


#: name -> factory(**options) or "module:attribute" (imported on first use).
_REGISTRY: dict[str, Callable[..., HandleSolver] | str] = {
    "oracle": OracleSolver,
    "fasterrcnn": "opend_mj.policy.learned.detector:FasterRCNNSolver",  # checkpoints/fasterrcnn.pt
    # trained on a real depth sensor's images too: checkpoints/fasterrcnn_sensor.pt
    "fasterrcnn-sensor": "opend_mj.policy.learned.detector:SensorFasterRCNNSolver",
    "cliport": "opend_mj.policy.learned.affordance:CLIPortSolver",  # checkpoints/cliport.pt
}


def register_solver(name: str, factory: Callable[..., HandleSolver] | str, *, overwrite: bool = False) -> None:
    """Register a solver factory (a class or callable taking keyword options, or "module:attr")."""
    if name in _REGISTRY and not overwrite and _REGISTRY[name] is not factory:
        raise ValueError(f"solver {name!r} is already registered (pass overwrite=True)")
    _REGISTRY[name] = factory


def list_solvers() -> list[str]:
    return sorted(_REGISTRY)


def solver_factory(name: str) -> Callable[..., HandleSolver]:
    if name not in _REGISTRY:
        raise KeyError(f"unknown handle solver {name!r}; known: {', '.join(list_solvers())}")
    factory = _REGISTRY[name]
    if isinstance(factory, str):
        module, attr = factory.split(":")
        factory = getattr(importlib.import_module(module), attr)
        _REGISTRY[name] = factory
    return factory


#: name -> how `opend train --solver <name>` trains its model: a
#: :class:`~opend_mj.policy.learned.loop.Trainer` or "module:attribute" (imported on first use).
_TRAINERS: dict[str, Any] = {
    "fasterrcnn": "opend_mj.policy.learned.train_detector:TRAINER",  # writes checkpoints/fasterrcnn.pt
    "cliport": "opend_mj.policy.learned.train_cliport:TRAINER",  # writes checkpoints/cliport.pt
}


def register_trainer(name: str, trainer: Any, *, overwrite: bool = False) -> None:
    """Register how solver ``name``'s model is trained (a ``Trainer`` or "module:attr"); `opend train
    --solver name` then offers it."""
    if name in _TRAINERS and not overwrite and _TRAINERS[name] is not trainer:
        raise ValueError(f"a trainer for solver {name!r} is already registered (pass overwrite=True)")
    _TRAINERS[name] = trainer


def trainable_solvers() -> list[str]:
    """The solvers whose model `opend train` trains, in the order they were registered."""
    return list(_TRAINERS)


def get_trainer(name: str):
    """The :class:`~opend_mj.policy.learned.loop.Trainer` of solver ``name``."""
    if name not in _TRAINERS:
        raise KeyError(f"no trainer for solver {name!r}; trainable: {', '.join(trainable_solvers())}")
    trainer = _TRAINERS[name]
    if isinstance(trainer, str):
        module, attr = trainer.split(":")
        trainer = _TRAINERS[name] = getattr(importlib.import_module(module), attr)
    return trainer


def needs_ground_truth(name: str) -> bool:
    return bool(getattr(solver_factory(name), "needs_ground_truth", False))


def get_solver(name: str, **options) -> HandleSolver:
    """A solver instance. Options are passed to its factory (``ground_truth=`` for ``oracle``)."""
    return solver_factory(name)(**options)


@dataclass(frozen=True)
class Located:
    """Where a solver finds the instructed handle in one RGB-D image (:func:`locate`)."""

    #: pixels (u0, v0, u1, v1) of the image, as the planner acts on it: a learned solver's box
    #: snapped to the handle standing out of the panel in depth, one of a pair of pulls
    box: HandleBox
    #: (3,) world metres: the handle's grip centre, the box back-projected with the depth image
    #: (the handle's front plus its assumed radius; `policy.perception.estimate_handle`)
    point: np.ndarray
    #: world x (m) of the handle's front, the face nearest the camera (the cabinet faces -x)
    front_x: float
    #: the rest of the planner's view of it (`policy.learned.bc_model.HandlePercept`: the 3D estimate with
    #: orientation, bar or knob, extent and panel; the measured shape; a door's hinge side)
    percept: Any


_LOCATORS: dict[tuple, HandleSolver] = {}


def locate(obs: dict, instruction: str | None = None, solver: str | Any = "fasterrcnn", **options) -> Located | None:
    """The instructed handle in an agent's observation through a handle solver, or None where it
    finds none.

    ``obs`` holds ``rgb``, ``depth``, ``camera_K`` and ``camera_pose`` (an agent's first observation);
    ``instruction``: default ``obs["instruction"]``. ``solver``: a registered solver that reads no
    ground truth (``fasterrcnn``, ``fasterrcnn-sensor``, ``cliport``; made once per process with
    ``options``, e.g. ``checkpoint=``) or an object with ``solve(rgb, depth, instruction,
    camera_view)``. The box is refined and back-projected as the planner and the behaviour-cloning
    agent do (`policy.learned.bc_model.perceive_handle`).
    """
    from opend_mj.policy.learned.bc_model import perceive_handle
    from opend_mj.sim.camera import CameraView

    if isinstance(solver, str):
        key = (solver, repr(sorted(options.items())))
        made = _LOCATORS.get(key)
        if made is None:
            if needs_ground_truth(solver):
                raise ValueError(f"solver {solver!r} reads the simulator's ground truth, which an agent may not")
            made = _LOCATORS[key] = get_solver(solver, **options)
        solver = made
    elif getattr(solver, "needs_ground_truth", False):
        raise ValueError(f"solver {getattr(solver, 'name', solver)!r} reads the simulator's ground truth")
    view = CameraView.from_arrays(obs["camera_K"], obs["camera_pose"])
    text = obs["instruction"] if instruction is None else instruction
    percept = perceive_handle(solver, np.asarray(obs["rgb"]), np.asarray(obs["depth"]), text, view)
    if percept is None:
        return None
    handle = percept.handle
    return Located(box=percept.box, point=np.asarray(handle.centre, float).copy(), front_x=float(handle.front_x),
                   percept=percept)
