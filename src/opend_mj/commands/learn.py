"""`opend make-data` (training renders) and `opend train` (learned handle solvers)."""

from __future__ import annotations

import json
from pathlib import Path

import click

from opend_mj.policy.learned.detector import BACKBONES
from opend_mj.policy.solvers import trainable_solvers

DEFAULT_DATA = Path("out/handle-data")


def _defaults(field: str) -> str:
    """Each trainable solver's default ``field`` (epochs, batch_size, lr), for the options' help."""
    from opend_mj.policy.solvers import get_trainer

    return "[" + ", ".join(f"{name} {getattr(get_trainer(name), field):g}" for name in trainable_solvers()) + "]"


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
@click.option("--solver", type=click.Choice(trainable_solvers()), required=True,
              help="A solver whose model is trained (its trainer in the solver registry).")
@click.option("--data", "data_dir", type=click.Path(path_type=Path), default=DEFAULT_DATA, show_default=True)
@click.option("--out", type=click.Path(path_type=Path), default=None,
              help="Checkpoint to write [checkpoints/<solver>.pt in the current folder, which the solver then loads before the shipped one].")
@click.option("--state", type=click.Path(path_type=Path), default=None,
              help="Full training state for --resume [out/train/<name>.state.pt].")
@click.option("--epochs", type=int, default=None, help=_defaults("epochs"))
@click.option("--batch-size", type=int, default=None, help=_defaults("batch_size"))
@click.option("--lr", type=float, default=None, help=_defaults("lr"))
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

    from opend_mj.policy.solvers import get_trainer

    trainer = get_trainer(solver)
    if threads:
        torch.set_num_threads(threads)
    out = out or Path(f"checkpoints/{solver}.pt")
    state = state or Path("out/train") / f"{out.stem}.state.pt"
    if evaluate_subset:
        metrics = trainer.evaluate(out, data_dir, evaluate_subset, threshold=threshold, device=device, progress=progress)
        click.echo(json.dumps(metrics))
        return
    options = dict(backbone=backbone, box_head_dim=box_head_dim, min_size=min_size, kinds=kinds, depth=depth,
                   context=context, fusion_layers=fusion_layers, fusion=fusion, image_size=image_size,
                   text_encoder=text_encoder, reword=reword, depth_noise=depth_noise)
    meta = trainer.train(data_dir, out, trainer.config(options), epochs=epochs or trainer.epochs,
                         batch_size=batch_size or trainer.batch_size, lr=lr or trainer.lr, init=init,
                         depth_noise=depth_noise, log=click.echo, pretrained=pretrained, max_minutes=max_minutes,
                         resume=resume, state_path=state, device=device, progress=progress)
    click.echo(f"wrote {out} ({out.stat().st_size / 1e6:.1f} MB); last epoch: {json.dumps(meta['history'][-1])}")
