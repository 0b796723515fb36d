"""The thresholds of the planner's perception, in one frozen dataclass (metres unless named otherwise).

How far a handle stands out of its panel is read for three purposes, each with its own range:

* ``PerceptionConfig.snap_protrusion`` (1.5-8 cm): the pixels in and around a solver's box that are
  its handle, to snap the box to it (:func:`refine_box_with_depth`) or to pick one of a pair of
  pulls under one box (:func:`one_of_paired_handles`). Strict: the box already says where to look.
* ``PerceptionConfig.neighbour_protrusion`` (0.8 cm and more): anything beside the handle that
  stands out of the panel is an obstacle the hand must clear (:func:`measure_handle`).
* ``ProposalConfig.min_protrusion`` / ``max_protrusion`` (1.2-9 cm): the whole-image search for
  handle candidates (:func:`handle_proposals`); wider, because a learned solver's map then
  picks among the candidates.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from opend_mj.policy.perception.front import FrontMotionConfig


@dataclass(frozen=True)
class PerceptionConfig:
    """What the planner reads from the depth image: the 3D handle, its shape, the door's hinge side
    and how a pulled front moved."""

    #: depth readings nearer than this (m) are no reading (a hole in the depth image)
    min_depth: float = 0.05
    #: the handle's front: this percentile of the world x of the box's pixels (the nearest few per
    #: cent: robust to a stray pixel); the panel behind it (a loose box): this percentile
    front_percentile: float = 3.0
    #: depth noise (m, `noise.pixel_noise` around the box) below this is none: exact depth reads
    #: exactly as it did. Above it, the front percentile is moved back by ``front_noise_shift`` sigmas
    #: (a normal's 3rd percentile lies 1.88 sigma below its mean) and the bar takes ``bar_noise_depth``
    #: sigmas more behind the front
    noise_floor: float = 0.001
    front_noise_shift: float = 1.88
    bar_noise_depth: float = 2.0
    panel_percentile: float = 95.0
    #: the panel behind a handle is at most this far (m) behind the handle's front: depths farther in
    #: and around its box (the floor below a door's bottom edge, the room beside the cabinet) are not it
    panel_max_behind: float = 0.1
    #: largest half-thickness of a bar: the grip centre is the front seen in depth plus this (m)
    handle_radius: float = 0.007
    #: handles whose box aspect (long / short, on the handle's plane) is below ``knob_aspect`` and
    #: whose long side is below ``knob_size`` (m) are knobs
    knob_aspect: float = 1.6
    knob_size: float = 0.055
    #: the panel around a box: the median depth of a ring ``panel_band`` (m) wide around it, read
    #: where it holds ``panel_min_pixels`` or more. A box with fewer than ``panel_share`` of its pixels
    #: within ``panel_near`` (m) of that depth holds only the handle (a box snapped to it in depth):
    #: its far depths are the bar, and the ring's depth is the panel
    panel_band: float = 0.04
    panel_min_pixels: int = 5
    panel_near: float = 0.01
    panel_share: float = 0.1
    #: the handle's shape: pixels in the box within ``bar_depth`` (m) of its front are the bar; the
    #: free space around the handle is looked for up to ``search_radius`` (m) from its box
    bar_depth: float = 0.006
    search_radius: float = 0.15
    #: what stands ``neighbour_protrusion`` (m) or more out of the panel beside the handle is an
    #: obstacle (another handle, a frame); pixels within ``handle_margin`` (m) of the handle's box
    #: are the handle's own; an obstacle counts for a side (up / down / left / right) when within
    #: ``neighbour_band`` (m) of the handle's extent across that side
    neighbour_protrusion: float = 0.008
    #: under depth noise a neighbour stands ``neighbour_noise_depth`` sigmas more out of the panel
    #: (`HandleEstimate.noise`): a lone noisy pixel is no obstacle
    neighbour_noise_depth: float = 3.0
    handle_margin: float = 0.01
    neighbour_band: float = 0.03
    #: handle pixels in and around a solver's box stand ``snap_protrusion`` (m, min, max) out of the
    #: panel; a box is snapped within ``snap_margin_px`` pixels around it; groups of fewer than
    #: ``min_group_pixels`` pixels are noise
    snap_protrusion: tuple = (0.015, 0.08)
    snap_margin_px: int = 12
    min_group_pixels: int = 3
    #: a pair of pulls under one box: the panel is read ``paired_ring_px`` pixels around the box;
    #: the box's centre (within ``paired_centre_px`` pixels) shows bare panel
    paired_ring_px: int = 6
    paired_centre_px: int = 2
    #: a door's front plane: pixels within ``plane_tolerance`` (m) of the panel behind the handle,
    #: along the image row through it; the plane ends after more than ``plane_gap_pixels`` off it
    plane_tolerance: float = 0.03
    plane_gap_pixels: int = 3
    #: the hinge side: where the plane reaches farther from the handle, when one side reaches at
    #: least ``hinge_min_reach`` (m) and the sides differ by ``hinge_min_difference`` (m) or more
    hinge_min_reach: float = 0.05
    hinge_min_difference: float = 0.02
    #: how a pulled front moved (:func:`front_motion`)
    front: FrontMotionConfig = field(default_factory=FrontMotionConfig)
