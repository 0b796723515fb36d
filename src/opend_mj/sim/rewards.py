"""Rewards for learning agents: the benchmark's sparse success and a dense shaping in [0, 1].

The benchmark itself scores only the final state (`sim.task.SuccessChecker`: the instructed target's
open ratio above 20 %). RL from scratch needs a signal before the target moves, so the environments
(`sim.envs`, `sim.gym_env`) also offer a dense reward built from four terms, each in [0, 1]:

* ``reach``: progress of the grasp site toward the instructed handle, relative to where the episode
  started: ``(d0 - d - dead_zone) / (d0 - dead_zone)`` clipped to [0, 1], where ``d`` is the
  distance from the grasp site to the handle's box (0 inside it) and ``d0`` that distance at reset.
  The dead zone (2 cm) keeps a hand that settles on its weld at 0.
* ``contact``: 1 while any geom of the hand touches a handle geom of the instructed target.
* ``open``: ``(open_ratio - 0.005) / (threshold - 0.005)`` clipped to [0, 1]: 1 at the success
  threshold (the 0.5 % dead zone ignores a closed target resting against its stop).
* ``others``: the largest fraction of its range that any *other* target opened, divided by 0.1 and
  clipped to [0, 1] (a penalty: 1 when another door or drawer opened 10 % of its range).

``dense = (1 * reach + 1 * contact + 2 * open) / 4 * (1 - 0.5 * others)``, and 1 on success with no
other target moved. As in ManiSkill3's normalised dense reward, every step's reward lies in [0, 1];
a hand that never moves gets 0 on every step. ``sparse`` is 1 on a success step, else 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

REWARD_MODES = ("dense", "sparse")


@dataclass(frozen=True)
class DenseRewardConfig:
    """Weights and dead zones of the dense reward (see the module doc)."""

    reach_weight: float = 1.0
    contact_weight: float = 1.0
    open_weight: float = 2.0
    reach_dead_zone: float = 0.02  # m
    open_dead_zone: float = 0.005  # open ratio
    #: range ratio of another target at which the penalty is full
    others_full: float = 0.1
    #: fraction of the reward taken away at full penalty
    others_penalty: float = 0.5


@dataclass(slots=True)
class RewardTerms:
    """What the dense reward is computed from (also handed out in ``info["reward_terms"]``)."""

    distance: float  # grasp site to the instructed handle's box (m)
    start_distance: float  # the same at reset
    contact: bool
    open_ratio: float
    others_range: float  # largest range ratio among the other targets
    success: bool
    others_moved: bool
    reach: float = 0.0
    open: float = 0.0
    others: float = 0.0
    range_ratio: float = 0.0  # fraction of the instructed target's joint range opened

    def to_dict(self) -> dict:
        """The fields as a plain dict (what ``asdict`` gives, without its deep copy: all are scalars)."""
        return {"distance": self.distance, "start_distance": self.start_distance, "contact": self.contact,
                "open_ratio": self.open_ratio, "others_range": self.others_range, "success": self.success,
                "others_moved": self.others_moved, "reach": self.reach, "open": self.open, "others": self.others,
                "range_ratio": self.range_ratio}


def clip01(x: float, lo: float = 0.0, hi: float = 1.0) -> float:
    """``float(np.clip(x, lo, hi))`` for a Python float, without numpy's call overhead (about 3 us).

    Same result to the bit, signed zeros and NaN included: numpy's clip is ``min(max(x, lo), hi)``
    with ``max(a, b) = a if a > b else b`` and NaN passed through.
    """
    if x != x:
        return x
    x = x if x > lo else lo
    return x if x < hi else hi


def dense_reward(terms: RewardTerms, threshold: float, config: DenseRewardConfig = DenseRewardConfig()) -> float:
    """The dense reward in [0, 1]; fills ``terms.reach``, ``terms.open`` and ``terms.others``."""
    c = config
    span = terms.start_distance - c.reach_dead_zone
    if span > 1e-9:
        terms.reach = clip01((terms.start_distance - terms.distance - c.reach_dead_zone) / span)
    else:  # started at the handle already
        terms.reach = 1.0 if terms.distance <= c.reach_dead_zone else 0.0
    terms.open = clip01((terms.open_ratio - c.open_dead_zone) / max(threshold - c.open_dead_zone, 1e-9))
    terms.others = clip01(terms.others_range / c.others_full)
    if terms.success and not terms.others_moved:
        return 1.0
    total = c.reach_weight + c.contact_weight + c.open_weight
    base = (c.reach_weight * terms.reach + c.contact_weight * float(terms.contact) + c.open_weight * terms.open) / total
    return clip01(base * (1.0 - c.others_penalty * terms.others))


def sparse_reward(terms: RewardTerms) -> float:
    return 1.0 if terms.success else 0.0


_BOX_SIGNS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)


class RewardProbe:
    """Reads the reward terms from a task's physics (ground truth: for rewards and labels only).

    Built per compiled scene. Everything a step reads is bound once: the hand's and each target's
    handle geoms as boolean masks over the model's geoms, each handle geom's box corners in its own
    frame, the target joints' qpos addresses. `read` is the per-step path (no name look-ups, no
    per-geom Python sets); `terms` computes the same terms the straightforward way and is kept as
    the reference that `read` is tested against, bit for bit.
    """

    def __init__(self, task, physics):
        model = physics.model.ptr
        self.task = task
        self._model = model
        self._data = physics.data.ptr
        root = physics.model.name2id(task.hand.root_body.full_identifier, "body")
        hand_bodies = np.flatnonzero(model.body_rootid == model.body_rootid[root])
        self._hand_geoms = np.flatnonzero(np.isin(model.geom_bodyid, hand_bodies))
        self._hand_mask = np.zeros(model.ngeom, dtype=bool)
        self._hand_mask[self._hand_geoms] = True
        self._site = physics.model.name2id(task.hand.grasp_site.full_identifier, "site")
        self._handles: dict[str, np.ndarray] = {}
        self._qpos: dict[str, int] = {t.joint: int(physics.bind(task.cabinet.joint_element(t.joint)).qposadr)
                                      for t in task.cabinet.targets}
        self._joints = list(self._qpos)
        self._targets = [task.cabinet.target(j) for j in self._joints]
        self._addresses = np.array([self._qpos[j] for j in self._joints], dtype=int)
        #: (joint, handle geom ids, their corners in the geom frame, handle mask, their bodies, views
        #: of those bodies' xpos and xquat rows, (per-target ratio constants, the instructed
        #: target's open span and range span))
        self._bound: tuple | None = None
        self._box_cache: tuple = (None, None)  # (pose bytes of the handle bodies, (lo, hi))
        self.start_distance = 0.0
        self._zeros3 = np.zeros(3)
        self._outside = np.zeros(3)  # `distance`'s per-axis distances outside the box
        self._site_pos = self._data.site_xpos[self._site]  # a view of the grasp site's position

    def handle_geoms(self, joint: str) -> np.ndarray:
        ids = self._handles.get(joint)
        if ids is None:
            import mujoco

            target = self.task.cabinet.target(joint)
            ids = np.array([mujoco.mj_name2id(self._model, mujoco.mjtObj.mjOBJ_GEOM, f"cabinet/{g}")
                            for g in target.handle_geoms], dtype=int)
            self._handles[joint] = ids = ids[ids >= 0]
        return ids

    def _bind(self, joint: str) -> tuple:
        """The instructed target's handle geoms, their corners (8 x 3 each, geom frame), and mask."""
        bound = self._bound
        if bound is None or bound[0] != joint:
            ids = self.handle_geoms(joint)
            aabb = self._model.geom_aabb
            local = np.array([_BOX_SIGNS * aabb[g, 3:] + aabb[g, :3] for g in ids]).reshape(-1, 8, 3)
            mask = np.zeros(self._model.ngeom, dtype=bool)
            mask[ids] = True
            bodies = np.unique(self._model.geom_bodyid[ids]) if len(ids) else np.zeros(0, dtype=int)
            # views of those bodies' position and quaternion rows (the box cache's key)
            poses = [row for b in bodies for row in (self._data.xpos[b], self._data.xquat[b])]
            # per target in `_joints` order: (is the instructed one, closed value, open sign, range span)
            ratios = [(t.joint == joint, t.closed, t.open_sign, t.range_span) for t in self._targets]
            target = self.task.cabinet.target(joint)
            ratios = (ratios, target.open_span, target.range_span)  # and the instructed target's spans
            self._bound = bound = (joint, np.asarray(ids, dtype=int), local, mask, bodies, poses, ratios)
            self._box_cache = (None, None)
        return bound

    def handle_box(self, joint: str | None = None) -> tuple[np.ndarray, np.ndarray]:
        """World axis-aligned box (min, max) around the target's handle geoms, as they are now.

        For the instructed target the box is kept while the bodies that carry the handle geoms have
        the same pose to the bit (a geom's pose is a function of its body's position and quaternion),
        which is most steps: a closed door or drawer does not move.
        """
        if joint is not None and joint != self.task.target.joint:
            return self._handle_box(joint)
        lo, hi = self.target_box()
        return lo.copy(), hi.copy()

    def target_box(self) -> tuple[np.ndarray, np.ndarray]:
        """`handle_box` of the instructed target, the cached arrays themselves (not to be changed)."""
        joint, bound = self.task.target.joint, self._bound
        if bound is None or bound[0] != joint:
            bound = self._bind(joint)
        rows = bound[5]
        key = (rows[0].tobytes() + rows[1].tobytes() if len(rows) == 2  # one body: the usual case
               else b"".join([row.tobytes() for row in rows]))
        cached_key, box = self._box_cache
        if key != cached_key:
            box = self._handle_box(self.task.target.joint)
            self._box_cache = (key, box)
        return box

    def _handle_box(self, joint: str) -> tuple[np.ndarray, np.ndarray]:
        """`handle_box` computed now (all handle geoms' box corners in one batched product)."""
        if joint == self.task.target.joint:
            _, ids, local, _, _, _, _ = self._bind(joint)
        else:
            ids = self.handle_geoms(joint)
            aabb = self._model.geom_aabb
            local = np.array([_BOX_SIGNS * aabb[g, 3:] + aabb[g, :3] for g in ids]).reshape(-1, 8, 3)
        data = self._data
        if not len(ids):  # a target without handle geoms: its closed handle box (cabinet at the origin)
            lo, hi = self.task.cabinet.target(joint).handle_box
            return np.asarray(lo, float), np.asarray(hi, float)
        xmat, xpos = data.geom_xmat, data.geom_xpos
        if len(ids) == 1:
            g = ids[0]
            pts = local[0] @ xmat[g].reshape(3, 3).T + xpos[g]
        else:  # one batched product: the same per-geom 8x3 @ 3x3 products (tested equal to the bit)
            pts = (np.matmul(local, xmat[ids].reshape(-1, 3, 3).transpose(0, 2, 1))
                   + xpos[ids][:, None, :]).reshape(-1, 3)
        return pts.min(axis=0), pts.max(axis=0)

    def handle_box_reference(self, joint: str | None = None) -> tuple[np.ndarray, np.ndarray]:
        """`handle_box` computed the straightforward way, one geom at a time (the reference)."""
        joint = joint or self.task.target.joint
        model, data = self._model, self._data
        corners = []
        for gid in self.handle_geoms(joint):
            aabb = model.geom_aabb[gid]
            local = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * aabb[3:] + aabb[:3]
            corners.append(local @ data.geom_xmat[gid].reshape(3, 3).T + data.geom_xpos[gid])
        if not corners:
            lo, hi = self.task.cabinet.target(joint).handle_box
            return np.asarray(lo, float), np.asarray(hi, float)
        pts = np.vstack(corners)
        return pts.min(axis=0), pts.max(axis=0)

    def distance(self, box: tuple[np.ndarray, np.ndarray] | None = None) -> float:
        """Grasp site to the instructed handle's box (m; 0 inside it).

        `distance_reference` in plain floats: per axis the larger of (lo - site, site - hi), at least
        0 (numpy's maximum of finite numbers; a zero's sign is squared away), then numpy's dot of
        those three numbers, as the reference. Non-finite inputs take the reference's path.
        """
        lo, hi = box if box is not None else self.target_box()
        s0, s1, s2 = self._site_pos.tolist()
        l0, l1, l2 = lo.tolist()
        h0, h1, h2 = hi.tolist()
        if not math.isfinite(s0 + s1 + s2 + l0 + l1 + l2 + h0 + h1 + h2):
            return self.distance_reference((lo, hi))
        outside = self._outside
        a, b = l0 - s0, s0 - h0
        a = a if a > b else b
        outside[0] = a if a > 0.0 else 0.0
        a, b = l1 - s1, s1 - h1
        a = a if a > b else b
        outside[1] = a if a > 0.0 else 0.0
        a, b = l2 - s2, s2 - h2
        a = a if a > b else b
        outside[2] = a if a > 0.0 else 0.0
        # outside @ outside is numpy's dot, as .dot; np.sqrt of a float: the same correctly rounded root
        return math.sqrt(outside.dot(outside))

    def distance_reference(self, box: tuple[np.ndarray, np.ndarray] | None = None) -> float:
        """`distance` with numpy's elementwise maximum (the reference)."""
        lo, hi = box if box is not None else self.target_box()
        site = self._data.site_xpos[self._site]
        outside = np.maximum(self._zeros3, np.maximum(lo - site, site - hi))  # = np.maximum(0.0, ...)
        return float(np.sqrt(outside @ outside))

    def contact(self) -> bool:
        data = self._data
        n = int(data.ncon)
        if n == 0:
            return False
        handles = self.handle_geoms(self.task.target.joint)
        g1, g2 = data.contact.geom1[:n], data.contact.geom2[:n]
        hand1, hand2 = np.isin(g1, self._hand_geoms), np.isin(g2, self._hand_geoms)
        return bool(np.any((hand1 & np.isin(g2, handles)) | (hand2 & np.isin(g1, handles))))

    def start(self) -> None:
        """Call at reset (after the hand is placed): remembers the starting distance."""
        self.start_distance = self.distance()

    def terms(self) -> RewardTerms:
        """The reward terms, computed the straightforward way (the reference for `read`)."""
        task, qpos = self.task, self._data.qpos
        target = task.target
        values = {j: float(qpos[a]) for j, a in self._qpos.items()}
        outcome = task.checker.check_values(values)
        others = [t.range_ratio(values[t.joint]) for t in task.cabinet.targets if t.joint != target.joint]
        return RewardTerms(distance=self.distance_reference(self.handle_box_reference()),
                           start_distance=self.start_distance,
                           contact=self.contact(),
                           open_ratio=float(outcome.open_ratio), others_range=max(others, default=0.0),
                           success=bool(outcome.success), others_moved=bool(outcome.others_moved),
                           range_ratio=float(outcome.range_ratio))

    def read(self, geom1: np.ndarray | None, geom2: np.ndarray | None, box=None) -> RewardTerms:
        """The reward terms of `terms`, from the contacts' geom pairs (``data.contact.geom1/2``, read
        once per step by the caller; None: no contacts) and, optionally, the handle box already
        computed this step."""
        task = self.task
        target = task.target
        bound = self._bound
        if bound is None or bound[0] != target.joint:
            bound = self._bind(target.joint)
        _, _, _, handle_mask, _, _, (ratios, open_span, range_span) = bound
        # what checker.check_values computes (Target.opening, open_ratio and range_ratio: the same
        # operations on the same joint values), without its dict and Outcome, and each other
        # target's range ratio once
        q, others_range, others = 0.0, 0.0, False
        for (is_target, closed, sign, span), value in zip(ratios, self._data.qpos[self._addresses].tolist()):
            if is_target:
                q = value
            else:
                # the largest other range ratio: others moved when it is above the threshold (range
                # ratios are never NaN: max(0.0, NaN) is 0.0)
                ratio = max(0.0, (value - closed) * sign) / span
                others_range = max(others_range, ratio) if others else ratio
                others = True
        opening = max(0.0, (q - target.closed) * target.open_sign)
        open_ratio = opening / open_span
        if geom1 is not None and len(geom1):
            hand = self._hand_mask
            contact = bool(np.any((hand[geom1] & handle_mask[geom2]) | (hand[geom2] & handle_mask[geom1])))
        else:
            contact = False
        checker = task.checker
        return RewardTerms(self.distance(box), self.start_distance, contact, open_ratio, others_range,
                           open_ratio > checker.threshold, others and others_range > checker.moved_threshold,
                           0.0, 0.0, 0.0, opening / range_span)
