"""One way to build what acts in an episode: a handle solver, and the planner around it.

Every caller (``opend run``, ``opend demos``, the planner as an agent, the BC policy's handle
percept, ``opend evaluate-solver``) builds through here, so that two things are set up in one place:

* the **ground truth**: a solver that reads the simulator (the oracle) is given the callback that
  returns the target handle's true image box; an agent may never have one (:func:`build_solver`
  with ``for_agent=True`` refuses it, naming the solver);
* the **hand's settings**: the planner's configuration with the hand's grasp tuning
  (``grasp.json``: finger closing, grasp depth, knob orientation) and its own numbers
  (``planner.json``), both from the hand's :class:`~opend_mj.sim.hands.HandModel`.
"""

from __future__ import annotations

from typing import Any, Callable

from opend_mj.policy.handle_box import HandleSolver
from opend_mj.policy.planner import Planner, PlannerConfig
from opend_mj.policy.solvers import needs_ground_truth, solver_factory
from opend_mj.sim.hands import HandModel, get_hand

#: Overrides that search the grasp itself (``opend search-grasp``): a run that sets them starts from
#: the default knob orientation, not the hand's tuned one.
GRASP_SEARCH_KEYS = ("grasp.close_scale", "grasp.depth")


def build_solver(solver: str | Any, ground_truth: Callable[[], Any] | None = None, *, for_agent: bool = False,
                 **options) -> HandleSolver:
    """A handle solver: a registered name (made with ``options``) or a solver object (used as it is).

    ``ground_truth``: a callable returning the target handle's true box (x0, y0, x1, y1, px) or None,
    given only to solvers that read the simulator (``needs_ground_truth``); such a solver without
    one, or with ``for_agent`` (an agent may not read the simulator), is an error naming it."""
    if not isinstance(solver, str):
        return solver
    if needs_ground_truth(solver):
        if for_agent:
            raise ValueError(f"solver {solver!r} reads the simulator's ground truth, which an agent may not; "
                             f"run it with `opend run --solver {solver}`")
        if ground_truth is None:
            raise ValueError(f"solver {solver!r} reads the simulator's ground truth: give it a ground_truth callback")
        options = {**options, "ground_truth": ground_truth}
    return solver_factory(solver)(**options)


def agent_solver(solver: str, **options) -> Callable[[], HandleSolver]:
    """For an agent: the builder of the registered solver ``solver`` (made on first use, with
    ``options``); a solver that reads the simulator is refused at once, with the reason."""
    if needs_ground_truth(solver):
        build_solver(solver, for_agent=True)  # raises, naming the solver
    return lambda: build_solver(solver, for_agent=True, **options)


def planner_config(hand: HandModel, pull: str = "arc", use_grasp_file: bool = True,
                   overrides: dict | tuple = ()) -> PlannerConfig:
    """The planner's configuration for ``hand``: ``pull`` ("arc" | "straight"), the hand's grasp tuning
    where ``use_grasp_file`` and it has one, then ``overrides`` (``{"grasp.close_scale": 0.9}``).
    Overrides of the grasp search's keys (:data:`GRASP_SEARCH_KEYS`) reset the knob orientation."""
    config = PlannerConfig(pull=pull)
    grasp = hand.grasp if use_grasp_file else None
    if grasp is not None:
        config = grasp.apply(config)
    overrides = dict(overrides)
    if overrides:
        config = config.override(overrides)
        if grasp is not None and any(k in overrides for k in GRASP_SEARCH_KEYS) \
                and "grasp.knob_orientation" not in overrides:
            config = config.override({"grasp.knob_orientation": PlannerConfig().grasp.knob_orientation})
    return config


def build_planner(solver: str | Any, hand: str | HandModel, *, pull: str = "arc", use_grasp_file: bool = True,
                  overrides: dict | tuple = (), ground_truth: Callable[[], Any] | None = None,
                  on_stage: Callable[[str, dict], None] | None = None, **solver_options) -> Planner:
    """The planner around a handle solver (a name or an object; see :func:`build_solver`) for ``hand``
    (a name or a :class:`~opend_mj.sim.hands.HandModel`), configured by :func:`planner_config`."""
    model = get_hand(hand) if isinstance(hand, str) else hand
    config = planner_config(model, pull=pull, use_grasp_file=use_grasp_file, overrides=overrides)
    return Planner(build_solver(solver, ground_truth, **solver_options), model, config, on_stage=on_stage)
