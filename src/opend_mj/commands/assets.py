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
@click.option("--family", "families", multiple=True, metavar="NAME[=WEIGHT]",
              help="Only these layout families, all describable, drawn by weight (default 1; repeatable), "
                   "e.g. long_door for extra training cabinets [the default mix, half not describable].")
def generate(count: int, seed: int, out: Path, start: int, families) -> None:
    """Write procedural cabinets in SAPIEN PartNet-Mobility format."""
    from opend_mj.assets.procedural import generate_source, generate_sources

    config = family_config(families)
    if start == 0:
        paths = generate_sources(count, seed, out, config)
    else:
        out.mkdir(parents=True, exist_ok=True)
        paths = [generate_source(i, seed, out, config) for i in range(start, start + count)]
    click.echo(f"wrote {len(paths)} cabinets to {out}")


def family_config(families):
    """The generator's configuration for ``--family NAME[=WEIGHT]`` values: only those families, all
    describable (the default configuration for none). Refuses an unknown family or a bad weight."""
    from dataclasses import replace

    from opend_mj.assets.procedural import GeneratorConfig
    from opend_mj.assets.procedural.layouts import FAMILIES

    config = GeneratorConfig()
    if not families:
        return config
    chosen = []
    for item in families:
        name, _, weight = item.partition("=")
        try:
            w = float(weight) if weight else 1.0
        except ValueError:
            w = -1.0
        if not w > 0:
            raise click.BadParameter(f"{item!r}: the weight must be a positive number", param_hint="--family")
        chosen.append((name.strip(), w))
    unknown = [name for name, _ in chosen if name not in FAMILIES]
    if unknown:
        raise click.BadParameter(f"unknown layout families {unknown}; known: {sorted(FAMILIES)}", param_hint="--family")
    return replace(config, valid_layouts=tuple(chosen), invalid_fraction=0.0)
