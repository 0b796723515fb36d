"""`opend render` and `opend gallery`: PNG pictures of task scenes."""

from __future__ import annotations

from pathlib import Path

import click

from opend_mj.commands.options import (
    cabinets_option,
    check_hand,
    episode_from_options,
    scene_options,
)


@click.command("render")
@cabinets_option
@click.option("--cabinet", "cabinet_id", required=True, help="Cabinet id (a folder under --cabinets).")
@scene_options
@click.option("--light-scale", type=click.FloatRange(min=0.0), default=1.0, show_default=True)
@click.option("--size", type=click.IntRange(64, 480), default=384, show_default=True)
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), default=Path("scene.png"), show_default=True)
def render(cabinets, cabinet_id, target, hand, room, seed, light_scale, size, out):
    """Render one episode's scene: the front camera (handle boxes drawn) beside an overview."""
    from opend_mj.apps.render import render_episode_views, save_png
    from opend_mj.sim.task import TaskConfig

    episode = episode_from_options(cabinets, cabinet_id, target, hand, seed, room)
    image = render_episode_views(episode, size=size, config=TaskConfig(light_scale=light_scale))
    click.echo(str(save_png(image, out)))


@click.command("gallery")
@cabinets_option
@click.option("--count", type=click.IntRange(1, 12), default=3, show_default=True, help="Cabinets (rows).")
@click.option("--rooms", default="0,3,6", show_default=True, help="Comma-separated room presets (columns).")
@click.option("--hand", default="allegro", show_default=True, callback=check_hand)
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), default=Path("gallery.png"), show_default=True)
def gallery(cabinets, count, rooms, hand, seed, out):
    """A grid of cabinets (rows) x rooms (columns) into one PNG."""
    from opend_mj.apps.render import render_gallery, save_png
    from opend_mj.assets.layout import load_manifest

    try:
        manifest = load_manifest(cabinets)
    except FileNotFoundError as exc:
        raise click.UsageError(str(exc)) from exc
    try:
        room_list = [int(r) for r in rooms.split(",") if r.strip()]
    except ValueError as exc:
        raise click.BadParameter(f"--rooms must be integers 0-8, got {rooms!r}") from exc
    if not room_list or any(not 0 <= r <= 8 for r in room_list):
        raise click.BadParameter(f"--rooms must be integers 0-8, got {rooms!r}")
    ids = [c["id"] for c in manifest.cabinets][::max(1, len(manifest.cabinets) // count)][:count]
    image = render_gallery(cabinets, ids, room_list, hand=hand, seed=seed)
    click.echo(str(save_png(image, out)))
