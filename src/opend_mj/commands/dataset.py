"""`opend build-assets`: compile sources (procedural by default) into a cabinet dataset."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import click


@click.command("build-assets")
@click.option("--source", "source", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="A PartNet-Mobility folder of id folders (e.g. your StorageFurniture copy). "
                   "Default: procedural cabinets, generated into <out>/.sources.")
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=Path("cabinets"),
              show_default=True, help="Output folder for compiled cabinets and manifest.json (in the current folder by default).")
@click.option("--ids", default=None, help="Comma-separated source ids to build (default: all).")
@click.option("--count", type=click.IntRange(min=1), default=None,
              help="Number of procedural cabinets (default 346), or the first N sources of --source.")
@click.option("--seed", type=int, default=0, show_default=True, help="Procedural generator seed.")
@click.option("--workers", type=click.IntRange(min=1), default=None, help="Parallel processes (default: all cores).")
@click.option("--scale", type=click.FloatRange(min=0, min_open=True), default=None,
              help="Scale from PartNet units to metres (default 0.7, as in the paper).")
@click.option("--force", is_flag=True, help="Rebuild even where the cache is valid.")
@click.option("--cache-dir", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Decomposition cache shared across output folders (default: $OPEND_CACHE_DIR, else "
                   "$XDG_CACHE_HOME/opend-mj, else ~/.cache/opend-mj).")
@click.option("--no-feasibility", is_flag=True, help="Skip the feasibility check (each target pushed open with "
              "the cabinet standing in a room; infeasible targets are excluded with their reason).")
@click.option("--no-progress", is_flag=True, help="No progress bar (for logs).")
@click.option("--backend", type=click.Choice(["local", "ray"]), default="local", show_default=True,
              help="local: this machine's process pool; ray: a Ray cluster (--address) or a local Ray instance.")
@click.option("--address", default=None, help="Ray cluster address (e.g. auto); with --backend ray. The "
              "cluster's machines must see --source and --out at the same paths.")
def build_assets(source, out, ids, count, seed, workers, scale, force, cache_dir, no_feasibility, no_progress,
                 backend, address) -> None:
    """Compile cabinets into MJCF, filter them, split them and write the manifest."""
    if address is not None and backend != "ray":
        raise click.UsageError("--address needs --backend ray")
    from opend_mj.assets.config import CompilerConfig, DatasetConfig
    from opend_mj.assets.dataset import build_dataset, format_split_table, list_sources

    config = CompilerConfig() if scale is None else dataclasses.replace(CompilerConfig(), scale=scale)
    dataset = DatasetConfig(seed=seed)
    id_list = [i.strip() for i in ids.split(",") if i.strip()] if ids else None
    if source is None:
        from opend_mj.assets.procedural import generate_sources

        source = out / ".sources"
        n = count or dataset.count
        click.echo(f"generating {n} procedural cabinets (seed {seed}) into {source}")
        generate_sources(n, seed, source)
    try:
        sources = list_sources(source, id_list)
    except FileNotFoundError as exc:
        raise click.UsageError(str(exc)) from exc
    if count and id_list is None:
        sources = sources[:count]
    if backend == "ray" and workers is None:
        workers = 2
    from opend_mj.backends import BackendError

    check = None
    if not no_feasibility:
        from opend_mj.sim.feasibility import RoomCheck

        check = RoomCheck()
    try:
        manifest = build_dataset(sources, out, config=config, dataset=dataset, workers=workers, force=force,
                                 progress=not no_progress, backend=backend, address=address,
                                 cache_dir=cache_dir, check=check)
    except BackendError as exc:
        raise click.ClickException(str(exc)) from exc
    info = manifest.info
    click.echo(f"\n{len(manifest.cabinets)} cabinets valid of {info['sources']} sources "
               f"({info['built']} built, {info['cached']} cached, {len(manifest.rejected)} rejected) "
               f"in {info['seconds']:.1f} s -> {out / 'manifest.json'}")
    reasons: dict[str, int] = {}
    for r in manifest.rejected:
        reasons[r["reason"]] = reasons.get(r["reason"], 0) + 1
    if reasons:
        click.echo("rejected: " + ", ".join(f"{k} {v}" for k, v in sorted(reasons.items())))
    if check is not None:
        n_targets = sum(len(c["targets"]) for c in manifest.cabinets) + len(manifest.excluded_targets)
        click.echo(f"feasibility in a room: {n_targets - len(manifest.excluded_targets)} of {n_targets} targets "
                   f"open to >= {check.config.reach:.0%} of their range; {len(manifest.excluded_targets)} excluded")
        for e in manifest.excluded_targets:
            click.echo(f"  excluded {e['id']} {e['joint']} [{e['reason']}]: {e['message']}")
    click.echo(format_split_table(manifest.to_json()["summary"]))
    if not manifest.cabinets:
        click.echo("error: no cabinet was built", err=True)
        sys.exit(1)
