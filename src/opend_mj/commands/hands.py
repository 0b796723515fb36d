"""`opend render-hand`: render a hand off-screen to a PNG."""

from __future__ import annotations

import os

import click


@click.command("render-hand")
@click.argument("name")
@click.option("--out", "out", default="hand.png", show_default=True, type=click.Path(),
              help="PNG file to write.")
@click.option("--pose", default="open", show_default=True,
              type=click.Choice(["open", "horizontal", "vertical"]),
              help="Finger pose: open, or the grasp profile for a horizontal/vertical handle.")
@click.option("--width", default=480, show_default=True, type=int)
@click.option("--height", default=360, show_default=True, type=int)
def render_hand(name: str, out: str, pose: str, width: int, height: int) -> None:
    """Render hand NAME (franka, allegro, shadow, skeleton or a registered one) to a PNG."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    from opend_mj.sim.hands import scene as hand_scene

    path = hand_scene.render_hand(name, out, width=width, height=height, pose=pose)
    click.echo(str(path))
