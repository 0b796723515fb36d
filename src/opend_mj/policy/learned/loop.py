"""The training loop that every learned model's training shares (`opend train`, the modules
:mod:`.train_cliport` and :mod:`.train_detector`): epochs, a time limit, the checkpoint after every
epoch (weights in float16, config, history; the best validation epoch kept) and a full training
state beside it for ``resume`` (float32 weights, optimiser, schedule, epoch), AdamW with a one-cycle
schedule, the device (CPU by default, CUDA when present), and what both models' batches use:
the depth sensor's augmentation, box overlap, the targets an image holds, a local pretrained image
stream, and the loss curve.

A trained model is one module with a :class:`Trainer` (its defaults, its configuration from
`opend train`'s options, its training and evaluation); the solver registry
(:func:`opend_mj.policy.solvers.get_trainer`) names it.
"""

from __future__ import annotations

import json
import random
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np


@dataclass(frozen=True)
class Trainer:
    """How `opend train --solver <solver>` trains and evaluates one model.

    ``config(options)``: the model's configuration from `opend train`'s options (a dict of them by
    name); ``train(data_dir, out, config, *, epochs, batch_size, lr, init, depth_noise, pretrained,
    max_minutes, resume, state_path, device, progress, log)``: train, write ``out``, return the
    checkpoint's metadata; ``evaluate(checkpoint, data_dir, subset, *, threshold, device, progress)``:
    the checkpoint's metrics on a subset of the data. ``epochs``, ``batch_size``, ``lr``: the
    defaults where the options give none."""

    solver: str
    epochs: int
    batch_size: int
    lr: float
    config: Callable[[dict], Any]
    train: Callable[..., dict]
    evaluate: Callable[..., dict]


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


def torch_device(device: str | None):
    """``device`` as a torch device; None: CUDA where present, else the CPU."""
    import torch

    return torch.device(device or ("cuda" if torch.cuda.is_available() else "cpu"))


def half_state(model) -> dict:
    """A model's state with its floating-point tensors as float16, on the CPU (the shipped checkpoint's)."""
    return {k: (v.half() if v.is_floating_point() else v).cpu() for k, v in model.state_dict().items()}


def default_state_path(out: Path) -> Path:
    """Where the full training state of the checkpoint ``out`` is kept: ``<stem>.state.pt`` beside it."""
    out = Path(out)
    return out.with_name(out.stem + ".state.pt")


def iou(a, b) -> float:
    """Intersection over union of two boxes (u0, v0, u1, v1)."""
    ix = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    iy = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    inter = ix * iy
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter
    return inter / union if union > 0 else 0.0


def valid_targets(record: dict) -> list[dict]:
    """An image record's targets that have a box and a mask."""
    return [t for t in record["targets"] if t["box"] is not None and t.get("mask_pixels", 1) > 0]


def one_cycle(opt, lr: float, total_steps: int, pct_start: float):
    """A one-cycle learning-rate schedule over `total_steps`; on a resumed optimizer it starts afresh."""
    import torch

    for g in opt.param_groups:  # a previous schedule's bookkeeping would otherwise be kept
        g.pop("initial_lr", None), g.pop("max_lr", None), g.pop("min_lr", None)
    return torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=lr, total_steps=max(1, total_steps), pct_start=pct_start)


def optimise(loop: "TrainingLoop", model, params, lr: float, epochs: int, steps_per_epoch: int, pct_start: float,
             resume: bool):
    """AdamW and a one-cycle schedule over the epochs left; on resume, their saved state (via ``loop``)."""
    import torch

    opt = torch.optim.AdamW(params, lr=lr, weight_decay=1e-4)
    sched = one_cycle(opt, lr, epochs * steps_per_epoch, pct_start)
    if resume:
        loop.resume(model, opt, sched)
        if loop.rebuild_scheduler:
            sched = one_cycle(opt, lr, (epochs - loop.start_epoch) * steps_per_epoch, pct_start)
    return opt, sched


class TrainingLoop:
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
        ckpt = {"solver": self.solver, "model": half_state(model), "epoch": epoch, "history": self.history,
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
