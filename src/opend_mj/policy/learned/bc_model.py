"""Behaviour cloning: what the policy reads, what it writes, and the model (a transformer over action chunks).

Inputs (only what the evaluation protocol gives an agent; never ground truth):

* **context** (once per episode, :func:`context_features`): the handle a shipped solver finds in the
  first RGB-D image, back-projected with the camera intrinsics and the depth at the box
  (:func:`perceive_handle`: the planner's own perception, `opend_mj.policy.perception`): the 3D grip
  centre (world, m), bar or knob, horizontal or vertical, its extent (m), how far it stands out of
  the panel, the free space around it, the side a door hinges on as the depth image shows it; and
  the instruction's one-hot code (`opend_mj.language.instruction_onehot`, 14 numbers); for a door,
  where its hinge line is (the planner's own estimate: the hinge side named by the instruction or
  seen in depth, at the edge of the door's front plane in depth), relative to the handle, which
  gives the circle that the door's handle moves on.
* **steps** (:func:`step_features`): the hand's own state at the current step and at earlier steps
  (``lags``): grasp site and commanded root (mocap) positions relative to the perceived handle centre
  (m), their orientations as the first two columns of the rotation matrix (6 numbers each, continuous
  where a quaternion flips sign), the root's velocity, the finger joints, touch (N) and the time (s);
  for a policy that watches (``BCConfig.watch``), the instructed front as the latest depth image shows
  it (`opend_mj.policy.perception.watch`: its shift and turn, where the handle is now, the grasp site
  relative to it; a new image every ``watch`` control steps).

Output: a chunk of ``chunk`` future actions (:func:`encode_actions`), each the root target position
relative to the perceived handle centre (m), the root target orientation (6 numbers) and the finger
targets mapped to [-1, 1] over their actuator ranges; :func:`decode_action` turns one back into the
task's absolute action (root position, quaternion w x y z, finger targets). Everything is
standardised with the training data's mean and spread, stored in the model's buffers.

The model (:class:`ChunkTransformer`) follows ACT (Zhao et al. 2023, "Learning fine-grained bimanual
manipulation with low-cost hardware") without its CVAE: planner demonstrations are one deterministic
behaviour per observation, so there is no mode to sample. A transformer encoder reads one context
token and one token per lag; a decoder turns ``chunk`` learned queries into the action chunk; the
agent blends the chunks that cover a step with ACT's temporal ensemble.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from opend_mj.transforms import mat_to_quat, quat_to_mat

#: Observation keys a step feature reads (all in the agent's observation, `policy.agents`).
STEP_KEYS = ("grasp_site_pos", "grasp_site_quat", "mocap_pos", "mocap_quat", "root_vel", "hand_qpos", "touch", "time")
#: The planner's grasp styles (`policy.planner.GraspChoice.style`): the modes of the grasp-style token.
GRASP_STYLES = ("hook", "pinch", "wrap", "hook_down", "press_down")


def style_index(style) -> int:
    """The index of a grasp style in :data:`GRASP_STYLES`; -1 for none or unknown."""
    return GRASP_STYLES.index(style) if style in GRASP_STYLES else -1


#: Length of :func:`percept_vector` (checkpoints of before the hinge line read its first 22 numbers).
PERCEPT_DIM = 25
HINGE_SIDES = ("left", "right")


@dataclass(frozen=True)
class BCConfig:
    """Model size, inputs and training settings of the behaviour-cloning policy."""

    chunk: int = 20  # actions predicted per query (1/3 s at 60 Hz)
    lags: tuple[int, ...] = (0, 4, 12, 30)  # control steps back of each step token
    d_model: int = 64
    heads: int = 4
    enc_layers: int = 2
    dec_layers: int = 1
    dropout: float = 0.1
    lr: float = 1e-3
    weight_decay: float = 1e-4
    batch_size: int = 256
    steps: int = 3000  # optimiser steps
    seed: int = 0
    ensemble_decay: float = 0.01  # ACT's temporal-ensemble weight exp(-decay * age), oldest first
    #: the grasp-style token: 0 (none), or len(GRASP_STYLES): a head predicts the grasp style the
    #: expert used at each step from the encoded inputs, and the decoder is conditioned on it
    #: (the true style in training, the predicted one when acting)
    modes: int = 0
    mode_weight: float = 0.1  # the style's cross-entropy beside the actions' L1 in the loss
    #: control steps between the depth images the policy watches its front in
    #: (`perception.watch.FrontWatcher`, a step token's last ``WATCH_DIM`` numbers); 0: blind after
    #: the first image (checkpoints from before the watch)
    watch: int = 0

    def to_dict(self) -> dict:
        d = asdict(self)
        d["lags"] = list(self.lags)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "BCConfig":
        d = dict(d)
        d["lags"] = tuple(d["lags"])
        return cls(**{k: v for k, v in d.items() if k in cls.__dataclass_fields__})


# --------------------------------------------------------------------------------------------------
# Perception: the solver's box -> a 3D handle (the planner's own steps)
# --------------------------------------------------------------------------------------------------
@dataclass
class HandlePercept:
    """The handle as the first image shows it: the solver's box (pixels, refined as the planner
    refines it), the 3D estimate, the measured shape and the hinge side ("left", "right" or None)."""

    box: object  # HandleBox
    handle: object  # HandleEstimate
    shape: object  # HandleShape
    hinge: str | None
    #: a door's hinge line (world x, y; m) as the planner sees it in depth (`hinge_line`), else None
    hinge_point: np.ndarray | None = None

    def vector(self) -> np.ndarray:
        return percept_vector(self)


def perceive_handle(solver, rgb, depth, instruction: str, view, planner_config=None) -> HandlePercept | None:
    """The instructed handle from one RGB-D image through ``solver`` (None where it finds none):
    the box snapped to depth as the planner snaps a learned solver's, one of a pair of pulls, then
    back-projected (:func:`opend_mj.policy.perception.estimate_handle`)."""
    from opend_mj.language import describe_instruction
    from opend_mj.policy.perception import estimate_handle, infer_hinge_side, measure_handle
    from opend_mj.policy.planner import PlannerConfig
    from opend_mj.policy.planner.loop import settle_box

    config = planner_config or PlannerConfig()
    box = solver.solve(rgb, depth, instruction, view)
    if box is None:
        return None
    box, _ = settle_box(solver, box, depth, view, config)
    seen = config.perception  # the planner's own depth perception, with the planner's settings
    handle = estimate_handle(box, depth, view, seen)
    if handle is None:
        return None
    shape = measure_handle(handle, box, depth, view, seen)
    door = describe_instruction(instruction).kind == "door"
    hinge = infer_hinge_side(handle, depth, view, seen) if door else None
    point = hinge_line(handle, depth, view, instruction, config) if door else None
    return HandlePercept(box=box, handle=handle, shape=shape, hinge=hinge, hinge_point=point)


def hinge_line(handle, depth, view, instruction: str, planner_config) -> np.ndarray | None:
    """A door's hinge line (world x, y; m) as the planner finds it (`Planner.hinge_from_depth`):
    on the side the instruction names (a double door), else the side inferred from depth, where
    the door's front plane ends in the depth image, at the panel's depth; None where unknown or
    closer than ``min_hinge_distance`` to the handle."""
    from opend_mj.language import hinge_side
    from opend_mj.policy.perception import door_edges, infer_hinge_side

    cfg = planner_config.grasp
    side = hinge_side(instruction)
    if side is None and cfg.infer_hinge:
        side = infer_hinge_side(handle, depth, view, planner_config.perception)
    edges = door_edges(handle, depth, view, planner_config.perception)
    if side is None or edges is None:
        return None
    y = edges[0] if side == "left" else edges[1]
    if abs(y - handle.centre[1]) < cfg.min_hinge_distance:
        return None
    return np.array([handle.panel_x, y], float)


def percept_vector(p: HandlePercept) -> np.ndarray:
    """``PERCEPT_DIM`` numbers: centre (3, world m), horizontal/vertical, bar/knob, extent y/z (m),
    handle front and panel relative to the centre along x (m), hinge left/right/unknown, thickness,
    length, gap, protrusion (m), free space up/down/left/right (m); the hinge line relative to the
    centre (x, y; m; zeros where none) and whether there is one."""
    h, s = p.handle, p.shape
    c = np.asarray(h.centre, float)
    hinge = [float(p.hinge == side) for side in HINGE_SIDES] + [float(p.hinge not in HINGE_SIDES)]
    clear = [float(s.clear.get(k, 0.15)) for k in ("up", "down", "left", "right")]
    v = np.concatenate([c, [h.orientation == "horizontal", h.orientation == "vertical", h.kind == "bar",
                            h.kind == "knob"], np.asarray(h.size, float), [h.front_x - c[0], h.panel_x - c[0]],
                        hinge, [s.thickness, s.length, s.gap, s.protrusion], clear]).astype(np.float64)
    point = getattr(p, "hinge_point", None)
    line = [0.0, 0.0, 0.0] if point is None else [float(point[0] - c[0]), float(point[1] - c[1]), 1.0]
    v = np.concatenate([v, line])
    assert v.shape == (PERCEPT_DIM,)
    return v


def context_features(percept_vec: np.ndarray, instruction: str) -> np.ndarray:
    """The episode's context: the percept vector and the instruction's one-hot code."""
    from opend_mj.language import instruction_onehot

    return np.concatenate([np.asarray(percept_vec, float), instruction_onehot(instruction)]).astype(np.float32)


# --------------------------------------------------------------------------------------------------
# Step features and actions
# --------------------------------------------------------------------------------------------------
def rot6(quats: np.ndarray) -> np.ndarray:
    """(T, 4) quaternions (w x y z) -> (T, 6): the rotation matrices' first two columns."""
    q = np.asarray(quats, float).reshape(-1, 4)
    w, x, y, z = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
    return np.stack([1 - 2 * (y * y + z * z), 2 * (x * y + z * w), 2 * (x * z - y * w),
                     2 * (x * y - z * w), 1 - 2 * (x * x + z * z), 2 * (y * z + x * w)], axis=1)


def quat_from_rot6(v: np.ndarray) -> np.ndarray:
    """The quaternion (w x y z) of the rotation whose first two columns ``v`` approximates (Gram-Schmidt)."""
    a, b = np.asarray(v[:3], float), np.asarray(v[3:6], float)
    x = a / max(np.linalg.norm(a), 1e-9)
    b = b - (x @ b) * x
    y = b / max(np.linalg.norm(b), 1e-9)
    m = np.stack([x, y, np.cross(x, y)], axis=1)
    q = mat_to_quat(m)
    return q / np.linalg.norm(q)


#: The per-step observation key of the watched front (`perception.watch.FrontWatcher.vector`).
WATCH_KEY = "front_watch"


def step_features(obs: dict, centre, watch: bool = False) -> np.ndarray:
    """(T, S) features of T observations (each key (T, ...)) relative to the handle ``centre``; with
    ``watch``, the watched front's numbers (``obs["front_watch"]``, (T, WATCH_DIM)) after them."""
    c = np.asarray(centre, float)
    parts = [np.asarray(obs["grasp_site_pos"], float) - c, rot6(obs["grasp_site_quat"]),
             np.asarray(obs["mocap_pos"], float) - c, rot6(obs["mocap_quat"])]
    keys = ("root_vel", "hand_qpos", "touch", "time") + ((WATCH_KEY,) if watch else ())
    parts += [np.asarray(obs[k], float).reshape(len(parts[0]), -1) for k in keys]
    return np.concatenate(parts, axis=1).astype(np.float32)


def lag_index(t: np.ndarray, lags) -> np.ndarray:
    """(N, L) indices of the steps ``lags`` before steps ``t`` (the first step where there is none)."""
    return np.maximum(np.asarray(t)[:, None] - np.asarray(lags)[None, :], 0)


def encode_actions(actions: np.ndarray, centre, finger_low, finger_high) -> np.ndarray:
    """(T, 7 + n) task actions -> (T, 9 + n): root position - centre, rot6, fingers in [-1, 1]."""
    a = np.asarray(actions, float)
    span = np.maximum(np.asarray(finger_high) - np.asarray(finger_low), 1e-12)
    fingers = 2.0 * (a[:, 7:] - finger_low) / span - 1.0
    return np.concatenate([a[:, :3] - np.asarray(centre, float), rot6(a[:, 3:7]), fingers], axis=1).astype(np.float32)


def decode_action(v: np.ndarray, centre, finger_low, finger_high) -> np.ndarray:
    """One encoded action -> the task's absolute action (root pos, quat w x y z, finger targets)."""
    v = np.asarray(v, float)
    low, high = np.asarray(finger_low, float), np.asarray(finger_high, float)
    fingers = low + (np.clip(v[9:], -1.0, 1.0) + 1.0) * 0.5 * (high - low)
    return np.concatenate([v[:3] + np.asarray(centre, float), quat_from_rot6(v[3:9]), fingers])


# --------------------------------------------------------------------------------------------------
# The model
# --------------------------------------------------------------------------------------------------
def build_model(ctx_dim: int, step_dim: int, act_dim: int, config: BCConfig):
    """A :class:`ChunkTransformer` (imports torch on first use)."""
    import torch
    from torch import nn

    class ChunkTransformer(nn.Module):
        """Context token + one token per lag -> encoder; ``chunk`` queries -> decoder -> actions."""

        def __init__(self):
            super().__init__()
            d, c = config.d_model, config
            self.ctx_in = nn.Sequential(nn.Linear(ctx_dim, d), nn.GELU(), nn.Linear(d, d))
            self.step_in = nn.Sequential(nn.Linear(step_dim, d), nn.GELU(), nn.Linear(d, d))
            self.token_pos = nn.Parameter(torch.randn(1 + len(c.lags), d) * 0.02)
            self.queries = nn.Parameter(torch.randn(c.chunk, d) * 0.02)
            enc = nn.TransformerEncoderLayer(d, c.heads, 4 * d, c.dropout, batch_first=True, norm_first=True)
            dec = nn.TransformerDecoderLayer(d, c.heads, 4 * d, c.dropout, batch_first=True, norm_first=True)
            self.encoder = nn.TransformerEncoder(enc, c.enc_layers, enable_nested_tensor=False)
            self.decoder = nn.TransformerDecoder(dec, c.dec_layers)
            self.head = nn.Sequential(nn.LayerNorm(d), nn.Linear(d, act_dim))
            if c.modes:  # the grasp-style token
                self.mode_head = nn.Sequential(nn.LayerNorm(d), nn.Linear(d, c.modes))
                self.mode_embed = nn.Embedding(c.modes, d)
            for name, dim in (("ctx", ctx_dim), ("step", step_dim), ("act", act_dim)):
                self.register_buffer(f"{name}_mean", torch.zeros(dim))
                self.register_buffer(f"{name}_std", torch.ones(dim))

        def predict(self, ctx, steps, mode=None):
            """ctx (B, C), steps (B, L, S), both raw -> ((B, chunk, A) standardised actions, (B, modes)
            style logits or None). ``mode`` (B,): the styles to condition on (default: the predicted ones)."""
            x0 = self.ctx_in((ctx - self.ctx_mean) / self.ctx_std)[:, None]
            xs = self.step_in((steps - self.step_mean) / self.step_std)
            memory = self.encoder(torch.cat([x0, xs], dim=1) + self.token_pos)
            q = self.queries.expand(len(ctx), -1, -1)
            logits = None
            if config.modes:
                logits = self.mode_head(memory[:, 0])
                chosen = logits.argmax(dim=-1) if mode is None else mode
                q = q + self.mode_embed(chosen)[:, None]
            return self.head(self.decoder(q, memory)), logits

        def forward(self, ctx, steps, mode=None):
            """ctx (B, C), steps (B, L, S), both raw -> (B, chunk, A) standardised actions."""
            return self.predict(ctx, steps, mode)[0]

        def actions(self, ctx, steps):
            """Raw (de-standardised) encoded actions (conditioned on the predicted grasp style)."""
            return self(ctx, steps) * self.act_std + self.act_mean

    return ChunkTransformer()


def load_policy(path, device: str = "cpu"):
    """``(model in eval mode, BCConfig, checkpoint dict)`` of a checkpoint written by training."""
    from opend_mj.policy.learned import load_checkpoint

    def build(ckpt):
        config = BCConfig.from_dict(ckpt["config"])
        dims = ckpt["dims"]
        return build_model(dims["ctx"], dims["step"], dims["act"], config), config

    return load_checkpoint(path, "bc_allegro.pt", "behaviour-cloning policy",
                           "opend train-policy", build, device=device)


#: ``format`` of a file that bundles several checkpoints into one seed ensemble (:func:`bundle_policies`).
ENSEMBLE_FORMAT = "opend-bc-ensemble"
#: What the members of an ensemble must share: they predict the same chunk from the same step
#: inputs (the context may differ in length: checkpoints of before the hinge line read fewer percept numbers).
_MEMBER_KEYS = ("hand", "finger_low", "finger_high")
_MEMBER_DIMS = ("step", "act")
_MEMBER_CONFIG = ("chunk", "lags", "watch")


#: One step's actions of each model (:func:`step_actions`): ``id(model) -> (model, traced forward)``,
#: the model kept so that its id stays its own.
_TRACED: dict = {}


def step_actions(model, ctx, steps):
    """``model.actions(ctx, steps)`` for one sample (batch of one, as an agent acts step by step),
    through a TorchScript trace of it made on first use and kept per model. The numbers are those of
    the module; at batch one most of the module's time is Python overhead between its layers, which
    the trace removes (a few times faster on a CPU). Other batch sizes, and a torch without
    TorchScript (deprecated in recent releases), go through the module."""
    import torch

    if ctx.shape[0] != 1:
        return model.actions(ctx, steps)
    if id(model) not in _TRACED:
        _TRACED[id(model)] = (model, _trace_actions(model, ctx, steps))
    with torch.no_grad():
        return _TRACED[id(model)][1](ctx, steps)


def _trace_actions(model, ctx, steps):
    """A frozen TorchScript trace of ``model.actions`` at the shapes of ``ctx`` and ``steps``, or
    ``model.actions`` itself where tracing is not available."""
    import warnings

    import torch

    class Actions(torch.nn.Module):
        def __init__(self, inner):
            super().__init__()
            self.inner = inner

        def forward(self, c, x):
            return self.inner.actions(c, x)

    with torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the batch of one traced as a constant; the API's deprecation
        try:
            return torch.jit.freeze(torch.jit.trace(Actions(model).eval(), (ctx, steps), check_trace=False))
        except (AttributeError, RuntimeError):
            return model.actions


def checkpoint_paths(spec) -> list:
    """The checkpoint files of a ``checkpoint=`` value: one path, or several separated by commas
    (a seed ensemble whose predictions are averaged)."""
    from pathlib import Path

    parts = [s.strip() for s in str(spec).split(",")]
    if not all(parts):
        raise ValueError(f"checkpoint={spec!r}: an empty path between commas")
    return [Path(s) for s in parts]


def load_policies(paths, device: str = "cpu", kind: str | None = None) -> list:
    """``[(model, BCConfig, checkpoint dict), ...]`` of the files ``paths``, each a checkpoint of
    `opend train-policy` or an ensemble bundle (:func:`bundle_policies`, every member listed, or
    for a target ``kind`` ("drawer" or "door") the members the bundle routes that kind to); the
    members must agree on the hand, the step and action sizes, the finger ranges, the chunk and
    the lags (an error names the file that does not)."""
    from pathlib import Path

    from opend_mj.policy.learned.checkpoint_io import read_checkpoint

    members = []
    for path in (Path(p) for p in paths):
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no behaviour-cloning policy checkpoint; train one with "
                                    "`opend train-policy` (or pass checkpoint=)")
        head = read_checkpoint(path, "behaviour-cloning policy checkpoint")
        if head.get("format") == ENSEMBLE_FORMAT:
            key = ("ensemble", str(path.resolve()), device)
            if key not in _BUNDLES:
                _BUNDLES[key] = [_member(m, device) for m in head["members"]]
            chosen = (head.get("routes") or {}).get(kind, range(len(head["members"])))
            members += [(*_BUNDLES[key][i], path) for i in chosen]
        else:
            members.append((*load_policy(path, device=device), path))
    first_model, first_config, first, first_path = members[0]
    for _, config, ckpt, path in members[1:]:
        for k in _MEMBER_KEYS:
            if ckpt.get(k) != first.get(k):
                raise ValueError(f"{path}: its {k} ({ckpt.get(k)}) differs from {first_path}'s ({first.get(k)}); "
                                 "an ensemble's members must predict the same actions from the same inputs")
        for k in _MEMBER_DIMS:
            if ckpt["dims"][k] != first["dims"][k]:
                raise ValueError(f"{path}: its {k} size ({ckpt['dims'][k]}) differs from {first_path}'s "
                                 f"({first['dims'][k]})")
        for k in _MEMBER_CONFIG:
            if getattr(config, k) != getattr(first_config, k):
                raise ValueError(f"{path}: its {k} ({getattr(config, k)}) differs from {first_path}'s "
                                 f"({getattr(first_config, k)})")
    return [(m, c, k) for m, c, k, _ in members]


_BUNDLES: dict = {}


def _member(ckpt: dict, device: str):
    config = BCConfig.from_dict(ckpt["config"])
    dims = ckpt["dims"]
    model = build_model(dims["ctx"], dims["step"], dims["act"], config)
    model.load_state_dict({k: v.float() for k, v in ckpt["model"].items()})
    return model.eval().to(device), config, ckpt


def bundle_policies(paths, out, ensemble_decay: float | None = None, routes: dict | None = None) -> dict:
    """Write the checkpoints ``paths`` (checked as :func:`load_policies` checks them) into one file
    ``out`` that `opend run --policy bc` loads as their ensemble; ``ensemble_decay`` (the temporal
    ensemble's weight decay per step of age) becomes every member's default where given.
    ``routes`` ({"drawer": [0, 2], ...}: indices into the bundle's members, counted over ``paths``
    in order) gives a target kind its own members; a kind not routed uses all of them. Returns the
    bundle's summary."""
    from pathlib import Path

    from opend_mj.language import TARGET_KINDS
    from opend_mj.policy.learned.checkpoint_io import read_checkpoint, write_checkpoint

    load_policies(paths)  # the same checks as at run time, before anything is written
    members, sources = [], []
    for path in paths:
        ckpt = read_checkpoint(path, "behaviour-cloning policy checkpoint")
        bundled = ckpt.get("format") == ENSEMBLE_FORMAT
        members += ckpt["members"] if bundled else [ckpt]
        # a bundle re-bundled (e.g. to add a route) keeps the files its members came from
        sources += ckpt.get("summary", {}).get("sources", [str(path)]) if bundled else [str(path)]
    if ensemble_decay is not None:
        members = [{**m, "config": {**m["config"], "ensemble_decay": float(ensemble_decay)}} for m in members]
    routes = {str(k): [int(i) for i in v] for k, v in (routes or {}).items()}
    for kind, ids in routes.items():
        if kind not in TARGET_KINDS:
            raise ValueError(f"route {kind!r}: a target kind is one of {', '.join(TARGET_KINDS)}")
        if not ids or any(not 0 <= i < len(members) for i in ids):
            raise ValueError(f"route {kind}={ids}: member indices must be 0..{len(members) - 1} "
                             f"(the bundle has {len(members)} members), at least one")

    def stop_of(ids):
        return float(np.mean([members[i].get("stop_time", members[i].get("max_time", 0.0)) for i in ids]))

    first = members[0]
    summary = {"members": len(members), "sources": sources, "hand": first["hand"],
               "seeds": [m["config"].get("seed") for m in members],
               "ensemble_decay": float(np.mean([m["config"].get("ensemble_decay", 0.01) for m in members])),
               "stop_time": stop_of(range(len(members)))}
    if routes:
        summary["routes"] = {k: {"members": v, "stop_time": stop_of(v)} for k, v in routes.items()}
    bundle = {"format": ENSEMBLE_FORMAT, "members": members, "hand": first["hand"], "summary": summary,
              "routes": routes}
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_checkpoint(bundle, out)
    # beside it: the first member's training summary (as `opend train-policy` writes one beside its
    # checkpoint) with the bundle's, and every member file's own where it has one
    import json

    def trained(path):
        side = Path(path).with_suffix(".json")
        return json.loads(side.read_text()) if side.is_file() else None

    first_summary = trained(paths[0]) or {}
    first_summary.pop("bundle", None)
    out.with_suffix(".json").write_text(json.dumps(
        {**first_summary, "bundle": {**summary, "member_summaries": [trained(p) for p in paths]}}, indent=1) + "\n")
    return summary


__all__ = ["BCConfig", "step_actions", "ENSEMBLE_FORMAT", "bundle_policies", "checkpoint_paths", "load_policies", "HandlePercept", "PERCEPT_DIM", "STEP_KEYS", "WATCH_KEY", "build_model", "context_features",
           "decode_action", "encode_actions", "hinge_line", "lag_index", "load_policy", "perceive_handle",
           "percept_vector", "quat_from_rot6", "rot6", "step_features"]
