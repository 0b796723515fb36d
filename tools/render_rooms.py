"""Save a 3x3 grid PNG of the nine rooms, each with a grey stand-in cabinet box at the origin.

usage: python tools/render_rooms.py OUT.png [--seed N] [--size 256] [--camera front|overview] [--light-scale 1.0]
"""

from __future__ import annotations

import argparse
import os

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402
from dm_control import mjcf  # noqa: E402
from PIL import Image  # noqa: E402

from opend_mj.sim.camera import RGBDCamera, place_camera  # noqa: E402
from opend_mj.sim.rooms import ROOM_NAMES, RoomArena  # noqa: E402


def render_room(room: int, seed: int, size: int, camera: str, light_scale: float, box=(0.5, 0.9, 1.2)) -> np.ndarray:
    arena = RoomArena(room, seed, light_scale=light_scale)
    hx, hy, h = box[0] / 2, box[1] / 2, box[2]
    arena.mjcf_model.worldbody.add("geom", name="standin", type="box", pos=[0, 0, h / 2], size=[hx, hy, h / 2], rgba=[0.55, 0.55, 0.55, 1])
    arena.add_camera(place_camera([-hx, -hy, 0], [hx, hy, h]), name="front")
    physics = mjcf.Physics.from_mjcf_model(arena.mjcf_model)
    physics.forward()
    with RGBDCamera(physics, camera, size, size) as cam:
        return cam.render_rgb()


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("out")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--camera", default="front")
    ap.add_argument("--light-scale", type=float, default=1.0)
    a = ap.parse_args(argv)
    tiles = []
    for r in range(len(ROOM_NAMES)):
        tiles.append(render_room(r, a.seed + r, a.size, a.camera, a.light_scale))
    rows = [np.concatenate(tiles[i * 3 : i * 3 + 3], axis=1) for i in range(3)]
    grid = np.concatenate(rows, axis=0)
    Image.fromarray(grid).save(a.out)
    print(f"wrote {a.out} ({', '.join(ROOM_NAMES)})")


if __name__ == "__main__":
    main()
