"""How an episode is labelled from ground truth (for the tables only; no agent ever reads it): whether
a solver's box names the right handle, and the stage where a failed episode went wrong."""

from __future__ import annotations

#: A box centre this close (pixels) outside a handle's box still counts as on that handle.
PAD_PX = 3.0
#: The grasp site ended farther than this (m) from the true handle box: the hand never got there.
APPROACH_MISS = 0.02
#: The target moved less than this fraction of its range: nothing held it.
GRASP_MISS = 0.03


def box_contains(box, u: float, v: float, pad: float = PAD_PX) -> bool:
    """Whether pixel (u, v) lies in ``box`` (u0, v0, u1, v1) grown by ``pad``; False for no box."""
    return box is not None and box[0] - pad <= u <= box[2] + pad and box[1] - pad <= v <= box[3] + pad


def box_centre(box) -> tuple[float, float]:
    return 0.5 * (box[0] + box[2]), 0.5 * (box[1] + box[3])


def failure_stage(success: bool, range_ratio: float, site_to_handle: float, box=None, gt_box=None,
                  check_locate: bool = True) -> str | None:
    """locate / approach / grasp / pull, or None for a success.

    ``box``: the box the policy acted on (checked against the true ``gt_box`` when ``check_locate``;
    agents that report no box are not graded at locate)."""
    if success:
        return None
    if check_locate and (box is None or gt_box is None or not box_contains(gt_box, *box_centre(box))):
        return "locate"
    if site_to_handle > APPROACH_MISS:
        return "approach"
    if range_ratio < GRASP_MISS:
        return "grasp"
    return "pull"
