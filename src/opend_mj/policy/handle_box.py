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


def centres_overlap(a, b) -> np.ndarray:
    """(len(a), len(b)) True where a box (u0, v0, u1, v1) of ``a`` holds the centre of a box of ``b``
    or the reverse: the two boxes are on one handle."""
    a = np.asarray(a, float).reshape(-1, 4)
    b = np.asarray(b, float).reshape(-1, 4)
    ca = np.stack([(a[:, 0] + a[:, 2]) / 2, (a[:, 1] + a[:, 3]) / 2], 1)
    cb = np.stack([(b[:, 0] + b[:, 2]) / 2, (b[:, 1] + b[:, 3]) / 2], 1)

    def inside(boxes, pts):
        return ((pts[None, :, 0] >= boxes[:, None, 0]) & (pts[None, :, 0] <= boxes[:, None, 2])
                & (pts[None, :, 1] >= boxes[:, None, 1]) & (pts[None, :, 1] <= boxes[:, None, 3]))

    return inside(a, cb) | inside(b, ca).T


#: The kind of an observed box (``observed`` of :meth:`HandleSolver.solve`) where the hand felt
#: nothing: every grasp tried there closed on air, so no handle is there whatever the image said
#: (noisy depth proposes ridges that are none).
NO_HANDLE = "none"


class HandleSolver(Protocol):
    """What the planner needs from a handle solver.

    A solver may also take ``observed=((box, kind), ...)`` in :meth:`solve` (and say so with a class
    attribute ``accepts_observed = True``): handles the robot has pulled and seen the kind of by
    their motion ("drawer": slid out, "door": swung), or ``NO_HANDLE`` where the fingers closed on
    nothing there at all. The planner asks such a solver again after a handle of the other kind than
    the instruction's, and after a box with no handle in it."""

    name: str

    def solve(self, rgb: np.ndarray, depth: np.ndarray, instruction: str, camera_view: Any) -> HandleBox | None:
        ...
