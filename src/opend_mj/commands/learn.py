"""`opend make-data` (training renders) and `opend train` (learned handle solvers)."""

from __future__ import annotations

import json
from pathlib import Path

import click

from opend_mj.policy.learned.detector import BACKBONES

DEFAULT_DATA = Path("out/handle-data")


@click.command("make-data")
@click.option("--cabinets", "cabinets_dir", type=click.Path(path_type=Path), default=Path("cabinets"), show_default=True,
              help="Compiled dataset (with manifest.json).")
@click.option("--out", type=click.Path(path_type=Path), default=DEFAULT_DATA, show_default=True)
@click.option("--images", "n_images", type=int, default=1740, show_default=True)
@click.option("--split", type=click.Choice(["train", "test"]), default="train", show_default=True,
              help="Cabinets to render: train (-> train/val subsets, 80/20 by cabinet) or test.")
@click.option("--size", "image_size", type=int, default=256, show_default=True)
@click.option("--max-shift", type=float, default=0.10, show_default=True, help="Camera shift per axis (m).")
@click.option("--colour-prob", type=float, default=0.5, show_default=True, help="Chance of a random handle colour.")
@click.option("--plain-prob", type=float, default=0.0, show_default=True,
              help="Chance that a view shows the cabinet plain light grey, as untextured PartNet-Mobility "
                   "cabinets compile.")
@click.option("--val-fraction", type=float, default=0.2, show_default=True)
@click.option("--views-per-scene", type=int, default=4, show_default=True)
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--workers", type=int, default=2, show_default=True)
@click.option("--progress/--no-progress", default=True)
def make_data(cabinets_dir, out, n_images, split, image_size, max_shift, colour_prob, plain_prob, val_fraction,
              views_per_scene, seed, workers, progress):
    """Render labelled training images (handle boxes, instructions, affordance masks)."""
    from opend_mj.policy.learned.data import DataConfig, make_dataset

    config = DataConfig(n_images=n_images, image_size=image_size, max_shift=max_shift, colour_prob=colour_prob,
                        plain_prob=plain_prob, val_fraction=val_fraction, views_per_scene=views_per_scene, seed=seed, split=split)
    info = make_dataset(cabinets_dir, out, config, workers=workers, progress=progress)
    click.echo(f"{info['images']} images in {out} ({info['subsets']}), {info['targets']} targets, "
               f"{info['seconds']:.0f} s")


@click.command("train")
@click.option("--solver", type=click.Choice(["fasterrcnn", "cliport"]), required=True)
@click.option("--data", "data_dir", type=click.Path(path_type=Path), default=DEFAULT_DATA, show_default=True)
@click.option("--out", type=click.Path(path_type=Path), default=None,
              help="Checkpoint to write [checkpoints/<solver>.pt in the current folder, which the solver then loads before the shipped one].")
@click.option("--state", type=click.Path(path_type=Path), default=None,
              help="Full training state for --resume [out/train/<name>.state.pt].")
@click.option("--epochs", type=int, default=None, help="[fasterrcnn 6, cliport 10]")
@click.option("--batch-size", type=int, default=None, help="[fasterrcnn 4, cliport 8]")
@click.option("--lr", type=float, default=None, help="[fasterrcnn 5e-4, cliport 1e-3]")
@click.option("--max-minutes", type=float, default=None, help="Stop (and save) after this much wall time.")
@click.option("--resume", is_flag=True, help="Continue from the training state.")
@click.option("--device", default=None, help="cpu / cuda [cuda when present].")
@click.option("--threads", type=int, default=None, help="torch CPU threads.")
@click.option("--backbone", type=click.Choice(list(BACKBONES)),
              default="compact_fpn", show_default=True,
              help="fasterrcnn backbone: the paper's three, or this project's compact_fpn (shipped).")
@click.option("--box-head-dim", type=int, default=128, show_default=True, help="fasterrcnn box head (torchvision: 1024).")
@click.option("--min-size", type=int, default=None, help="fasterrcnn input size (builder default if unset).")
@click.option("--fusion-layers", type=click.Choice(["2", "3", "4"]), default="3", show_default=True)
@click.option("--fusion", type=click.Choice(["film", "product"]), default="film", show_default=True)
@click.option("--image-size", type=int, default=128, show_default=True, help="cliport input resolution.")
@click.option("--text-encoder", default="minilm", show_default=True, help="cliport text encoder (minilm, bow).")
@click.option("--reword", type=click.FloatRange(0, 1), default=0.0, show_default=True,
              help="cliport: chance that a training instruction is a grammar rewording of its template.")
@click.option("--evaluate", "evaluate_subset", type=click.Choice(["train", "val", "test"]), default=None,
              help="Do not train: evaluate the checkpoint (--out) on this subset of --data and print the metrics.")
@click.option("--threshold", type=float, default=None, help="fasterrcnn detection threshold for --evaluate.")
@click.option("--pretrained", type=click.Path(exists=True, dir_okay=False, path_type=Path), default=None,
              help="Local torchvision classification weights for the image stream (resnet18 for cliport, "
                   "mobilenet_v3_large / resnet50 for fasterrcnn); nothing is downloaded. Default: from scratch.")
@click.option("--kinds/--no-kinds", default=True, show_default=True,
              help="fasterrcnn: two handle classes (drawer, door), so a drawer is ranked among drawers.")
@click.option("--depth/--no-depth", default=True, show_default=True,
              help="fasterrcnn (compact_fpn): read the depth relief as a fourth channel.")
@click.option("--context/--no-context", default=True, show_default=True,
              help="fasterrcnn (compact_fpn): the box head also reads the box's surroundings, so a bar along a "
                   "door's edge is told from a drawer's.")
@click.option("--init", "init", type=click.Path(exists=True, dir_okay=False, path_type=Path), default=None,
              help="Start from this checkpoint of the same solver (fine-tuning; for fasterrcnn a one-class "
                   "checkpoint seeds both kinds).")
@click.option("--depth-noise", type=click.FloatRange(0, 1), default=0.0, show_default=True,
              help="Chance that a training image's depth is a real sensor's (noise and holes, `--perturb "
                   "depth_noise` at a level drawn per image); validation adds the strong sensor's images, "
                   "and the epoch kept is the best mean of both.")
@click.option("--progress/--no-progress", default=True)
def train(solver, data_dir, out, state, epochs, batch_size, lr, max_minutes, resume, device, threads, backbone,
          box_head_dim, min_size, fusion_layers, fusion, image_size, text_encoder, reword, evaluate_subset, threshold,
          pretrained, kinds, depth, context, init, depth_noise, progress):
    """Train a learned handle solver on `opend make-data` images."""
    import torch

    from opend_mj.policy.learned import train as T
    from opend_mj.policy.learned import train_detector as TD

    if threads:
        torch.set_num_threads(threads)
    out = out or Path(f"checkpoints/{solver}.pt")
    state = state or Path("out/train") / f"{out.stem}.state.pt"
    if evaluate_subset:
        if solver == "cliport":
            metrics = T.evaluate_cliport(out, data_dir, evaluate_subset, device=device, progress=progress)
        else:
            metrics = TD.evaluate_detector(out, data_dir, evaluate_subset, threshold=threshold, device=device,
                                          progress=progress)
        click.echo(json.dumps(metrics))
        return
    common = dict(pretrained=pretrained, max_minutes=max_minutes, resume=resume, state_path=state, device=device, progress=progress)
    if solver == "cliport":
        from opend_mj.policy.learned.affordance import AffordanceConfig

        cfg = AffordanceConfig(fusion_layers=int(fusion_layers), fusion=fusion, image_size=image_size,
                               text_encoder=text_encoder, reword=reword, fill_holes=depth_noise == 0)
        meta = T.train_cliport(data_dir, out, cfg, epochs=epochs or 10, batch_size=batch_size or 8, lr=lr or 1e-3,
                               init=init, depth_noise=depth_noise, log=click.echo, **common)
    else:
        from opend_mj.policy.learned.detector import DetectorConfig

        cfg = DetectorConfig(backbone=backbone, box_head_dim=box_head_dim, min_size=min_size,
                             max_size=max(min_size, 640) if min_size else None, kinds=kinds,
                             depth=depth and backbone == "compact_fpn", context=context and backbone == "compact_fpn",
                             relief_holes=depth_noise > 0, relief_denoise=depth_noise == 0)
        meta = TD.train_fasterrcnn(data_dir, out, cfg, epochs=epochs or 6, batch_size=batch_size or 4, lr=lr or 5e-4,
                                  init=init, depth_noise=depth_noise, log=click.echo, **common)
    click.echo(f"wrote {out} ({out.stat().st_size / 1e6:.1f} MB); last epoch: {json.dumps(meta['history'][-1])}")
