"""`opend hands` (the registered hands) and `opend render-hand` (a hand off-screen to a PNG)."""

from __future__ import annotations

import os

import click


@click.command("hands")
@click.option("--names", is_flag=True, help="Only the names, one a line (what the Makefile reads).")
def hands(names: bool) -> None:
    """List the hands in their order: name, title, finger DoF and folder. The hands are the folders of
    the shipped hands/ (or of $OPEND_HANDS_DIR); each one's title and order are in its spec.json."""
    from opend_mj.sim.hands import get_hand, list_hands

    for name in list_hands():
        if names:
            click.echo(name)
            continue
        hand = get_hand(name)
        click.echo(f"{name:12s} {hand.title:18s} {hand.spec.dof:3d} DoF  {hand.folder}")


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
    """Render hand NAME (one that `opend hands` lists) to a PNG."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    from opend_mj.sim.hands import scene as hand_scene

    path = hand_scene.render_hand(name, out, width=width, height=height, pose=pose)
    click.echo(str(path))
