"""Click options shared by the commands that open one task scene (render, view, teleop)."""

from __future__ import annotations

from pathlib import Path

import click

cabinets_option = click.option(
    "--cabinets", "cabinets", type=click.Path(file_okay=False, path_type=Path), default=Path("cabinets"),
    show_default=True, help="Compiled dataset folder (with manifest.json).")

target_option = click.option("--target", default=None, help="Target joint (default: the cabinet's first target).")


def check_hand(ctx, param, value):
    """A registered hand's name; a usage error (exit 2) naming the known ones otherwise."""
    from opend_mj.sim.hands import list_hands

    if value not in list_hands():
        raise click.BadParameter(f"unknown hand {value!r}; known: {', '.join(list_hands())}", ctx, param)
    return value


hand_option = click.option("--hand", default="allegro", show_default=True, callback=check_hand)
room_option = click.option("--room", type=click.IntRange(0, 8), default=None,
                           help="Room preset 0-8 (default: from the seed).")
seed_option = click.option("--seed", type=int, default=0, show_default=True)


def scene_options(func):
    """--target, --hand, --room, --seed (in that order on the command line help)."""
    for option in (seed_option, room_option, hand_option, target_option):
        func = option(func)
    return func


def episode_from_options(cabinets: Path, cabinet_id: str, target: str | None, hand: str, seed: int,
                         room: int | None):
    """The EpisodeSpec the scene options name; a usage error for a missing cabinet or target."""
    from opend_mj.sim.cabinet import CabinetError, load_cabinet_info
    from opend_mj.sim.task import EpisodeSpec

    try:
        info = load_cabinet_info(cabinets / cabinet_id)
    except CabinetError as exc:
        raise click.UsageError(str(exc)) from exc
    joints = [t["joint"] for t in info["targets"]]
    if target is not None and target not in joints:
        raise click.UsageError(f"cabinet {cabinet_id} has no target {target!r}; targets: {joints}")
    return EpisodeSpec(cabinets / cabinet_id, target or joints[0], hand, seed=seed, room=room)
