"""Nine procedural rooms (the arena of the OpenD task), built from MuJoCo primitives.

``RoomArena(room, seed, light_scale)`` is a dm_control ``composer.Arena``. The room type (0..8, see
``ROOM_NAMES``) fixes which furniture the room holds; the seed fixes everything that varies per
episode: room size, wall distance behind the cabinet, floor material and texture (wood planks,
tiles, checker, gradient, flat/concrete, carpet), wall type and colour (paint, stripes, brick,
tiles, wainscot), light count, intensity and direction, furniture colours and positions.
``light_scale`` multiplies every light (lights, headlight, emissive materials): 0.7 reproduces the
paper's low-light ablation.

Layout and keep-out zones (world frame, z up, the cabinet faces -x):

* the cabinet zone ``|x| < zone_x``, ``|y| < zone_y``, ``0 <= z < zone_z`` (default 0.5, 0.8, 2.0 m)
  around the origin, where the cabinet stands on the floor (attach it at ``arena.cabinet_site``);
* the line-of-sight strip in front of it, ``los_x_min <= x < zone_x``, ``|y| < zone_y + los_margin``,
  ``z < los_z`` (default from x = -3.6 m, 0.1 m margin, 2.5 m high), which holds the camera, the
  hand and the view between them.

No geom of the arena other than the floor enters either box (``arena.keepout_boxes``; tested).
The back wall stands 0.25-0.6 m behind the cabinet zone.

Collisions: only the floor (a plane, group 0) collides. Walls, ceiling and furniture are visual
only (``contype = conaffinity = 0``, geom group 1), so they cost nothing in the contact pipeline and
can never push the cabinet or the hand.

Physics options for the whole scene are `opend_mj.sim.physics.PhysicsOptions` (noslip off; the
dm_control base arena turns on 5 noslip iterations; pass ``noslip_iterations`` to change it); the
task then sets its own timestep. The off-screen buffer is 640x480 (videos) unless asked otherwise.

Modules: `catalogue` (room names and contents), `furniture` (furniture as primitive parts),
`textures` (procedural textures and colours) and `arena` (`RoomArena`, `KeepOut`).
"""

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # before dm_control picks a GL backend

from opend_mj.sim.rooms.arena import KeepOut, RoomArena  # noqa: E402
from opend_mj.sim.rooms.catalogue import ROOM_NAMES  # noqa: E402

__all__ = ["ROOM_NAMES", "RoomArena", "KeepOut"]
