"""Matching handle boxes in an image to an instruction with Algorithm 1 (no torch needed)."""

from __future__ import annotations

import math

import numpy as np

from opend_mj.language import (
    Description,
    LanguageConfig,
    LanguageInvalid,
    TargetLayout,
    describe,
    describe_instruction,
    levels,
)


def _label_index(label: str, n: int, labels: dict[int, tuple[str, ...]]) -> float:
    """Where a label sits among n levels (0 = first); for an unknown count, by its meaning."""
    if n in labels and label in labels[n]:
        return float(labels[n].index(label))
    meaning = {"": (n - 1) / 2, "top": 0, "left": 0, "second top": 1, "second left": 1, "middle": (n - 1) / 2,
               "second bottom": n - 2, "second right": n - 2, "bottom": n - 1, "right": n - 1}
    return float(meaning.get(label, (n - 1) / 2))


def box_layout_points(boxes: np.ndarray, depth: np.ndarray | None = None, camera_view=None) -> np.ndarray:
    """(N, 2) positions (horizontal, vertical) of box centres: +horizontal = viewer's left, +vertical = up.

    With depth and a camera view: metres, from the world point at the box centre (the nearest depth
    inside the box, i.e. the handle's front). Otherwise: pixels (-u, -v).
    """
    boxes = np.asarray(boxes, float).reshape(-1, 4)
    uc = 0.5 * (boxes[:, 0] + boxes[:, 2])
    vc = 0.5 * (boxes[:, 1] + boxes[:, 3])
    if depth is None or camera_view is None:
        return np.stack([-uc, -vc], axis=1)
    h, w = depth.shape
    out = []
    for (u0, v0, u1, v1), u, v in zip(boxes, uc, vc):
        a, b = int(max(0, math.floor(v0))), int(min(h, math.ceil(v1)))
        c, d = int(max(0, math.floor(u0))), int(min(w, math.ceil(u1)))
        patch = depth[a:max(b, a + 1), c:max(d, c + 1)]
        patch = patch[np.isfinite(patch) & (patch > 0.05)]
        z = float(np.percentile(patch, 10)) if patch.size else float(np.median(depth[depth > 0.05]))
        p = camera_view.backproject(u, v, z)
        out.append([p[1], p[2]])
    return np.asarray(out, float)


def _layout_language(depth, camera_view, config: LanguageConfig, pixel_tolerance: float) -> LanguageConfig:
    """Algorithm 1's labels with the level tolerance of the frame the box layout is in (metres with
    depth and a camera view, else pixels)."""
    metric = depth is not None and camera_view is not None
    return LanguageConfig(level_tolerance=config.level_tolerance if metric else pixel_tolerance,
                          vertical_labels=config.vertical_labels, horizontal_labels=config.horizontal_labels)


def _named_member(pts: np.ndarray, members, named: Description, lang: LanguageConfig) -> int | None:
    """The one of ``members`` (indices into ``pts``, taken as handles of the ``named`` kind) that
    Algorithm 1 describes as ``named``; None if they cannot all be described, or if none or several
    read so."""
    layout = [TargetLayout(key=str(i), kind=named.kind, y=float(pts[i, 0]), z=float(pts[i, 1])) for i in members]
    try:
        desc = describe(layout, lang)
    except LanguageInvalid:
        return None
    hits = [int(k) for k, d in desc.items() if (d.vertical, d.horizontal) == (named.vertical, named.horizontal)]
    return hits[0] if len(hits) == 1 else None


def match_instruction(boxes, instruction: str, depth: np.ndarray | None = None, camera_view=None,
                      scores=None, config: LanguageConfig = LanguageConfig(),
                      pixel_tolerance: float = 6.0) -> int | None:
    """Index of the box that the instruction names, or None if there are no boxes.

    All boxes are taken to be handles of the instruction's kind (door/drawer). See the module doc.
    """
    boxes = np.asarray(boxes, float).reshape(-1, 4)
    if len(boxes) == 0:
        return None
    scores = np.ones(len(boxes)) if scores is None else np.asarray(scores, float)
    named = describe_instruction(instruction)
    vertical, horizontal = named.vertical, named.horizontal
    pts = box_layout_points(boxes, depth, camera_view)
    lang = _layout_language(depth, camera_view, config, pixel_tolerance)
    tol = lang.level_tolerance
    hit = _named_member(pts, range(len(boxes)), named, lang)
    if hit is not None:
        return hit
    # nearest by rank: rows from the top, columns from the left within the row
    rows = levels(list(pts[:, 1]), tol, descending=True)
    n_rows = max(rows) + 1
    want_row = _label_index(vertical, n_rows, config.vertical_labels)
    best, best_cost = None, None
    for i in range(len(boxes)):
        members = [j for j in range(len(boxes)) if rows[j] == rows[i]]
        cols = levels([pts[j, 0] for j in members], tol, descending=True)
        n_cols = max(cols) + 1
        col = cols[members.index(i)]
        want_col = _label_index(horizontal, n_cols, config.horizontal_labels)
        cost = abs(rows[i] - want_row) + abs(col - want_col) - 1e-3 * scores[i]
        if best_cost is None or cost < best_cost:
            best, best_cost = i, cost
    return best


def consistent_choice(boxes, probability, instruction: str, depth: np.ndarray | None = None, camera_view=None,
                      config: LanguageConfig = LanguageConfig(), max_flips: int = 3, max_uncertain: int = 12,
                      certain: float = 0.98, pixel_tolerance: float = 6.0) -> int | None:
    """Index of the named handle when the kind calls are read together with the instruction.

    ``probability`` (N,) is each candidate's probability of being a handle of the instructed kind.
    The instruction says something of the whole set: "door" means one door in view, "left door"
    two or more side by side with the named one leftmost, and so on (Algorithm 1's labels). The
    most probable set of the instructed kind (sum of log-odds kept) whose Algorithm 1 description
    names exactly one member as the instruction does is chosen, changing at most ``max_flips``
    of the ``max_uncertain`` least certain calls (none surer than ``certain`` either way); that
    member's index, or None if no such set.
    """
    from itertools import combinations

    boxes = np.asarray(boxes, float).reshape(-1, 4)
    if not len(boxes):
        return None
    named = describe_instruction(instruction)
    pts = box_layout_points(boxes, depth, camera_view)
    lang = _layout_language(depth, camera_view, config, pixel_tolerance)
    p = np.clip(np.asarray(probability, float), 1e-4, 1 - 1e-4)
    base = p >= 0.5
    cost = np.abs(np.log(p / (1 - p)))
    limit = math.log(certain / (1 - certain))
    uncertain = [int(i) for i in np.argsort(cost, kind="stable")[:max_uncertain] if cost[i] <= limit]
    flips = [c for k in range(max_flips + 1) for c in combinations(uncertain, k)]
    flips.sort(key=lambda c: float(sum(cost[i] for i in c)))
    for flip in flips:
        members = base.copy()
        members[list(flip)] ^= True
        idx = np.nonzero(members)[0]
        hit = _named_member(pts, idx, named, lang) if len(idx) else None
        if hit is not None:
            return hit
    return None


def box_orientation(box) -> str:
    u0, v0, u1, v1 = box
    return "horizontal" if (u1 - u0) >= (v1 - v0) else "vertical"
