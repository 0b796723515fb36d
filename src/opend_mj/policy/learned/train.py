"""Training and validation loops of the learned handle solvers (`opend train`); the detector's own
parts are in :mod:`opend_mj.policy.learned.train_detector`.

Both loops read the on-disk format of :mod:`opend_mj.policy.learned.data`, log training and validation
loss per epoch (and a validation metric), write the shipped checkpoint (weights in float16, config,
text-embedding table, history) after every epoch, and keep a full training state (float32 weights,
optimiser, epoch) next to it for ``resume``. CPU by default, CUDA when present.

Augmentation: horizontal flips (p = 0.5); for the affordance model the instruction is mirrored too
(left <-> right; Algorithm 1 is mirror-symmetric), so the language grounding stays correct.

Metrics:

* ``fasterrcnn``: target recall at IoU 0.5 after language matching (the box the solver would
  return for each target overlaps its ground-truth box with IoU >= 0.5), and plain handle recall
  (every ground-truth handle found by some detection above the threshold).
* ``cliport``: the fraction of targets whose predicted centre falls inside the ground-truth box.
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


#: Depth-sensor augmentation of training (``depth_noise``, both solvers): the levels and the numbers of
#: fused frames drawn per image (one frame: a single reading; 8: what an episode fuses,
#: `sim.task.TaskConfig.depth_frames`).
SENSOR_LEVELS = ("mild", "strong")
SENSOR_FRAMES = (1, 8)


def sensor_augment(rgb: np.ndarray, depth: np.ndarray, rng: random.Random, chance: float) -> np.ndarray:
    """``depth`` as the depth_noise sensor gives it (`sim.perturb.sensor_depth`: a level of
    ``SENSOR_LEVELS`` and a frame count of ``SENSOR_FRAMES`` drawn from ``rng``) with probability
    ``chance``, else unchanged; ``rng`` is not drawn from at all when ``chance`` is 0."""
    if chance <= 0 or rng.random() >= chance:
        return depth
    from opend_mj.sim.perturb import sensor_depth

    return sensor_depth(np.ascontiguousarray(rgb), np.ascontiguousarray(depth), rng.choice(SENSOR_LEVELS),
                        rng.getrandbits(31), rng.choice(SENSOR_FRAMES))


def sensor_view(rgb: np.ndarray, depth: np.ndarray, level: str, image_id: int) -> np.ndarray:
    """``depth`` as the depth_noise sensor at ``level`` gives it, fused over an episode's frames
    (``SENSOR_FRAMES[-1]``): validation's view, one draw per image id, the same for every model."""
    from opend_mj.sim.perturb import sensor_depth

    return sensor_depth(np.ascontiguousarray(rgb), np.ascontiguousarray(depth), level, int(image_id),
                        SENSOR_FRAMES[-1])


def _device(device: str | None):
    import torch

    return torch.device(device or ("cuda" if torch.cuda.is_available() else "cpu"))


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


def _half_state(model) -> dict:
    return {k: (v.half() if v.is_floating_point() else v).cpu() for k, v in model.state_dict().items()}


def default_state_path(out: Path) -> Path:
    out = Path(out)
    return out.with_name(out.stem + ".state.pt")


def iou(a, b) -> float:
    ix = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    iy = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    inter = ix * iy
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter
    return inter / union if union > 0 else 0.0


def _valid_targets(record: dict) -> list[dict]:
    return [t for t in record["targets"] if t["box"] is not None and t.get("mask_pixels", 1) > 0]


def _one_cycle(opt, lr: float, total_steps: int, pct_start: float):
    """A one-cycle learning-rate schedule over `total_steps`; on a resumed optimizer it starts afresh."""
    import torch

    for g in opt.param_groups:  # a previous schedule's bookkeeping would otherwise be kept
        g.pop("initial_lr", None), g.pop("max_lr", None), g.pop("min_lr", None)
    return torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=lr, total_steps=max(1, total_steps), pct_start=pct_start)


def _optimise(loop: "_Loop", model, params, lr: float, epochs: int, steps_per_epoch: int, pct_start: float,
              resume: bool):
    """AdamW and a one-cycle schedule over the epochs left; on resume, their saved state (via ``loop``)."""
    import torch

    opt = torch.optim.AdamW(params, lr=lr, weight_decay=1e-4)
    sched = _one_cycle(opt, lr, epochs * steps_per_epoch, pct_start)
    if resume:
        loop.resume(model, opt, sched)
        if loop.rebuild_scheduler:
            sched = _one_cycle(opt, lr, (epochs - loop.start_epoch) * steps_per_epoch, pct_start)
    return opt, sched


class _Loop:
    """Shared bookkeeping: epochs, time limit, checkpoints, resume, history, progress."""

    def __init__(self, solver: str, out: Path, state_path: Path | None, epochs: int, max_minutes: float | None,
                 progress: bool, log: Callable[[str], None]):
        self.solver = solver
        self.out = Path(out)
        self.state_path = Path(state_path) if state_path else default_state_path(self.out)
        self.epochs = epochs
        self.max_minutes = max_minutes
        self.deadline = time.time() + 60 * max_minutes if max_minutes else None
        self.progress = progress
        self.log = log
        self.history: list[dict] = []
        self.start_epoch = 0
        self.trained_seconds = 0.0
        self.best: float | None = None
        self.rebuild_scheduler = False

    def resume(self, model, optimiser, scheduler) -> None:
        from opend_mj.policy.learned.checkpoint_io import read_checkpoint

        if not self.state_path.is_file():
            self.log(f"resume: no state at {self.state_path}; starting fresh")
            return
        st = read_checkpoint(self.state_path, "training state (--resume)")
        model.load_state_dict(st["model"])
        optimiser.load_state_dict(st["optimiser"])
        self.history = st["history"]
        self.start_epoch = st["epoch"] + 1
        self.best = st.get("best")
        if scheduler is not None and st.get("scheduler") and st.get("epochs") == self.epochs:
            scheduler.load_state_dict(st["scheduler"])
        else:  # more (or fewer) epochs than planned: a fresh one-cycle schedule over the rest
            self.rebuild_scheduler = True
        self.trained_seconds = st.get("trained_seconds", 0.0)
        self.log(f"resumed from {self.state_path} after epoch {st['epoch'] + 1}")

    def out_of_time(self) -> bool:
        return self.deadline is not None and time.time() > self.deadline

    def save(self, epoch: int, model, optimiser, scheduler, payload: dict, metric: str | None = None) -> None:
        """Training state always; the shipped checkpoint when the validation metric is the best so far;
        both as plain data (`checkpoint_io.write_checkpoint`)."""
        from opend_mj.policy.learned.checkpoint_io import write_checkpoint

        self.out.parent.mkdir(parents=True, exist_ok=True)
        self.state_path.parent.mkdir(parents=True, exist_ok=True)
        value = self.history[-1].get(metric) if metric else None
        improved = value is None or not np.isfinite(value) or self.best is None or value > self.best \
            or not self.out.is_file()
        if improved and value is not None and np.isfinite(value):
            self.best = float(value)
        write_checkpoint({"model": model.state_dict(), "optimiser": optimiser.state_dict(),
                          "scheduler": scheduler.state_dict() if scheduler is not None else None,
                          "epoch": epoch, "epochs": self.epochs, "history": self.history, "best": self.best,
                          "trained_seconds": self.trained_seconds}, self.state_path)
        if not improved:
            self.log(f"kept {self.out} (best validation {metric} {self.best:.3f})")
            meta = json.loads(self.out.with_suffix(".json").read_text())
            meta["history"] = self.history
            self.out.with_suffix(".json").write_text(json.dumps(meta, indent=1, default=str) + "\n")
            return
        ckpt = {"solver": self.solver, "model": _half_state(model), "epoch": epoch, "history": self.history,
                "trained_seconds": round(self.trained_seconds, 1), **payload}
        tmp = self.out.with_suffix(".tmp")
        write_checkpoint(ckpt, tmp)
        tmp.replace(self.out)
        self.out.with_suffix(".json").write_text(json.dumps(
            {k: v for k, v in ckpt.items() if k not in ("model", "text")}, indent=1, default=str) + "\n")

    def end_epoch(self, epoch: int, row: dict, started: float, summary: str, model, optimiser, scheduler,
                  payload: dict, metric: str | None, stopped: bool) -> bool:
        """An epoch's close: its wall time (s, from ``started``) counted, ``row`` kept in the history
        and logged after ``summary``, the state and (when best) the checkpoint saved. True where
        training stops here (the time limit was reached)."""
        seconds = time.time() - started
        self.trained_seconds += seconds
        row["seconds"] = round(seconds, 1)
        self.history.append(row)
        self.log(f"epoch {epoch + 1}: {summary}  ({row['seconds']:.0f} s)")
        self.save(epoch, model, optimiser, scheduler, payload, metric=metric)
        if stopped:
            self.log(f"stopped: time limit of {self.max_minutes} min reached")
        return stopped


def plot_history(history: list[dict], out_png: Path, title: str, metric: str) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ep = [h["epoch"] for h in history]
    fig, ax = plt.subplots(1, 2, figsize=(9, 3.4))
    ax[0].plot(ep, [h["train_loss"] for h in history], "o-", label="train")
    ax[0].plot(ep, [h["val_loss"] for h in history], "s-", label="validation")
    ax[0].set_xlabel("epoch")
    ax[0].set_ylabel("loss")
    ax[0].legend()
    ax[1].plot(ep, [h.get(metric, float("nan")) for h in history], "s-", color="C2")
    ax[1].set_xlabel("epoch")
    ax[1].set_ylabel(f"validation {metric}")
    ax[1].set_ylim(0, 1)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(out_png, dpi=90)
    plt.close(fig)
    return Path(out_png)


def load_pretrained(model, path: Path, solver: str, log: Callable[[str], None] = print) -> int:
    """Initialise the image stream from a local torchvision classification state dict (opt-in).

    ``cliport``: a ``resnet18`` state dict (conv1's RGB filters go to the RGB channels, the depth and
    coordinate channels start at zero). ``fasterrcnn``: a ``mobilenet_v3_large`` or ``resnet50`` state
    dict, loaded into ``backbone.body``. Keys that do not fit are skipped. Returns the tensors loaded.
    The file is read as plain data (`checkpoint_io.read_checkpoint`), as torchvision's are.
    """
    import torch

    from opend_mj.policy.learned.checkpoint_io import read_checkpoint

    src = read_checkpoint(path, "pretrained state dict (--pretrained)")
    src = src.get("model", src.get("state_dict", src)) if isinstance(src, dict) else src
    own = model.state_dict()
    mapped = {}
    for k, v in src.items():
        if solver == "cliport":
            k2 = {"conv1.weight": "stem.0.weight"}.get(k, k.replace("bn1.", "stem.1.", 1) if k.startswith("bn1.") else k)
        else:
            k2 = "backbone.body." + (k[len("features."):] if k.startswith("features.") else k)
        if k2 not in own:
            continue
        if own[k2].shape == v.shape:
            mapped[k2] = v
        elif k2 == "stem.0.weight" and v.shape[1] == 3:
            w = torch.zeros_like(own[k2])
            w[:, :3] = v
            mapped[k2] = w
    model.load_state_dict(mapped, strict=False)
    log(f"pretrained: {len(mapped)} tensors from {path}")
    return len(mapped)


# --------------------------------------------------------------------------------------------------
# CLIPort-style affordance model
# --------------------------------------------------------------------------------------------------


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
    dev = _device(device)
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
    loop = _Loop("cliport", out, state_path, epochs, max_minutes, progress, log)
    opt, sched = _optimise(loop, model, model.parameters(), lr, epochs, steps_per_epoch, 0.15, resume)
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
        for t in _valid_targets(rec):
            prob = predict(model, config, text, rgb, depth, t["instruction"])
            res[t["type"]].append(cliport_hits(prob, t["box"]))
    allh = res["door"] + res["drawer"]
    return {"subset": subset, "images": len(recs), "targets": len(allh),
            "centre_in_box": float(np.mean(allh)) if allh else float("nan"),
            "door": float(np.mean(res["door"])) if res["door"] else float("nan"),
            "drawer": float(np.mean(res["drawer"])) if res["drawer"] else float("nan")}
