"""Pictures of the task: one scene (front camera + overview), and a gallery grid of cabinets x rooms."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from PIL import Image, ImageDraw  # noqa: E402

from opend_mj.sim.camera import RGBDCamera  # noqa: E402
from opend_mj.sim.task import EpisodeSpec, TaskConfig, make_environment  # noqa: E402


def render_episode_views(episode: EpisodeSpec, size: int = 256, config: TaskConfig = TaskConfig(),
                         boxes: bool = True) -> np.ndarray:
    """Front camera (what solvers see, with ground-truth handle boxes drawn) beside the overview."""
    config = TaskConfig(**{**config.__dict__, "enable_rgbd": False})
    env = make_environment(episode, config)
    try:
        env.reset()
        physics = env.physics
        with RGBDCamera(physics, "front", size, size) as cam:
            front = cam.render_rgb()
        with RGBDCamera(physics, "overview", size, size) as cam:
            overview = cam.render_rgb()
        image = Image.fromarray(front)
        if boxes:
            draw = ImageDraw.Draw(image)
            scale = size / config.image_size
            for joint, box in env.task.handle_boxes(physics).items():
                if box is None:
                    continue
                colour = (255, 40, 40) if joint == episode.target_joint else (255, 220, 0)
                draw.rectangle([c * scale for c in box], outline=colour, width=2)
        caption = Image.new("RGB", (2 * size, 22), (20, 20, 20))
        ImageDraw.Draw(caption).text(
            (6, 5), f"{env.task.cabinet.id} | {env.task.arena.room_name} | \"{env.task.instruction}\"",
            fill=(255, 255, 255))
        views = np.hstack([np.asarray(image), overview])
        return np.vstack([np.asarray(caption), views])
    finally:
        env.close()


def render_gallery(cabinets_dir: Path, cabinet_ids: list[str], rooms: list[int], hand: str = "allegro",
                   size: int = 192, seed: int = 0) -> np.ndarray:
    """A grid: one row per cabinet, one column per room, front-camera views with the target box."""
    from opend_mj.sim.cabinet import load_cabinet_info

    rows = []
    for k, cid in enumerate(cabinet_ids):
        info = load_cabinet_info(Path(cabinets_dir) / cid)
        tiles = []
        for j, room in enumerate(rooms):
            target = info["targets"][(k + j) % len(info["targets"])]["joint"]
            episode = EpisodeSpec(Path(cabinets_dir) / cid, target, hand, seed=seed + 97 * k + j, room=room)
            view = render_episode_views(episode, size=size)
            caption, front = view[:22, : 2 * size], view[22:, :size]
            tiles.append(np.vstack([caption[:, :size], front]))
        rows.append(np.hstack(tiles))
    return np.vstack(rows)


def save_png(image: np.ndarray, out: Path) -> Path:
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(image).save(out)
    return out
