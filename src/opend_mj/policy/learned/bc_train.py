"""Training the behaviour-cloning policy (`policy.learned.bc_model`) from planner demonstrations.

A demonstration is any object with ``actions`` (T, 7 + n: the task's absolute action), ``obs`` (the
keys of `bc.STEP_KEYS` plus ``handle_features``, each (T, ...)) and ``attrs``
(``instruction``, ``success``, ``hand``), as `opend_mj.apps.demos.read_demos` returns them. Every
control step of every kept demonstration is one sample: its context, the step tokens at the
configured lags (the first step where the demo is shorter) and the next ``chunk`` actions (the last
action repeated past the end: the hand holds where the demonstration stopped). The loss is the mean
absolute error of the standardised actions. Training is deterministic for a seed on one machine.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from opend_mj.policy.learned.bc_model import (
    WATCH_KEY,
    BCConfig,
    build_model,
    context_features,
    encode_actions,
    lag_index,
    step_features,
)


@dataclass
class DemoArrays:
    """Every usable demo's steps, concatenated: context per demo, step features and encoded actions per step."""

    ctx: np.ndarray  # (D, C) float32
    steps: np.ndarray  # (N, S) float32
    actions: np.ndarray  # (N, A) float32
    start: np.ndarray  # (D,) index of each demo's first step
    length: np.ndarray  # (D,) steps per demo
    max_time: float  # s: the longest demonstration
    cabinets: list[str]
    modes: np.ndarray | None = None  # (N,) int: the grasp style of each step (-1: unknown); None: not recorded

    @property
    def stop_time(self) -> float:
        """s: 95 % of the demonstrations are over by then (the agent's default stop)."""
        return float(np.percentile(self.length, 95)) / 60.0

    @property
    def n_demos(self) -> int:
        return len(self.ctx)


def usable(demo) -> bool:
    """A successful demonstration, or a DAgger rollout labelled by the expert (``labels`` "expert":
    its labels are the expert's whatever the rollout did), whose first image gave a handle (its
    features are finite)."""
    feats = np.asarray(demo.obs.get("handle_features", np.full((1, 1), np.nan)))
    wanted = bool(demo.attrs.get("success")) or demo.attrs.get("labels") == "expert"
    return wanted and len(demo.actions) > 0 and bool(np.isfinite(feats[0]).all())


def demo_arrays(demos, finger_low, finger_high, watch: int = 0) -> DemoArrays:
    """The samples of the usable demos (see :func:`usable`); ``modes`` where every one recorded its
    grasp styles (``grasp_style``, `opend demos`); with ``watch`` (control steps between looks),
    each step's watched front (``front_watch``) among its features, which every usable demo must
    have recorded at that rate (its ``watch_every`` attribute)."""
    ctx, steps, acts, lengths, cabinets, max_time, modes = [], [], [], [], [], 0.0, []
    for d in demos:
        if not usable(d):
            continue
        style = getattr(d, "extra", {}).get("grasp_style")
        modes.append(None if style is None else np.asarray(style, np.int64).reshape(-1))
        feats = np.asarray(d.obs["handle_features"][0], float)
        centre = feats[:3]
        ctx.append(context_features(feats, d.attrs["instruction"]))
        if watch and (WATCH_KEY not in d.obs or int(d.attrs.get("watch_every", 0)) != watch):
            raise ValueError(f"demonstration {d.attrs.get('cabinet')}/{d.attrs.get('target_joint')} recorded no "
                             f"{WATCH_KEY} every {watch} steps (the watched front; it has "
                             f"{d.attrs.get('watch_every', 'none')}): record it again with this opend-mj's "
                             "`opend demos`, or train with its rate (--watch)")
        steps.append(step_features(d.obs, centre, watch=bool(watch)))
        acts.append(encode_actions(d.actions, centre, finger_low, finger_high))
        lengths.append(len(d.actions))
        cabinets.append(str(d.attrs.get("cabinet", "")))
        max_time = max(max_time, float(np.asarray(d.obs["time"])[-1, 0]) + 1.0 / 60.0)
    if not ctx:
        raise ValueError("no usable demonstrations (successful, with a located handle) to train on")
    length = np.asarray(lengths, np.int64)
    start = np.concatenate([[0], np.cumsum(length)[:-1]]).astype(np.int64)
    styles = np.concatenate(modes) if all(m is not None for m in modes) else None
    return DemoArrays(ctx=np.stack(ctx), steps=np.concatenate(steps), actions=np.concatenate(acts), start=start,
                      length=length, max_time=max_time, cabinets=cabinets, modes=styles)


def batch_indices(data: DemoArrays, demo_ids: np.ndarray, t: np.ndarray, config: BCConfig):
    """(ctx rows, (B, L) step rows, (B, K) action rows) of samples (demo, step)."""
    start, length = data.start[demo_ids], data.length[demo_ids]
    lag_rows = start[:, None] + lag_index(t, config.lags)
    ahead = np.minimum(t[:, None] + np.arange(config.chunk)[None, :], length[:, None] - 1)
    return demo_ids, lag_rows, start[:, None] + ahead


def _stats(x: np.ndarray, floor: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    mean = x.mean(axis=0)
    std = x.std(axis=0)
    return mean.astype(np.float32), np.where(std < floor, 1.0, std).astype(np.float32)


def split_demos(data: DemoArrays, val_fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(train demo ids, validation demo ids): validation = whole cabinets, drawn from the seed."""
    cabs = sorted(set(data.cabinets))
    rng = np.random.default_rng([seed, 35])
    n_val = int(round(len(cabs) * val_fraction)) if len(cabs) > 1 else 0
    val_cabs = set(rng.choice(cabs, size=n_val, replace=False).tolist()) if n_val else set()
    ids = np.arange(data.n_demos)
    is_val = np.array([c in val_cabs for c in data.cabinets], bool)
    return ids[~is_val], ids[is_val]


def train_bc(demos, hand: str, config: BCConfig = BCConfig(), out: Path | None = None, val_fraction: float = 0.1,
             progress: bool = True, threads: int | None = None, device: str = "cpu", log=None,
             kind: str | None = None, init: Path | None = None) -> dict:
    """Train on ``demos`` (of ``hand``); write the checkpoint to ``out`` (with a ``.json`` summary beside it).
    ``kind`` ("drawer", "door") is recorded in the summary where the demos were of one kind only.
    ``init``: a checkpoint to start from (a warm start: its weights and its standardisation of
    inputs and actions, which its weights were trained for); its architecture (width, layers,
    chunk, lags, grasp-style token) wins over ``config``'s, whose optimiser settings and steps apply.

    Returns the summary: data sizes, losses, seconds, parameter count."""
    import torch
    from tqdm import tqdm

    from opend_mj.sim.envs import ActionAdapter
    from opend_mj.sim.task import TaskConfig

    if threads:
        torch.set_num_threads(int(threads))
    torch.manual_seed(config.seed)
    adapter = ActionAdapter(hand, TaskConfig())
    t0 = time.perf_counter()
    data = demo_arrays(demos, adapter.finger_low, adapter.finger_high, watch=config.watch)
    if config.modes and data.modes is None:
        raise ValueError("the grasp-style token needs demonstrations that recorded their grasp styles "
                         "(grasp_style): record them again with this opend-mj's `opend demos`")
    start = None
    if init is not None:
        config, start = _warm_start(Path(init), config, hand, data)
    train_ids, val_ids = split_demos(data, val_fraction, config.seed)
    model = build_model(data.ctx.shape[1], data.steps.shape[1], data.actions.shape[1], config).to(device)
    train_rows = np.concatenate([np.arange(data.start[i], data.start[i] + data.length[i]) for i in train_ids])
    if start is not None:
        model.load_state_dict(start)
    else:
        for name, arr in (("ctx", data.ctx[train_ids]), ("step", data.steps[train_rows]),
                          ("act", data.actions[train_rows])):
            mean, std = _stats(arr)
            getattr(model, f"{name}_mean").copy_(torch.from_numpy(mean))
            getattr(model, f"{name}_std").copy_(torch.from_numpy(std))
    opt = torch.optim.AdamW(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    warmup = max(1, config.steps // 20)
    sched = torch.optim.lr_scheduler.LambdaLR(
        opt, lambda s: min(1.0, (s + 1) / warmup) * 0.5 * (1 + math.cos(math.pi * min(1.0, s / config.steps))))
    ctx_t, steps_t, acts_t = (torch.from_numpy(a).to(device) for a in (data.ctx, data.steps, data.actions))
    modes_t = torch.from_numpy(data.modes).to(device) if config.modes else None
    mean_t, std_t = model.act_mean, model.act_std
    rng = np.random.default_rng([config.seed, 1])
    # samples drawn uniformly over the training demos' steps
    train_len = data.length[train_ids]
    weights = train_len / train_len.sum()

    def draw(ids, p, n):
        demo_ids = ids[rng.choice(len(ids), size=n, p=p)]
        t = (rng.random(n) * data.length[demo_ids]).astype(np.int64)
        return batch_indices(data, demo_ids, t, config)

    def loss_of(rows):
        c, lag_rows, act_rows = (torch.from_numpy(r).to(device) for r in rows)
        target = (acts_t[act_rows] - mean_t) / std_t
        if modes_t is None:
            return (model(ctx_t[c], steps_t[lag_rows]) - target).abs().mean()
        style = modes_t[act_rows[:, 0]]  # the style at the sample's own step
        known = style >= 0
        pred, logits = model.predict(ctx_t[c], steps_t[lag_rows], mode=style.clamp(min=0))
        loss = (pred - target).abs().mean()
        if bool(known.any()):
            loss = loss + config.mode_weight * torch.nn.functional.cross_entropy(logits[known], style[known])
        return loss

    val_rng_state = np.random.default_rng([config.seed, 2])
    val_rows = None
    if len(val_ids):
        vl = data.length[val_ids]
        vd = val_ids[val_rng_state.choice(len(val_ids), size=2048, p=vl / vl.sum())]
        val_rows = batch_indices(data, vd, (val_rng_state.random(len(vd)) * data.length[vd]).astype(np.int64), config)

    history = []
    bar = tqdm(range(config.steps), desc="train-policy", unit="step", disable=not progress)
    running = None
    for step in bar:
        model.train()
        loss = loss_of(draw(train_ids, weights, config.batch_size))
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        opt.step()
        sched.step()
        value = loss.item()
        running = value if running is None else 0.98 * running + 0.02 * value
        if (step + 1) % 250 == 0 or step + 1 == config.steps:
            entry = {"step": step + 1, "train_l1": round(running, 4), "seconds": round(time.perf_counter() - t0, 1)}
            if val_rows is not None:
                model.eval()
                with torch.no_grad():
                    entry["val_l1"] = round(float(loss_of(val_rows)), 4)
            history.append(entry)
            bar.set_postfix({k: v for k, v in entry.items() if k.endswith("l1")})
            if log is not None:
                log(entry)
    bar.close()
    seconds = time.perf_counter() - t0
    summary = {
        "hand": hand, "kind": kind, "config": config.to_dict(), "demos": int(data.n_demos), "train_demos": int(len(train_ids)),
        "val_demos": int(len(val_ids)), "samples": int(len(data.steps)), "cabinets": len(set(data.cabinets)),
        "max_time": round(data.max_time, 3), "stop_time": round(data.stop_time, 3), "parameters": int(sum(p.numel() for p in model.parameters())),
        "seconds": round(seconds, 1), "threads": torch.get_num_threads(), "history": history,
        "init": None if init is None else str(init),
    }
    if out is not None:
        save_checkpoint(model, summary, data, adapter, Path(out))
    return summary


#: BCConfig fields that shape the model: a warm start takes them from the checkpoint it starts from.
ARCHITECTURE_FIELDS = ("chunk", "lags", "d_model", "heads", "enc_layers", "dec_layers", "dropout", "modes", "watch")


def _warm_start(init: Path, config: BCConfig, hand: str, data: DemoArrays) -> tuple[BCConfig, dict]:
    """(``config`` with the architecture of the checkpoint ``init`` (:data:`ARCHITECTURE_FIELDS`), its
    weights and standardisation as float32): the checkpoint read once, as plain data
    (`checkpoint_io.read_checkpoint`: a file that needs more is refused unread); one of another hand
    or other input sizes is refused with one line naming it."""
    import dataclasses

    from opend_mj.policy.learned.checkpoint_io import read_checkpoint

    if not init.is_file():
        raise FileNotFoundError(f"{init}: no checkpoint to start from (--init)")
    ckpt = read_checkpoint(init, "checkpoint of `opend train-policy` (--init)")
    if not isinstance(ckpt, dict) or "model" not in ckpt or "dims" not in ckpt:
        raise ValueError(f"{init}: not a checkpoint of `opend train-policy` (--init)")
    if ckpt.get("hand") not in (None, hand):
        raise ValueError(f"{init}: a checkpoint of the {ckpt['hand']} hand, but training is for the {hand} hand "
                         "(--init)")
    dims = {"ctx": data.ctx.shape[1], "step": data.steps.shape[1], "act": data.actions.shape[1]}
    if {k: int(v) for k, v in ckpt["dims"].items()} != dims:
        raise ValueError(f"{init}: its inputs and actions are {ckpt['dims']}, these demonstrations give {dims} "
                         "(--init)")
    theirs = BCConfig.from_dict(ckpt["config"])
    if theirs.modes and data.modes is None:
        raise ValueError(f"{init}: has the grasp-style token, and these demonstrations recorded no grasp styles")
    weights = {k: v.float() for k, v in ckpt["model"].items()}
    return dataclasses.replace(config, **{f: getattr(theirs, f) for f in ARCHITECTURE_FIELDS}), weights


def save_checkpoint(model, summary: dict, data: DemoArrays, adapter, out: Path) -> None:
    """The model (float32 weights), its config, input sizes and the hand's finger ranges, as plain
    data (`checkpoint_io.write_checkpoint`)."""
    import json

    from opend_mj.policy.learned.checkpoint_io import write_checkpoint

    out.parent.mkdir(parents=True, exist_ok=True)
    ckpt = {"model": {k: v.detach().cpu().clone() for k, v in model.state_dict().items()},
            "config": summary["config"], "hand": summary["hand"],
            "dims": {"ctx": int(data.ctx.shape[1]), "step": int(data.steps.shape[1]), "act": int(data.actions.shape[1])},
            "finger_low": adapter.finger_low.tolist(), "finger_high": adapter.finger_high.tolist(),
            "max_time": summary["max_time"], "stop_time": summary["stop_time"], "summary": summary}
    write_checkpoint(ckpt, out)
    out.with_suffix(".json").write_text(json.dumps(summary, indent=1) + "\n")


__all__ = ["DemoArrays", "batch_indices", "demo_arrays", "save_checkpoint", "split_demos", "train_bc", "usable"]
