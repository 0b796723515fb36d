"""Sliding panels: "drawers" that slide along their front (sideways, or up and down) instead of out.

A drawer's handle that does not come out with the hand (the pull stalls, or the hand comes off it,
within ``PullConfig.drawer_stuck_travel``) is grasped again and slid along its front, across its bar
(a vertical bar is pushed sideways, a horizontal one up or down: a bar is mounted across a panel's
direction of travel, at its leading edge). The panel's body lies on the side where its front plane
reaches farther from the handle in the depth image (:func:`~opend_mj.policy.perception.door_edges`,
:func:`~opend_mj.policy.perception.door_edges_vertical`); it is slid that way first, then the other.
The grasp for the slide (at the depth the handle was seen, a dexterous hand's fingers against the
slide) is chosen by :meth:`~opend_mj.policy.planner.grasp.Grasping.next_grasp`.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from opend_mj.policy.perception import door_edges, door_edges_vertical
from opend_mj.policy.planner.records import PlanResult, PullState
from opend_mj.policy.planner.stage import Stage


class PanelSliding(Stage):
    """The slide variant of the pull: the directions to slide a panel along its front, from the
    episode's handle and first image (``config.perception``)."""

    def slide_directions(self, shape: dict | None = None) -> list:
        """The directions (world unit vectors) to slide a panel whose handle did not come out, in
        the order to try; empty for a knob (no bar to tell the panel's travel). ``shape``: the
        handle as measured (:class:`~opend_mj.policy.perception.HandleShape` as a dict), whose
        protrusion places the panel (the ring around the bar) where the box's own depths may
        reach past the front (a bar as tall as the cabinet)."""
        handle, first = self.episode.handle, self.episode.first
        if handle is None or handle.kind != "bar" or first is None or first.depth is None:
            return []
        if shape is not None and "protrusion" in shape:
            handle = replace(handle, panel_x=handle.front_x + float(shape["protrusion"]))
        axis = 1 if handle.orientation == "vertical" else 2  # world y (sideways) or z (up and down)
        edges_of = door_edges if axis == 1 else door_edges_vertical
        edges = edges_of(handle, first.depth, first.camera_view, self.config.perception)
        plus = np.zeros(3)
        plus[axis] = 1.0
        if edges is None:
            return [plus, -plus]
        centre = float(handle.centre[axis])
        reach_plus, reach_minus = edges[0] - centre, centre - edges[1]  # +y / +z first in both
        return [plus, -plus] if reach_plus >= reach_minus else [-plus, plus]

    def next_slide(self, state: PullState, result: PlanResult) -> bool:
        """Set the next pull direction along the front for a drawer that did not come out; False
        where every direction was tried."""
        if state.slides is None:
            state.slides = self.slide_directions(result.shape)
        if not state.slides:
            return False
        state.direction = state.slides.pop(0)
        result.events.append({"slide": [round(float(v), 3) for v in state.direction]})
        return True
