"""Training and validation of the CLIPort-style affordance model (`opend train --solver cliport`).

The loop shared with the other models is :mod:`opend_mj.policy.learned.loop`; here what is this
model's own: its batches and augmentation (horizontal flips with the instruction mirrored, left <->
right, since Algorithm 1 is mirror-symmetric; grammar rewordings; a real depth sensor's images) and
its metric, the fraction of targets whose predicted centre falls inside the ground-truth box.
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

from opend_mj.policy.learned.data import load_images, load_records
from opend_mj.policy.learned.loop import (
    SENSOR_LEVELS,
    Trainer,
    TrainingLoop,
    load_pretrained,
    optimise,
    plot_history,
    sensor_augment,
    sensor_view,
    torch_device,
    valid_targets,
)


def mirror_instruction(text: str) -> str:
    words = text.split()
    swap = {"left": "right", "right": "left"}
    return " ".join(swap.get(w, w) for w in words)


def training_instruction(template: str, rng: random.Random, reword: float, choices: int = 50) -> str:
    """``template``, or with chance ``reword`` one of ``choices`` grammar rewordings of it (drawn with
    ``rng``), so a text encoder is trained on the words people use, each of them naming the same target."""
    if reword <= 0 or rng.random() >= reword:
        return template
    from opend_mj.language import parse_instruction, rewordings

    return rng.choice(rewordings(parse_instruction(template), choices, seed=rng.randrange(1 << 16)))


def _cliport_batch(data_dir, records, pairs, text, config, augment: bool, rng: random.Random,
                   depth_noise: float = 0.0, sensor: str | None = None):
    """Inputs, instruction embeddings and target masks of a batch. Augmentation: horizontal flips
    (the instruction mirrored), rewordings, and with chance ``depth_noise`` a real sensor's depth
    (:func:`sensor_augment`). ``sensor`` ("mild" / "strong", validation): every image's depth as that
    sensor gives it (:func:`sensor_view`).
    Depth reaches the model as :func:`affordance.predict` gives it (holes filled where the config says)."""
    import torch

    from opend_mj.policy.learned.affordance import prepare_image, target_mask
    from opend_mj.policy.perception.noise import fill_holes

    xs, ts, ys, instr = [], [], [], []
    for ri, ti in pairs:
        rec = records[ri]
        rgb, depth, mask = load_images(data_dir, rec)
        t = rec["targets"][ti]
        y = target_mask(mask, t["mask_value"], dilate=1)
        instruction = t["instruction"]
        if augment and rng.random() < 0.5:
            rgb, depth, y = rgb[:, ::-1], depth[:, ::-1], y[:, ::-1]
            instruction = mirror_instruction(instruction)
        if augment:
            instruction = training_instruction(instruction, rng, config.reword)
            depth = sensor_augment(rgb, depth, rng, depth_noise)
        if sensor is not None:
            depth = sensor_view(rgb, depth, sensor, rec["id"])
        if config.fill_holes:
            depth = fill_holes(np.asarray(depth))
        x = prepare_image(rgb.copy(), depth.copy(), config.image_size)
        yt = torch.from_numpy(np.ascontiguousarray(y))[None, None]
        if yt.shape[-1] != config.image_size:
            yt = torch.nn.functional.adaptive_max_pool2d(yt, config.image_size)
        xs.append(x)
        ys.append(yt[0])
        instr.append(instruction)
    ts = torch.from_numpy(_encode_for_training(text, instr))
    return torch.stack(xs), ts, torch.stack(ys)


#: (encoder name, rewording) -> embedding: kept out of the table saved with the model (templates only).
_REWORDED: dict[tuple[str, str], np.ndarray] = {}


def _encode_for_training(text, instr: list[str]) -> np.ndarray:
    """``text.encode``, except that texts outside its table (grammar rewordings) are encoded apart.
    Without rewording every training text is in the table already (it is filled before training)."""
    new = sorted({t for t in instr if t not in text.table and (text.name, t) not in _REWORDED})
    for t, e in zip(new, text.encoder.encode(new) if new else []):
        _REWORDED[(text.name, t)] = np.asarray(e, np.float32)
    return np.stack([text.table[t] if t in text.table else _REWORDED[(text.name, t)] for t in instr]).astype(np.float32)


def _pairs(records, all_targets: bool, rng: random.Random | None = None):
    out = []
    for i, r in enumerate(records):
        valid = [k for k, t in enumerate(r["targets"]) if t["box"] is not None and t.get("mask_pixels", 1) > 0]
        if not valid:
            continue
        if all_targets:
            out += [(i, k) for k in valid]
        else:
            out.append((i, rng.choice(valid) if rng else valid[r["id"] % len(valid)]))
    return out


def cliport_hits(prob: np.ndarray, box, pad: float = 0.0) -> bool:
    from opend_mj.policy.learned.affordance import map_to_box

    (u, v), _, _, _ = map_to_box(prob)
    return box[0] - pad <= u <= box[2] + pad and box[1] - pad <= v <= box[3] + pad


def init_from_checkpoint(model, checkpoint: Path | str, log: Callable[[str], None] = print) -> int:
    """Load every tensor of a checkpoint's model whose name and shape fit ``model``; returns the count."""
    from opend_mj.policy.learned import checkpoint_tensors

    src = checkpoint_tensors(checkpoint)
    own = model.state_dict()
    loaded = {k: v for k, v in src.items() if k in own and own[k].shape == v.shape}
    model.load_state_dict(loaded, strict=False)
    log(f"init: {len(loaded)} of {len(own)} tensors from {checkpoint}")
    return len(loaded)


def train_cliport(data_dir: Path, out: Path, config=None, epochs: int = 10, batch_size: int = 8, lr: float = 1e-3,
                  pos_weight: float = 20.0, max_minutes: float | None = None, resume: bool = False,
                  state_path: Path | None = None, device: str | None = None, progress: bool = True,
                  seed: int = 0, max_train: int | None = None, max_val: int | None = None,
                  pretrained: Path | None = None, init: Path | None = None, depth_noise: float = 0.0,
                  log: Callable[[str], None] = print) -> dict:
    """Train the CLIPort-style affordance model; returns the checkpoint's metadata. ``init``: start
    from another CLIPort checkpoint of the same architecture (fine-tuning on new renders);
    ``depth_noise``: the chance that a training image's depth is a real sensor's (:func:`_cliport_batch`)."""
    import torch
    from tqdm import tqdm

    from opend_mj.policy.learned.affordance import AffordanceConfig, build_model
    from opend_mj.policy.learned.text import CachedEncoder, algorithm1_instructions

    config = config or AffordanceConfig()
    data_dir = Path(data_dir)
    dev = torch_device(device)
    torch.manual_seed(seed)
    rng = random.Random(seed)
    train_recs = load_records(data_dir, "train")[:max_train]
    val_recs = load_records(data_dir, "val")[:max_val]
    if not train_recs:
        raise ValueError(f"{data_dir}: no training images")
    text = CachedEncoder(config.text_encoder)
    instructions = sorted({t["instruction"] for r in train_recs + val_recs for t in r["targets"]})
    # cache (saved with the model): every Algorithm 1 instruction, so inference needs no text encoder
    text.encode(sorted(set(instructions + [mirror_instruction(s) for s in instructions] + algorithm1_instructions())))
    config = AffordanceConfig(**{**asdict(config), "text_dim": int(text.dim)})
    model = build_model(config)
    if pretrained and not resume:
        load_pretrained(model, pretrained, "cliport", log)
    if init and not resume:
        init_from_checkpoint(model, init, log)
    model = model.to(dev)
    steps_per_epoch = math.ceil(len(train_recs) / batch_size)
    loop = TrainingLoop("cliport", out, state_path, epochs, max_minutes, progress, log)
    opt, sched = optimise(loop, model, model.parameters(), lr, epochs, steps_per_epoch, 0.15, resume)
    bce = torch.nn.BCEWithLogitsLoss(pos_weight=torch.tensor(pos_weight, device=dev))
    val_pairs = _pairs(val_recs, all_targets=True)
    log(f"cliport: {len(train_recs)} train images, {len(val_pairs)} validation targets, device {dev}, "
        f"{sum(p.numel() for p in model.parameters()) / 1e6:.2f} M parameters")
    for epoch in range(loop.start_epoch, epochs):
        t0 = time.time()
        model.train()
        pairs = _pairs(train_recs, all_targets=False, rng=rng)
        rng.shuffle(pairs)
        losses = []
        bar = tqdm(range(0, len(pairs), batch_size), disable=not progress, desc=f"epoch {epoch + 1}/{epochs}",
                   unit="batch")
        stopped = False
        for b in bar:
            x, t, y = _cliport_batch(data_dir, train_recs, pairs[b:b + batch_size], text, config, True, rng,
                                     depth_noise=depth_noise)
            loss = bce(model(x.to(dev), t.to(dev)), y.to(dev))
            opt.zero_grad()
            loss.backward()
            opt.step()
            if sched.last_epoch + 1 < sched.total_steps:
                sched.step()
            losses.append(loss.item())
            bar.set_postfix(loss=f"{np.mean(losses[-20:]):.4f}")
            if loop.out_of_time():
                stopped = True
                break
        train_seconds = time.time() - t0
        model.eval()
        val_loss, hits = _cliport_validate(model, data_dir, val_recs, val_pairs, text, config, batch_size, dev, rng,
                                           bce)
        row = {"epoch": epoch + 1, "train_loss": float(np.mean(losses)) if losses else float("nan"),
               "val_loss": val_loss / max(1, len(val_pairs)),
               "val_centre_in_box": float(np.mean(hits)) if hits else float("nan"),
               "train_seconds": round(train_seconds, 1), "batches": len(losses), "complete": not stopped}
        summary = (f"train loss {row['train_loss']:.4f}  val loss {row['val_loss']:.4f}  "
                   f"val centre-in-box {row['val_centre_in_box']:.3f}")
        if depth_noise > 0:  # a sensor model is chosen on exact renders and the strong sensor alike
            _, sensor_hits = _cliport_validate(model, data_dir, val_recs, val_pairs, text, config, batch_size, dev,
                                               rng, bce, sensor=SENSOR_LEVELS[-1])
            row["val_centre_in_box_sensor"] = float(np.mean(sensor_hits)) if sensor_hits else float("nan")
            row["val_centre_in_box_mean"] = 0.5 * (row["val_centre_in_box"] + row["val_centre_in_box_sensor"])
            summary += f"  under the strong sensor {row['val_centre_in_box_sensor']:.3f}"
        metric = "val_centre_in_box_mean" if depth_noise > 0 else "val_centre_in_box"
        payload = {"config": asdict(config), "text": text.state(), "data": str(data_dir), "pos_weight": pos_weight,
                   "depth_noise": depth_noise, **({"init": str(init)} if init else {})}
        if loop.end_epoch(epoch, row, t0, summary, model, opt, sched, payload, metric, stopped):
            break
    plot_history(loop.history, loop.out.with_name(loop.out.stem + "_curve.png"), "CLIPort-style affordance model",
                 "val_centre_in_box")
    return json.loads(loop.out.with_suffix(".json").read_text())


def _cliport_validate(model, data_dir, records, pairs, text, config, batch_size, dev, rng, bce,
                      sensor: str | None = None) -> tuple[float, list[bool]]:
    """One pass over the validation targets: the summed loss (times each batch's size) and, per
    target, whether the map's peak lies inside its box; ``sensor``: every image's depth as that
    depth_noise level gives it (:func:`_cliport_batch`)."""
    import torch

    loss, hits = 0.0, []
    with torch.no_grad():
        for b in range(0, len(pairs), batch_size):
            chunk = pairs[b:b + batch_size]
            x, t, y = _cliport_batch(data_dir, records, chunk, text, config, False, rng, sensor=sensor)
            logits = model(x.to(dev), t.to(dev))
            loss += float(bce(logits, y.to(dev))) * len(chunk)
            prob = torch.sigmoid(logits)[:, 0].cpu().numpy()
            for p, (ri, ti) in zip(prob, chunk):
                box = np.asarray(records[ri]["targets"][ti]["box"]) * (config.image_size / records[ri]["width"])
                hits.append(cliport_hits(p, box))
    return loss, hits


def evaluate_cliport(checkpoint: Path, data_dir: Path, subset: str = "val", device: str | None = None,
                     progress: bool = True, limit: int | None = None) -> dict:
    """Fraction of targets whose predicted centre is inside the ground-truth box, per type."""
    from tqdm import tqdm

    from opend_mj.policy.learned.affordance import load_affordance, predict

    model, config, text, _ = load_affordance(checkpoint, device)
    recs = load_records(data_dir, subset)[:limit]
    res = {"door": [], "drawer": []}
    for rec in tqdm(recs, disable=not progress, desc=f"eval cliport {subset}"):
        rgb, depth, _ = load_images(data_dir, rec)
        for t in valid_targets(rec):
            prob = predict(model, config, text, rgb, depth, t["instruction"])
            res[t["type"]].append(cliport_hits(prob, t["box"]))
    allh = res["door"] + res["drawer"]
    return {"subset": subset, "images": len(recs), "targets": len(allh),
            "centre_in_box": float(np.mean(allh)) if allh else float("nan"),
            "door": float(np.mean(res["door"])) if res["door"] else float("nan"),
            "drawer": float(np.mean(res["drawer"])) if res["drawer"] else float("nan")}


def config_from_options(options: dict):
    """The model's configuration from `opend train`'s options."""
    from opend_mj.policy.learned.affordance import AffordanceConfig

    return AffordanceConfig(fusion_layers=int(options["fusion_layers"]), fusion=options["fusion"],
                            image_size=options["image_size"], text_encoder=options["text_encoder"],
                            reword=options["reword"], fill_holes=options["depth_noise"] == 0)


def evaluate(checkpoint: Path, data_dir: Path, subset: str = "val", *, threshold: float | None = None,
             device: str | None = None, progress: bool = True) -> dict:
    """:func:`evaluate_cliport` as `opend train --evaluate` calls it (a map has no threshold)."""
    return evaluate_cliport(checkpoint, data_dir, subset, device=device, progress=progress)


#: `opend train --solver cliport`.
TRAINER = Trainer(solver="cliport", epochs=10, batch_size=8, lr=1e-3, config=config_from_options, train=train_cliport,
                  evaluate=evaluate)
