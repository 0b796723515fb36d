"""Click options shared by the commands that open one task scene (render, view, teleop)."""

from __future__ import annotations

from pathlib import Path

import click

cabinets_option = click.option(
    "--cabinets", "cabinets", type=click.Path(file_okay=False, path_type=Path), default=Path("cabinets"),
    show_default=True, help="Compiled dataset folder (with manifest.json).")

target_option = click.option("--target", default=None, help="Target joint (default: the cabinet's first target).")
hand_option = click.option("--hand", default="allegro", show_default=True)
room_option = click.option("--room", type=click.IntRange(0, 8), default=None,
                           help="Room preset 0-8 (default: from the seed).")
seed_option = click.option("--seed", type=int, default=0, show_default=True)


def scene_options(func):
    """--target, --hand, --room, --seed (in that order on the command line help)."""
    for option in (seed_option, room_option, hand_option, target_option):
        func = option(func)
    return func
