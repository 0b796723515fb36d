"""Training and validation of the Faster R-CNN handle detector (`opend train --solver fasterrcnn`).

The loop shared with the other models is :mod:`opend_mj.policy.learned.loop` (float16 checkpoint
after every epoch, full state for ``resume``, the best validation epoch kept); here what is the
detector's own: its batches and augmentation (flips, colours, a real depth sensor's images), and its
metric, target recall at IoU 0.5 after language matching, plus plain handle recall.
"""

from __future__ import annotations

import json
import math
import random
import time
from dataclasses import asdict
from pathlib import Path
from typing import Callable

import numpy as np

from opend_mj.policy.learned.data import camera_view_of, load_images, load_records
from opend_mj.policy.learned.loop import (
    SENSOR_LEVELS,
    Trainer,
    TrainingLoop,
    iou,
    load_pretrained,
    optimise,
    plot_history,
    sensor_augment,
    sensor_view,
    torch_device,
    valid_targets,
)


def _detector_batch(data_dir, records, idx, augment: bool, rng: random.Random, dev, config=None,
                    depth_noise: float = 0.0):
    """Images and targets of a batch. Augmentation: horizontal flips; and with a depth channel, the
    colours shuffled, scaled or greyed out (a quarter of the images each), so the detector learns
    handles from their shape in depth as well as from their look; with chance ``depth_noise``, the
    depth as a real sensor gives it (:func:`~opend_mj.policy.learned.loop.sensor_augment`: noise
    growing with distance, holes at edges and on dark surfaces), so that the relief channel is not
    trusted beyond what it holds."""
    import torch

    from opend_mj.policy.learned.detector import DetectorConfig, detector_input, detector_targets

    config = config or DetectorConfig()
    xs, ys = [], []
    for i in idx:
        rec = records[i]
        rgb, depth, _ = load_images(data_dir, rec)
        tgt = detector_targets(rec, kinds=config.kinds)
        if augment and rng.random() < 0.5:
            rgb, depth = rgb[:, ::-1], depth[:, ::-1]
            b = tgt["boxes"].clone()
            w = rec["width"]
            tgt["boxes"] = torch.stack([w - b[:, 2], b[:, 1], w - b[:, 0], b[:, 3]], 1) if len(b) else b
        if augment and config.depth:
            depth = sensor_augment(rgb, depth, rng, depth_noise)
        x = detector_input(rgb, depth, config)
        if augment and config.depth:
            r = rng.random()
            if r < 0.25:
                x[:3] = x[[*rng.sample(range(3), 3)]]
            elif r < 0.5:
                x[:3] = (x[:3] * rng.uniform(0.4, 1.3)).clamp(0, 1)
            elif r < 0.75:
                x[:3] = x[:3].mean(0, keepdim=True) if rng.random() < 0.5 else 0.5
        xs.append(x.to(dev))
        ys.append({k: v.to(dev) for k, v in tgt.items()})
    return xs, ys


def _set_bn_eval(model) -> None:
    import torch

    for m in model.modules():
        if isinstance(m, torch.nn.modules.batchnorm._BatchNorm):
            m.eval()


def evaluate_detector_model(model, data_dir: Path, records: list[dict], threshold: float = 0.8,
                            progress: bool = False, sensor: str | None = None) -> dict:
    """Target recall at IoU 0.5 after language matching (the solver's :func:`select_handle` on the
    detections alone, no depth proposals), and plain handle recall. ``sensor`` ("mild" / "strong"):
    each image's depth as that depth_noise sensor gives it, fused over an episode's 8 frames (one
    draw per image id, the same for every model)."""
    from tqdm import tqdm

    from opend_mj.policy.learned.detector import MatchConfig, detect_handles, select_handle

    model.eval()
    match = MatchConfig(threshold=threshold, use_proposals=False)
    matched, found, per = [], [], {"door": [], "drawer": []}
    for rec in tqdm(records, disable=not progress, desc="eval detector"):
        rgb, depth, _ = load_images(data_dir, rec)
        if sensor is not None:
            depth = sensor_view(rgb, depth, sensor, rec["id"])
        dets, _ = detect_handles(model, rgb, depth=depth)
        boxes = dets.boxes[dets.handle >= threshold]
        view = camera_view_of(rec)
        for t in valid_targets(rec):
            found.append(any(iou(b, t["box"]) >= 0.5 for b in boxes))
            chosen = select_handle(dets, None, t["instruction"], depth, view, match)
            ok = chosen is not None and iou(chosen[0], t["box"]) >= 0.5
            matched.append(ok)
            per[t["type"]].append(ok)
    return {"target_recall": float(np.mean(matched)) if matched else float("nan"),
            "handle_recall": float(np.mean(found)) if found else float("nan"),
            "door": float(np.mean(per["door"])) if per["door"] else float("nan"),
            "drawer": float(np.mean(per["drawer"])) if per["drawer"] else float("nan"),
            "targets": len(matched), "images": len(records)}


def train_fasterrcnn(data_dir: Path, out: Path, config=None, epochs: int = 10, batch_size: int = 4,
                     lr: float = 5e-4, max_minutes: float | None = None, resume: bool = False,
                     state_path: Path | None = None, device: str | None = None, progress: bool = True,
                     seed: int = 0, max_train: int | None = None, max_val: int | None = None,
                     threshold: float = 0.8, eval_every: int = 1, pretrained: Path | None = None,
                     init: Path | None = None, depth_noise: float = 0.0,
                     log: Callable[[str], None] = print) -> dict:
    """Train a Faster R-CNN handle detector; returns the checkpoint's metadata. ``init``: start from
    another detector checkpoint (:func:`~opend_mj.policy.learned.detector.init_from_detector`).
    ``depth_noise``: the chance that a training image's depth is a real sensor's (:func:`_detector_batch`);
    above 0, validation also measures the target recall under the strong sensor, and the kept epoch
    is the one with the best mean of the clean and the sensor recall."""
    import torch
    from tqdm import tqdm

    from opend_mj.policy.learned.detector import DetectorConfig, build_detector, init_from_detector

    config = config or DetectorConfig()
    data_dir = Path(data_dir)
    dev = torch_device(device)
    torch.manual_seed(seed)
    rng = random.Random(seed)
    train_recs = [r for r in load_records(data_dir, "train")[:max_train]]
    val_recs = load_records(data_dir, "val")[:max_val]
    if not train_recs:
        raise ValueError(f"{data_dir}: no training images")
    model = build_detector(config)
    if pretrained and not resume:
        load_pretrained(model, pretrained, "fasterrcnn", log)
    if init and not resume:
        init_from_detector(model, init, log)
    model = model.to(dev)
    params = [p for p in model.parameters() if p.requires_grad]
    steps_per_epoch = math.ceil(len(train_recs) / batch_size)
    loop = TrainingLoop("fasterrcnn", out, state_path, epochs, max_minutes, progress, log)
    opt, sched = optimise(loop, model, params, lr, epochs, steps_per_epoch, 0.1, resume)
    log(f"fasterrcnn ({config.backbone}): {len(train_recs)} train images, {len(val_recs)} validation images, "
        f"device {dev}, {sum(p.numel() for p in model.parameters()) / 1e6:.2f} M parameters")
    for epoch in range(loop.start_epoch, epochs):
        t0 = time.time()
        model.train()
        order = list(range(len(train_recs)))
        rng.shuffle(order)
        losses, parts = [], {}
        bar = tqdm(range(0, len(order), batch_size), disable=not progress, desc=f"epoch {epoch + 1}/{epochs}",
                   unit="batch")
        stopped = False
        for b in bar:
            x, y = _detector_batch(data_dir, train_recs, order[b:b + batch_size], True, rng, dev, config,
                                   depth_noise=depth_noise)
            ld = model(x, y)
            loss = sum(ld.values())
            opt.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(params, 10.0)
            opt.step()
            if sched.last_epoch + 1 < sched.total_steps:
                sched.step()
            losses.append(loss.item())
            for k, v in ld.items():
                parts.setdefault(k, []).append(v.item())
            bar.set_postfix(loss=f"{np.mean(losses[-20:]):.3f}")
            if loop.out_of_time():
                stopped = True
                break
        train_seconds = time.time() - t0
        # validation loss: train-mode heads (they return losses) with frozen batch-norm statistics
        model.train()
        _set_bn_eval(model)
        vl = []
        with torch.no_grad():
            for b in range(0, len(val_recs), batch_size):
                idx = list(range(b, min(b + batch_size, len(val_recs))))
                x, y = _detector_batch(data_dir, val_recs, idx, False, rng, dev, config)
                vl.append(float(sum(model(x, y).values())) * len(idx))
        row = {"epoch": epoch + 1, "train_loss": float(np.mean(losses)) if losses else float("nan"),
               "val_loss": float(np.sum(vl) / max(1, len(val_recs))),
               **{f"train_{k}": float(np.mean(v)) for k, v in parts.items()},
               "train_seconds": round(train_seconds, 1), "batches": len(losses), "complete": not stopped}
        if eval_every and ((epoch + 1) % eval_every == 0 or epoch + 1 == epochs or stopped):
            m = evaluate_detector_model(model, data_dir, val_recs, threshold)
            row.update({"val_target_recall": m["target_recall"], "val_handle_recall": m["handle_recall"]})
            if depth_noise > 0:
                m = evaluate_detector_model(model, data_dir, val_recs, threshold, sensor=SENSOR_LEVELS[-1])
                row.update({"val_target_recall_sensor": m["target_recall"],
                            "val_target_recall_mean": 0.5 * (row["val_target_recall"] + m["target_recall"])})
        summary = (f"train loss {row['train_loss']:.4f}  val loss {row['val_loss']:.4f}  "
                   f"val target recall {row.get('val_target_recall', float('nan')):.3f}  "
                   f"handle recall {row.get('val_handle_recall', float('nan')):.3f}"
                   + (f"  under the strong sensor {row['val_target_recall_sensor']:.3f}"
                      if "val_target_recall_sensor" in row else ""))
        metric = next((k for k in ("val_target_recall_mean", "val_target_recall") if k in row), None)
        payload = {"config": asdict(config), "data": str(data_dir), "threshold": threshold,
                   "depth_noise": depth_noise, **({"init": str(init)} if init else {})}
        if loop.end_epoch(epoch, row, t0, summary, model, opt, sched, payload, metric, stopped):
            break
    plot_history(loop.history, loop.out.with_name(loop.out.stem + "_curve.png"),
                 f"Faster R-CNN ({config.backbone})", "val_target_recall")
    return json.loads(loop.out.with_suffix(".json").read_text())


def evaluate_detector(checkpoint: Path, data_dir: Path, subset: str = "val", threshold: float | None = None,
                      device: str | None = None, progress: bool = True, limit: int | None = None) -> dict:
    """Target recall after matching; ``threshold`` None: the checkpoint's (see FasterRCNNSolver)."""
    from opend_mj.policy.learned.detector import load_detector

    model, _, ckpt = load_detector(checkpoint, device)
    if threshold is None:
        threshold = float(ckpt.get("threshold", 0.8))
    out = evaluate_detector_model(model, Path(data_dir), load_records(data_dir, subset)[:limit], threshold, progress)
    return {"subset": subset, "threshold": threshold, **out}


def config_from_options(options: dict):
    """The detector's configuration from `opend train`'s options (depth and context only for the
    ``compact_fpn`` backbone)."""
    from opend_mj.policy.learned.detector import DetectorConfig

    backbone, min_size, noise = options["backbone"], options["min_size"], options["depth_noise"]
    return DetectorConfig(backbone=backbone, box_head_dim=options["box_head_dim"], min_size=min_size,
                          max_size=max(min_size, 640) if min_size else None, kinds=options["kinds"],
                          depth=options["depth"] and backbone == "compact_fpn",
                          context=options["context"] and backbone == "compact_fpn",
                          relief_holes=noise > 0, relief_denoise=noise == 0)


#: `opend train --solver fasterrcnn`.
TRAINER = Trainer(solver="fasterrcnn", epochs=6, batch_size=4, lr=5e-4, config=config_from_options,
                  train=train_fasterrcnn, evaluate=evaluate_detector)
