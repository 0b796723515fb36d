"""Asset commands: procedural cabinet sources (and, later, the compiler)."""

from __future__ import annotations

from pathlib import Path

import click


@click.command("generate")
@click.option("--count", type=click.IntRange(min=1), default=346, show_default=True,
              help="Number of procedural cabinets to write.")
@click.option("--seed", type=int, default=0, show_default=True, help="Generator seed.")
@click.option("--out", "out", type=click.Path(file_okay=False, path_type=Path), default=Path("sources"),
              show_default=True, help="Folder that receives one PartNet-Mobility folder per cabinet.")
@click.option("--start", type=click.IntRange(min=0), default=0, show_default=True,
              help="Index of the first cabinet (ids are proc_<index>).")
def generate(count: int, seed: int, out: Path, start: int) -> None:
    """Write procedural cabinets in SAPIEN PartNet-Mobility format."""
    from opend_mj.assets.procedural import generate_source, generate_sources

    if start == 0:
        paths = generate_sources(count, seed, out)
    else:
        out.mkdir(parents=True, exist_ok=True)
        paths = [generate_source(i, seed, out) for i in range(start, start + count)]
    click.echo(f"wrote {len(paths)} cabinets to {out}")
