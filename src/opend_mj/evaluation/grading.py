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


#: Where a failed episode ended (:func:`episode_ending`), in the order an episode gets there.
ENDINGS = ("never_reached", "never_held", "slipped", "stalled", "pushed_back")
#: A part that had opened by this much and ends below half of it was pushed back (open ratio).
PUSHED_BACK_FROM = 0.05
#: The hand still on the part within this many control steps of the end holds it (0.5 s at 60 Hz).
HELD_AT_END = 30


def episode_ending(success: bool, open_ratio: float, closest: float, hold: dict) -> str | None:
    """Where a failed episode ended, from ground truth (for the tables only): ``never_reached`` (the
    hand never came within ``APPROACH_MISS`` of the handle nor touched the part), ``never_held`` (it
    got there but its open ratio never reached ``GRASP_MISS``), ``pushed_back`` (the part had
    opened ``PUSHED_BACK_FROM`` or more and ends below half of its peak), ``slipped`` (it moved the
    part and was off it for the last ``HELD_AT_END`` steps), ``stalled`` (on the part to the end,
    short of success); None for a success. ``closest``: the least distance (m) of the grasp site or
    the hand's gripping surfaces to the handle; ``hold``: `probes.HoldProbe.summary`."""
    if success:
        return None
    touched = hold.get("first_held") is not None
    peak = float(hold.get("peak_ratio", 0.0))
    if closest > APPROACH_MISS and not touched:
        return "never_reached"
    if peak < GRASP_MISS or not touched:
        return "never_held"
    if peak >= PUSHED_BACK_FROM and open_ratio < 0.5 * peak:
        return "pushed_back"
    last = hold.get("last_held")
    if last is None or hold.get("steps", 0) - 1 - last > HELD_AT_END:
        return "slipped"
    return "stalled"
