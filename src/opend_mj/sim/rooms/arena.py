"""The room arena (a dm_control ``composer.Arena``) and the keep-out boxes its decoration avoids."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from dm_control import composer

from opend_mj.sim.physics import PhysicsOptions
from opend_mj.sim.rooms.catalogue import ROOM_NAMES, ROOM_SPECS
from opend_mj.sim.rooms.furniture import FLOOR_ITEMS, WALL_ITEMS
from opend_mj.sim.rooms.textures import WOOD_TONES, hsv, png_asset, tex_brick, tex_stripes, tex_wood
from opend_mj.transforms import look_rotation, yaw_quat


@dataclass(frozen=True)
class KeepOut:
    """Boxes no decoration may enter: the cabinet zone and the camera's line-of-sight strip."""

    zone_x: float = 0.5
    zone_y: float = 0.8
    zone_z: float = 2.0
    los_x_min: float = -3.6
    los_margin: float = 0.1
    los_z: float = 2.5

    def boxes(self) -> list[tuple[np.ndarray, np.ndarray]]:
        zone = (np.array([-self.zone_x, -self.zone_y, 0.0]), np.array([self.zone_x, self.zone_y, self.zone_z]))
        w = self.zone_y + self.los_margin
        los = (np.array([self.los_x_min, -w, 0.0]), np.array([self.zone_x, w, self.los_z]))
        return [zone, los]


def _overlap(a_lo, a_hi, b_lo, b_hi, pad=0.0) -> bool:
    return bool(np.all(a_lo < b_hi + pad) and np.all(b_lo < a_hi + pad))


class RoomArena(composer.Arena):
    """One of nine rooms, randomised by ``seed``.

    Args:
      room: 0..8, index into ``ROOM_NAMES``.
      seed: per-episode randomisation (``np.random.default_rng(seed)``); same seed -> same room.
      light_scale: multiplies every light intensity (0.7 = the paper's 30 % darker ablation).
      keepout: the :class:`KeepOut` boxes (cabinet zone and camera strip) decoration must avoid.
      fast_render: shadows and multisampling off (about 20x faster on a CPU renderer).
      offscreen: (width, height) of the off-screen buffer; 640x480 suffices for 256x256 and video.
      noslip_iterations: 0 by default (the base dm_control arena uses 5).
    """

    def _build(
        self,
        room: int = 0,
        seed: int = 0,
        light_scale: float = 1.0,
        keepout: KeepOut | None = None,
        fast_render: bool = True,
        offscreen: tuple[int, int] = (640, 480),
        noslip_iterations: int = 0,
        name: str | None = None,
    ):
        if not 0 <= int(room) < len(ROOM_NAMES):
            raise ValueError(f"room must be in 0..{len(ROOM_NAMES) - 1}, got {room}")
        super()._build(name=name or f"room{int(room)}_{ROOM_NAMES[int(room)].replace(' ', '_')}")
        self.room = int(room)
        self.room_name = ROOM_NAMES[self.room]
        self.seed = int(seed)
        self.light_scale = float(light_scale)
        self.keepout = keepout or KeepOut()
        self._rng = np.random.default_rng([self.seed, self.room])
        self._decorations: list = []
        self._placed: list[tuple[np.ndarray, np.ndarray]] = []

        root = self._mjcf_root
        PhysicsOptions(noslip_iterations=int(noslip_iterations)).apply(root)
        g = root.visual.get_children("global")
        g.offwidth, g.offheight = int(offscreen[0]), int(offscreen[1])
        q = root.visual.quality
        if fast_render:
            q.shadowsize = 0
            q.offsamples = 0
        root.visual.map.znear = 0.01
        root.visual.map.zfar = 50

        self._make_materials()
        self._make_shell()
        self._make_lights()
        self._place_furniture()
        self._cabinet_site = root.worldbody.add("site", name="cabinet_site", pos=[0, 0, 0], size=[0.01], rgba=[0, 0, 0, 0], group=5)
        # A wide view for debugging and figures (not the benchmark camera).
        ov = np.array([-self.keepout.zone_x - 2.6, -self.half_width + 0.3, self.ceiling - 0.25])
        tgt = np.array([self.back_x - 0.3, 0.5, 0.6])
        look = look_rotation(tgt - ov)
        root.worldbody.add("camera", name="overview", pos=ov, xyaxes=np.concatenate([look[:, 0], look[:, 1]]), fovy=70)

    # ------------------------------------------------------------------ materials
    def _mat(self, name, rgba=None, texture=None, texrepeat=None, emission=None, specular=0.2, shininess=0.2, texuniform=True):
        kw = dict(name=name, specular=specular, shininess=shininess)
        if rgba is not None:
            kw["rgba"] = [float(x) for x in rgba]
        if texture is not None:
            kw["texture"] = texture
            kw["texuniform"] = "true" if texuniform else "false"
            kw["texrepeat"] = [float(x) for x in (texrepeat or (1, 1))]
        if emission is not None:
            kw["emission"] = float(emission) * self.light_scale
        return self._mjcf_root.asset.add("material", **kw)

    def _make_materials(self):
        rng = self._rng
        spec = ROOM_SPECS[self.room]
        A = self._mjcf_root.asset
        # ---- floor
        kind = str(rng.choice(spec["floors"]))
        self.floor_kind = kind
        if kind == "wood":
            base = np.array(WOOD_TONES[int(rng.integers(len(WOOD_TONES)))]) * rng.uniform(0.85, 1.1)
            tex = A.add("texture", name="floor_tex", type="2d", file=png_asset(tex_wood(rng, base)))
            rep = 1.0 / rng.uniform(1.0, 1.6)
        elif kind == "tiles":
            c = hsv(rng.uniform(), rng.uniform(0.0, 0.3), rng.uniform(0.55, 0.95))
            c2 = c * rng.uniform(0.85, 1.0) if rng.random() < 0.6 else hsv(rng.uniform(), rng.uniform(0, 0.3), rng.uniform(0.2, 0.5))
            tex = A.add("texture", name="floor_tex", type="2d", builtin="checker", rgb1=c, rgb2=c2, mark="edge",
                        markrgb=c * 0.55, width=256, height=256)
            rep = 1.0 / (2 * rng.uniform(0.25, 0.6))
        elif kind == "checker":
            c1 = hsv(rng.uniform(), rng.uniform(0, 0.6), rng.uniform(0.5, 0.9))
            c2 = hsv(rng.uniform(), rng.uniform(0, 0.6), rng.uniform(0.1, 0.5))
            tex = A.add("texture", name="floor_tex", type="2d", builtin="checker", rgb1=c1, rgb2=c2, width=128, height=128)
            rep = 1.0 / (2 * rng.uniform(0.2, 0.5))
        elif kind == "gradient":
            c1 = hsv(rng.uniform(), rng.uniform(0.1, 0.6), rng.uniform(0.5, 0.9))
            c2 = hsv(rng.uniform(), rng.uniform(0.1, 0.6), rng.uniform(0.2, 0.5))
            tex = A.add("texture", name="floor_tex", type="2d", builtin="gradient", rgb1=c1, rgb2=c2, width=128, height=128)
            rep = 1.0 / rng.uniform(0.5, 2.0)
        elif kind == "carpet":
            c = hsv(rng.uniform(), rng.uniform(0.2, 0.6), rng.uniform(0.3, 0.7))
            tex = A.add("texture", name="floor_tex", type="2d", builtin="flat", rgb1=c, rgb2=c, mark="random",
                        markrgb=c * 0.8, random=0.3, width=128, height=128)
            rep = 2.0
        else:  # flat: concrete / linoleum
            c = hsv(rng.uniform(), rng.uniform(0, 0.15), rng.uniform(0.45, 0.8))
            tex = A.add("texture", name="floor_tex", type="2d", builtin="flat", rgb1=c, rgb2=c, mark="random",
                        markrgb=c * 0.9, random=0.05, width=128, height=128)
            rep = 1.0
        self._mat("floor", texture=tex, texrepeat=(rep, rep), specular=float(rng.uniform(0.05, 0.4)))
        # ---- walls
        wk = str(rng.choice(spec["walls"]))
        self.wall_kind = wk
        paint = hsv(rng.uniform(), rng.uniform(0.0, 0.45), rng.uniform(0.6, 0.95))
        if wk == "paint":
            self._mat("wall", rgba=(*paint, 1), specular=0.05)
        elif wk == "stripes":
            c2 = paint * rng.uniform(0.75, 0.92)
            tex = A.add("texture", name="wall_tex", type="2d", file=png_asset(tex_stripes(rng, paint, c2)))
            self._mat("wall", texture=tex, texrepeat=(1 / rng.uniform(0.4, 1.0), 1 / rng.uniform(0.4, 1.0)), specular=0.05)
        elif wk == "brick":
            brick = hsv(rng.uniform(0.0, 0.08), rng.uniform(0.4, 0.7), rng.uniform(0.45, 0.75))
            if rng.random() < 0.3:  # painted brick
                brick = paint
            tex = A.add("texture", name="wall_tex", type="2d", file=png_asset(tex_brick(rng, brick, brick * 0.6 + 0.35)))
            self._mat("wall", texture=tex, texrepeat=(1 / 0.8, 1 / 0.8), specular=0.05)
        elif wk == "tiles":
            tex = A.add("texture", name="wall_tex", type="2d", builtin="checker", rgb1=paint, rgb2=paint * 0.97, mark="edge",
                        markrgb=paint * 0.7, width=128, height=128)
            self._mat("wall", texture=tex, texrepeat=(1 / (2 * 0.15), 1 / (2 * 0.15)), specular=0.3)
        else:  # wainscot: paint above, wood panel below (panel added as geoms in _make_shell)
            self._mat("wall", rgba=(*paint, 1), specular=0.05)
        # ---- furniture palette
        wood = np.array(WOOD_TONES[int(rng.integers(len(WOOD_TONES)))])
        self._mat("wood", rgba=(*wood, 1), specular=0.2)
        self._mat("wood_dark", rgba=(*(wood * 0.6), 1), specular=0.2)
        fab = hsv(rng.uniform(), rng.uniform(0.2, 0.7), rng.uniform(0.3, 0.8))
        self._mat("fabric", rgba=(*fab, 1), specular=0.02)
        self._mat("fabric2", rgba=(*hsv(rng.uniform(), rng.uniform(0.2, 0.7), rng.uniform(0.3, 0.8)), 1), specular=0.02)
        self._mat("accent", rgba=(*hsv(rng.uniform(), rng.uniform(0.5, 0.9), rng.uniform(0.5, 0.9)), 1), specular=0.5, shininess=0.6)
        self._mat("metal", rgba=(0.6, 0.6, 0.62, 1), specular=0.8, shininess=0.8)
        self._mat("white", rgba=(0.92, 0.92, 0.9, 1), specular=0.3)
        self._mat("black", rgba=(0.08, 0.08, 0.09, 1), specular=0.5)
        self._mat("screen", rgba=(0.05, 0.08, 0.12, 1), specular=0.9, shininess=0.9)
        self._mat("stone", rgba=(*hsv(rng.uniform(), rng.uniform(0, 0.2), rng.uniform(0.2, 0.9)), 1), specular=0.6)
        self._mat("cabinet_front", rgba=(*hsv(rng.uniform(), rng.uniform(0, 0.4), rng.uniform(0.4, 0.95)), 1), specular=0.3)
        self._mat("terracotta", rgba=(0.72, 0.38, 0.24, 1), specular=0.1)
        self._mat("soil", rgba=(0.2, 0.13, 0.08, 1), specular=0.0)
        self._mat("leaf", rgba=(*hsv(rng.uniform(0.25, 0.4), rng.uniform(0.5, 0.8), rng.uniform(0.3, 0.6)), 1), specular=0.2)
        self._mat("cardboard", rgba=(0.66, 0.5, 0.32, 1), specular=0.05)
        self._mat("lampshade", rgba=(1.0, 0.95, 0.82, 1), emission=0.6, specular=0.0)
        self._mat("window", rgba=(0.75, 0.88, 1.0, 1), emission=0.8, specular=0.0)
        rug = hsv(rng.uniform(), rng.uniform(0.3, 0.8), rng.uniform(0.25, 0.6))
        self._mat("rug", rgba=(*rug, 1), specular=0.0)
        self._mat("rug2", rgba=(*hsv(rng.uniform(), rng.uniform(0.2, 0.6), rng.uniform(0.4, 0.8)), 1), specular=0.0)
        for i in range(4):
            self._mat(f"book{i}", rgba=(*hsv(rng.uniform(), rng.uniform(0.3, 0.8), rng.uniform(0.25, 0.75)), 1), specular=0.1)
        for i in range(2):
            self._mat(f"art{i}", rgba=(*hsv(rng.uniform(), rng.uniform(0.3, 0.9), rng.uniform(0.3, 0.9)), 1), specular=0.1)

    # ------------------------------------------------------------------ floor, walls, ceiling
    def _deco_geom(self, parent, **kw):
        kw.setdefault("contype", 0)
        kw.setdefault("conaffinity", 0)
        kw.setdefault("group", 1)
        g = parent.add("geom", **kw)
        self._decorations.append(g)
        return g

    def _make_shell(self):
        rng = self._rng
        k = self.keepout
        self.back_x = k.zone_x + float(rng.uniform(0.25, 0.6))
        self.front_x = k.los_x_min - float(rng.uniform(0.4, 1.0))
        self.half_width = float(rng.uniform(*ROOM_SPECS[self.room].get("width", (1.7, 2.6))))
        self.ceiling = float(max(k.los_z, k.zone_z) + rng.uniform(0.15, 0.5))
        wb = self._mjcf_root.worldbody
        cx = 0.5 * (self.back_x + self.front_x)
        hx = 0.5 * (self.back_x - self.front_x)
        W, H, t = self.half_width, self.ceiling, 0.1
        self.floor = wb.add("geom", name="floor", type="plane", pos=[cx, 0, 0], size=[hx, W, 0.1], material="floor",
                            friction=[1.0, 0.005, 0.0001], group=0)
        # Walls are finite visual planes facing into the room: a plane maps a 2D texture onto its own
        # x-y axes (boxes would smear it along one axis), and texrepeat then counts repeats per metre.
        walls = (
            ("wall_back", [self.back_x, 0, H / 2], [0, -1, 0, 0, 0, 1], W),
            ("wall_front", [self.front_x, 0, H / 2], [0, 1, 0, 0, 0, 1], W),
            ("wall_left", [cx, W, H / 2], [1, 0, 0, 0, 0, 1], hx),
            ("wall_right", [cx, -W, H / 2], [-1, 0, 0, 0, 0, 1], hx),
        )
        for nm, pos, xy, half in walls:
            self._deco_geom(wb, name=nm, type="plane", pos=pos, xyaxes=xy, size=[half, H / 2, 0.1], material="wall")
        self._deco_geom(wb, name="ceiling", type="box", pos=[cx, 0, H + t], size=[hx + 2 * t, W + 2 * t, t], rgba=[0.95, 0.95, 0.93, 1])
        # skirting boards (and a wood panel for wainscot walls)
        skirt_h = 0.45 if self.wall_kind == "wainscot" else 0.04
        mat = "wood" if self.wall_kind == "wainscot" else "white"
        self._deco_geom(wb, name="skirt_back", type="box", pos=[self.back_x - 0.008, 0, skirt_h], size=[0.008, W, skirt_h], material=mat)
        for s in (1, -1):
            self._deco_geom(wb, name=f"skirt_{'left' if s > 0 else 'right'}", type="box", pos=[cx, s * (W - 0.008), skirt_h],
                            size=[hx, 0.008, skirt_h], material=mat)

    # ------------------------------------------------------------------ lights
    def _make_lights(self):
        rng = self._rng
        s = self.light_scale
        wb = self._mjcf_root.worldbody
        amb = float(rng.uniform(0.15, 0.3))
        hl = self._mjcf_root.visual.headlight
        hl.ambient = [amb * s] * 3
        hl.diffuse = [float(rng.uniform(0.1, 0.25)) * s] * 3
        hl.specular = [0.05 * s] * 3
        n = int(rng.integers(1, 4))
        self.lights = []
        tint = 1.0 + np.array([0.06, 0.0, -0.08]) * rng.uniform(-1, 1)  # warm or cool light
        for i in range(n):
            pos = np.array([rng.uniform(-2.0, self.back_x - 0.3), rng.uniform(-self.half_width + 0.4, self.half_width - 0.4), self.ceiling - 0.05])
            target = np.array([rng.uniform(-0.6, 0.4), rng.uniform(-0.8, 0.8), 0.0])
            d = target - pos
            d /= np.linalg.norm(d)
            diff = float(rng.uniform(0.35, 0.75)) / np.sqrt(n) * s
            directional = bool(rng.random() < 0.3)
            self.lights.append(wb.add(
                "light", name=f"light{i}", pos=pos, dir=d, type="directional" if directional else "spot",
                diffuse=np.clip(diff * tint, 0, None), specular=[0.15 * s] * 3, ambient=[0.0, 0.0, 0.0],
                cutoff=float(rng.uniform(55, 85)), exponent=float(rng.uniform(1, 6)), castshadow="false"))
            # a ceiling fixture where the light hangs
            self._deco_geom(wb, name=f"ceiling_lamp{i}", type="cylinder", pos=[pos[0], pos[1], self.ceiling - 0.02], size=[0.18, 0.02], material="lampshade")

    # ------------------------------------------------------------------ furniture
    def _free(self, lo, hi) -> bool:
        for klo, khi in self.keepout.boxes():
            if _overlap(lo, hi, klo, khi, pad=0.02):
                return False
        for plo, phi in self._placed:
            if _overlap(lo, hi, plo, phi, pad=0.03):
                return False
        room_lo = np.array([self.front_x, -self.half_width, 0.0])
        room_hi = np.array([self.back_x, self.half_width, self.ceiling])
        return bool(np.all(lo >= room_lo - 1e-9) and np.all(hi <= room_hi + 1e-9))

    def _add_item(self, name, parts, pos, yaw):
        body = self._mjcf_root.worldbody.add("body", name=name, pos=[float(x) for x in pos], quat=[float(x) for x in yaw_quat(yaw)])
        for j, (typ, p, size, mat, euler) in enumerate(parts):
            kw = dict(name=f"{name}_{j}", type=typ, pos=[float(x) for x in p], size=[float(x) for x in size], material=mat)
            if euler is not None:
                kw["euler"] = [float(x) for x in euler]
            self._deco_geom(body, **kw)
        return body

    def _place_first_free(self, propose, tries: int):
        """Rejection sampling: the first proposal ``(pos, yaw, lo, hi)`` whose box is free, or None."""
        for _ in range(tries):
            pos, yaw, lo, hi = propose()
            if self._free(lo, hi):
                self._placed.append((lo, hi))
                return pos, yaw
        return None

    def _place_furniture(self):
        rng = self._rng
        spec = ROOM_SPECS[self.room]
        k = self.keepout
        W = self.half_width
        self.furniture: list[str] = []
        x_min = max(self.front_x + 0.05, -2.8)  # behind the camera nothing is seen
        for idx, (item, where) in enumerate(spec["floor"]):
            hx0, hy0, h, parts = FLOOR_ITEMS[item](rng)

            def propose_floor(where=where, hx0=hx0, hy0=hy0, h=h):
                side = 1 if rng.random() < 0.5 else -1
                if where == "back":  # against the back wall, facing -x
                    yaw, hx, hy = np.pi, hx0, hy0
                    x = self.back_x - hx - 0.01
                    y = rng.uniform(-W + hy, W - hy)
                elif where == "back_corner":
                    yaw, hx, hy = np.pi, hx0, hy0
                    x = self.back_x - hx - 0.01
                    y = side * (W - hy - 0.01)
                elif where == "side":  # against a side wall, facing the room
                    yaw, hx, hy = -side * np.pi / 2, hy0, hx0
                    y = side * (W - hy - 0.01)
                    x = rng.uniform(x_min + hx, self.back_x - hx)
                else:  # free standing
                    yaw = float(rng.integers(0, 4)) * np.pi / 2
                    hx, hy = (hx0, hy0) if int(round(yaw / (np.pi / 2))) % 2 == 0 else (hy0, hx0)
                    x = rng.uniform(x_min + hx, self.back_x - hx)
                    y = side * rng.uniform(k.zone_y + k.los_margin + hy, max(W - hy, k.zone_y + k.los_margin + hy + 1e-3))
                return (x, y, 0.0), yaw, np.array([x - hx, y - hy, 0.0]), np.array([x + hx, y + hy, h])

            placed = self._place_first_free(propose_floor, 60)
            if placed is not None:
                self._add_item(f"{item}{idx}", parts, *placed)
                self.furniture.append(item)
        for idx, (item, wall, zc) in enumerate(spec["wall"]):
            hd, hy0, hz, parts = WALL_ITEMS[item](rng)

            def propose_wall(wall=wall, zc=zc, hd=hd, hy0=hy0, hz=hz):
                z = zc + rng.uniform(-0.1, 0.1)
                z = min(max(z, hz + 0.01), self.ceiling - hz - 0.02)
                if wall == "back":
                    yaw = np.pi
                    x, y = self.back_x, rng.uniform(-W + hy0 + 0.05, W - hy0 - 0.05)
                    lo, hi = np.array([x - 2 * hd, y - hy0, z - hz]), np.array([x, y + hy0, z + hz])
                else:
                    side = 1 if rng.random() < 0.5 else -1
                    yaw = -side * np.pi / 2
                    x, y = rng.uniform(x_min + hy0, self.back_x - hy0 - 0.05), side * W
                    lo = np.array([x - hy0, y - 2 * hd if side > 0 else y, z - hz])
                    hi = np.array([x + hy0, y if side > 0 else y + 2 * hd, z + hz])
                return (x, y, z), yaw, lo, hi

            placed = self._place_first_free(propose_wall, 40)
            if placed is not None:
                self._add_item(f"{item}_w{idx}", parts, *placed)
                self.furniture.append(item)

    # ------------------------------------------------------------------ API
    @property
    def cabinet_site(self):
        """Site at the world origin on the floor: attach the cabinet here (``attach_cabinet``)."""
        return self._cabinet_site

    def attach_cabinet(self, cabinet_entity):
        """Attach a cabinet entity (fixed, no free joint) at the origin; returns the attachment frame.

        The carcass stands on the floor; its doors and drawers do not touch it (no floor contact for
        the cabinet's moving bodies, as real fronts hang a few millimetres clear of the floor; every
        other contact, the hand's with the floor included, is kept). See docs/cabinets.md.
        """
        from ..cabinet import moving_bodies

        frame = self.attach(cabinet_entity, self._cabinet_site)
        bodies = (cabinet_entity.moving_bodies() if hasattr(cabinet_entity, "moving_bodies")
                  else moving_bodies(cabinet_entity.mjcf_model))
        for body in bodies:
            self._mjcf_root.contact.add("exclude", body1="world", body2=body)
        return frame

    def add_camera(self, pose, name: str = "front"):
        from opend_mj.sim.camera import add_camera

        return add_camera(self._mjcf_root, pose, name=name)

    @property
    def decoration_geoms(self) -> list:
        """All visual-only geoms (walls, ceiling, furniture, lamps); the floor is not among them."""
        return list(self._decorations)

    @property
    def keepout_boxes(self) -> list[tuple[np.ndarray, np.ndarray]]:
        return self.keepout.boxes()
