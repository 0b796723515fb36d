"""The ``fasterrcnn`` handle solver: detections (and depth proposals) matched to the instruction."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from opend_mj.language import describe_instruction
from opend_mj.policy.handle_box import NO_HANDLE, centres_overlap
from opend_mj.policy.learned.detector.matching import box_orientation, consistent_choice, match_instruction
from opend_mj.policy.learned.detector.model import KIND_LABELS, Detections, detect_handles, load_detector
from opend_mj.resources import default_checkpoint


@dataclass(frozen=True)
class MatchConfig:
    """How the solver turns detections (and depth proposals) into the named handle."""

    threshold: float = 0.8  # handle probability of a detection (the paper's 0.8)
    #: Depth proposals (handles standing proud of a panel) that no detection covers join the
    #: candidates when the detector's head calls them a handle with this probability: depth says
    #: where a handle is, the head says whether it is one and of which kind.
    proposal_threshold: float = 0.0
    use_proposals: bool = True
    #: With a kinds detector, candidates of the instructed kind (probability among handle classes).
    kind_threshold: float = 0.5
    #: Only what depth confirms: the candidates are the depth proposals, each scored by the best
    #: detection covering it (else by the head on the proposal's own box), so an edge or a seam the
    #: detector takes for a handle is not one unless it stands proud of a panel like a handle.
    #: Why: the detector learnt generated handles, so its own handle probability rejects many real
    #: ones, while its drawer / door call on a box that depth proposes holds (chosen on the real
    #: train part of the OpenD training cabinets and the procedural train split).
    depth_verified: bool = True
    #: With a kinds detector, read the kind calls together with the instruction
    #: (:func:`consistent_choice`) before falling back to the kind threshold and Algorithm 1's
    #: nearest rank. ``handle_weight``: the exponent of the handle probability in the probability
    #: that a candidate is a handle of the instructed kind (0: the kind call alone).
    consistent: bool = True
    handle_weight: float = 0.0
    certain: float = 0.98
    #: Prior odds door : drawer of a vertical bar (a candidate box at least ``vertical_aspect`` times
    #: taller than wide), multiplied into the detector's kind odds. Real cabinets put vertical bars on
    #: doors: 56 of the 59 vertical bars of the real train part's 191 targets (horizontal bars:
    #: 38 doors, 78 drawers; no prior there). 1: no prior.
    vertical_door_odds: float = 56.0 / 3.0
    vertical_aspect: float = 2.5
    #: Thin pulls (:func:`opend_mj.policy.perception.thin_proposals`: a few millimetres proud, which
    #: depth alone cannot tell from a front's moulding, while the detector alone calls seams handles
    #: on real images) join the candidates where a detection of handle probability
    #: ``thin_threshold`` or more covers them: both must agree.
    thin: bool = True
    thin_threshold: float = 0.9
    #: Depth so noisy that handles sink into it (a real sensor 2 m off) is also searched averaged
    #: along bars and over knobs (:data:`opend_mj.policy.perception.proposals.NOISE_WINDOWS`); the
    #: head, which scores each proposal's own box, rejects the edges the averaging turns into ridges.
    noise_windows: bool = True


def observed_members(boxes: np.ndarray, observed: tuple) -> list[tuple[int, str]]:
    """(candidate index, kind) for each candidate box that an observed box (u0, v0, u1, v1) covers
    (either holds the other's centre): the handles the robot has moved and seen the kind of."""
    boxes = np.asarray(boxes, float).reshape(-1, 4)
    out = []
    for box, kind in observed:
        if len(boxes):
            hit = centres_overlap(boxes, np.asarray(box, float).reshape(1, 4))[:, 0]
            out.extend((int(i), kind) for i in np.nonzero(hit)[0])
    return out


def apply_observed_kinds(boxes: np.ndarray, kind: np.ndarray, observed: tuple) -> np.ndarray:
    """The kind probabilities (N, K) with the calls of observed handles made certain: a handle that
    slid out is a drawer's, one that swung about a hinge a door's, whatever the image said."""
    if not observed or kind.shape[1] < 2:
        return kind
    kind = kind.copy()
    for i, k in observed_members(boxes, observed):
        if k in KIND_LABELS:
            kind[i] = 1e-4
            kind[i, KIND_LABELS[k] - 1] = 1.0 - 1e-4 * (kind.shape[1] - 1)
    return kind


def vertical_bar_prior(boxes: np.ndarray, kind: np.ndarray, door_odds: float, aspect: float = 2.5) -> np.ndarray:
    """The kind probabilities (N, K; drawer, door) with the door : drawer odds of every vertical bar
    (box height >= ``aspect`` x width) multiplied by ``door_odds``: a handle's orientation is the
    same on real and generated images, where the detector's kind call, learnt on generated ones,
    is not."""
    boxes = np.asarray(boxes, float).reshape(-1, 4)
    if door_odds == 1.0 or kind.shape[1] < 2 or not len(boxes):
        return kind
    vertical = (boxes[:, 3] - boxes[:, 1]) >= aspect * np.maximum(boxes[:, 2] - boxes[:, 0], 1e-6)
    if not vertical.any():
        return kind
    kind = kind.copy()
    d, r = KIND_LABELS["door"] - 1, KIND_LABELS["drawer"] - 1
    door = kind[vertical, d] * door_odds
    total = door + kind[vertical, r]
    kind[vertical, d], kind[vertical, r] = door / np.maximum(total, 1e-12), kind[vertical, r] / np.maximum(total, 1e-12)
    return kind


def select_handle(found: Detections, proposals: Detections | None, instruction: str, depth=None,
                  camera_view=None, config: MatchConfig = MatchConfig(),
                  observed: tuple = ()) -> tuple[np.ndarray, float] | None:
    """(box, handle probability) of the handle the instruction names, or None without candidates.

    Candidates: detections above ``threshold``, plus depth proposals no detection covers that the
    head calls handles; with a kinds detector, those of the instructed kind (all of them where none
    is); Algorithm 1 (:func:`match_instruction`) picks among them. ``observed``: (box, kind) pairs
    of handles whose kind the robot saw by moving them (:func:`apply_observed_kinds`); their calls
    are certain; candidates an observed box of kind ``NO_HANDLE`` covers (the hand closed on nothing
    there) are dropped."""
    keep = found.handle >= config.threshold
    boxes, handle, kind = found.boxes[keep], found.handle[keep], found.kind[keep]
    if config.depth_verified and proposals is not None and len(proposals.boxes):
        covering, covering_handle, covering_kind = boxes, handle, kind
        handle, kind = proposals.handle.copy(), proposals.kind.copy()
        if len(covering):
            cover = centres_overlap(proposals.boxes, covering)
            for i in np.nonzero(cover.any(1))[0]:
                j = np.nonzero(cover[i])[0]
                j = j[np.argmax(covering_handle[j])]
                handle[i], kind[i] = max(handle[i], covering_handle[j]), covering_kind[j]
        add = handle >= config.proposal_threshold
        boxes, handle, kind = proposals.boxes[add], handle[add], kind[add]
    elif config.use_proposals and proposals is not None and len(proposals.boxes):
        add = proposals.handle >= config.proposal_threshold
        if len(boxes):
            add &= ~centres_overlap(proposals.boxes, boxes).any(1)
        boxes = np.concatenate([boxes, proposals.boxes[add]])
        handle = np.concatenate([handle, proposals.handle[add]])
        kind = np.concatenate([kind, proposals.kind[add]])
    if observed and len(boxes):  # boxes the hand found empty are no candidates
        empty = [i for i, k in observed_members(boxes, observed) if k == NO_HANDLE]
        if empty:
            keep = np.ones(len(boxes), bool)
            keep[empty] = False
            boxes, handle, kind = boxes[keep], handle[keep], kind[keep]
    if not len(boxes):
        return None
    kind = vertical_bar_prior(boxes, kind, config.vertical_door_odds, config.vertical_aspect)
    kind = apply_observed_kinds(boxes, kind, observed)
    named = describe_instruction(instruction)
    if config.consistent and kind.shape[1] > 1 and named.kind in KIND_LABELS:
        p = kind[:, KIND_LABELS[named.kind] - 1] * np.clip(handle, 1e-4, 1.0) ** config.handle_weight
        i = consistent_choice(boxes, p, instruction, depth, camera_view, certain=config.certain)
        if i is not None:
            return boxes[i], float(handle[i])
    if kind.shape[1] > 1 and named.kind in KIND_LABELS:
        of_kind = kind[:, KIND_LABELS[named.kind] - 1] >= config.kind_threshold
        if of_kind.any():
            boxes, handle = boxes[of_kind], handle[of_kind]
    if not named.vertical and not named.horizontal:  # "drawer", "door": the one most like a handle
        i = int(np.argmax(handle))
        return boxes[i], float(handle[i])
    i = match_instruction(boxes, instruction, depth, camera_view, handle)
    return (boxes[i], float(handle[i])) if i is not None else None


def confirmed(boxes: np.ndarray, found: Detections, threshold: float) -> np.ndarray:
    """(N,) bool: which ``boxes`` a detection of handle probability ``threshold`` or more covers
    (either holds the other's centre)."""
    boxes = np.asarray(boxes, float).reshape(-1, 4)
    sure = found.boxes[found.handle >= threshold]
    if not len(boxes) or not len(sure):
        return np.zeros(len(boxes), bool)
    return centres_overlap(boxes, sure).any(1)


class FasterRCNNSolver:
    """Handle solver: Faster R-CNN detections (and the depth proposals its head accepts) matched
    to the instruction with Algorithm 1; see :func:`select_handle`."""

    name = "fasterrcnn"
    needs_ground_truth = False

    def __init__(self, checkpoint: Path | str | None = None, threshold: float | None = None, device: str | None = None,
                 proposals: bool = True, canonical: bool = True, **match):
        """``threshold`` None: the checkpoint's ``threshold`` (0.8, the paper's, unless it says
        otherwise); ``match``: other :class:`MatchConfig` fields."""
        self.model, self.config, self.checkpoint = load_detector(checkpoint, device)
        threshold = float(threshold if threshold is not None else self.checkpoint.get("threshold", 0.8))
        self.match = MatchConfig(threshold=threshold, use_proposals=proposals, **match)
        #: Read the instruction through Algorithm 1's parser first, so reworded instructions name
        #: the same position and kind.
        self.canonical = canonical
        self.last_detections: Detections | None = None

    #: :meth:`solve` takes ``observed``: handles whose kind the robot saw by moving them.
    accepts_observed = True

    def solve(self, rgb, depth, instruction, camera_view, observed: tuple = ()):
        """The named handle's box; ``observed``: ((u0, v0, u1, v1), "drawer" | "door" | NO_HANDLE)
        pairs of handles the robot moved and saw the kind of, or of boxes it found empty (a retry
        after a wrong handle or an empty box)."""
        from opend_mj.language import canonical_instruction
        from opend_mj.policy.handle_box import HandleBox

        if self.canonical:
            instruction = canonical_instruction(instruction)
        extra = thin = None
        if self.match.use_proposals and depth is not None and camera_view is not None:
            from opend_mj.policy.perception import ProposalConfig, handle_proposals, thin_proposals
            from opend_mj.policy.perception.proposals import NOISE_WINDOWS

            windows = NOISE_WINDOWS if self.match.noise_windows else ()
            main = handle_proposals(depth, camera_view, ProposalConfig(noise_windows=windows))
            extra = np.array([box for box, _ in main], float).reshape(-1, 4)
            thin = np.array([box for box, _ in (thin_proposals(depth, camera_view, main) if self.match.thin else [])],
                            float).reshape(-1, 4)
        found, scored = detect_handles(self.model, rgb, None if extra is None else np.concatenate([extra, thin]),
                                       depth=depth)
        self.last_detections = found
        if thin is not None and len(thin):
            held = np.concatenate([np.ones(len(extra), bool), confirmed(thin, found, self.match.thin_threshold)])
            scored = Detections(scored.boxes[held], scored.handle[held], scored.kind[held])
            extra = scored.boxes
        chosen = select_handle(found, scored if extra is not None else None, instruction, depth, camera_view,
                               self.match, observed=tuple(observed))
        if chosen is None:
            return None
        b, score = chosen
        from_depth = self.match.depth_verified and extra is not None and len(extra) > 0
        return HandleBox(float(b[0]), float(b[1]), float(b[2]), float(b[3]), orientation=box_orientation(b),
                         score=score, from_depth=from_depth)


#: The file name of the detector trained on a real depth sensor's images as well as exact renders
#: (`opend train --depth-noise`; checkpoints/README.md), found by `opend_mj.resources.default_checkpoint`.
SENSOR_CHECKPOINT = "fasterrcnn_sensor.pt"


class SensorFasterRCNNSolver(FasterRCNNSolver):
    """``fasterrcnn-sensor``: the Faster R-CNN solver with the detector trained on the depth_noise
    sensor's depth too (noise growing with distance, holes at edges and on dark surfaces), whose
    relief channel reads holes as holes; the rest as :class:`FasterRCNNSolver`."""

    name = "fasterrcnn-sensor"

    def __init__(self, checkpoint: Path | str | None = None, **options):
        super().__init__(checkpoint if checkpoint is not None else default_checkpoint(SENSOR_CHECKPOINT), **options)
