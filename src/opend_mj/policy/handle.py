"""What a handle solver returns and the interface every solver implements (the planner's input).

Kept apart from the solver registry (`opend_mj.policy.solvers`) so that solvers, learned or not,
import it without importing the registry that imports them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np


@dataclass(frozen=True)
class HandleBox:
    """An image box (pixels, u right, v down) around a handle, optionally with its orientation."""

    u0: float
    v0: float
    u1: float
    v1: float
    orientation: str | None = None  # "horizontal" | "vertical" | None (let the planner decide)
    score: float = 1.0
    #: The box is a handle group found in depth already (a depth proposal): the planner does not
    #: snap it to depth again.
    from_depth: bool = False

    @property
    def centre(self) -> tuple[float, float]:
        return (0.5 * (self.u0 + self.u1), 0.5 * (self.v0 + self.v1))

    @property
    def width(self) -> float:
        return self.u1 - self.u0

    @property
    def height(self) -> float:
        return self.v1 - self.v0

    def as_tuple(self) -> tuple[float, float, float, float]:
        return (float(self.u0), float(self.v0), float(self.u1), float(self.v1))

    def to_dict(self) -> dict:
        return {"box": [round(x, 2) for x in self.as_tuple()], "orientation": self.orientation}


class HandleSolver(Protocol):
    """What the planner needs from a handle solver.

    A solver may also take ``observed=((box, kind), ...)`` in :meth:`solve` (and say so with a class
    attribute ``accepts_observed = True``): handles the robot has pulled and seen the kind of by
    their motion ("drawer": slid out, "door": swung). The planner asks such a solver again after a
    handle of the other kind than the instruction's."""

    name: str

    def solve(self, rgb: np.ndarray, depth: np.ndarray, instruction: str, camera_view: Any) -> HandleBox | None:
        ...
