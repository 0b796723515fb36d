"""Perturbations of an episode: the shifts a deployment meets (camera, light, textures, distractors,
physics, depth sensor, instruction), each at a ``mild`` and a ``strong`` level (`opend run --perturb`).

`PerturbConfig` holds every number of both levels (one place, documented in docs/robustness.md). A
perturbation is written ``AXIS=LEVEL`` (several joined by commas, e.g. ``camera_pose=mild,light=strong``);
`parse_perturb` checks and canonicalises it. `SceneShift.draw` turns it into concrete values for one
scene from the scene's seed (`evaluation.episode.scene_seed`: the episode seed and the cabinet), so every
solver, agent, hand and target of a cabinet meets the same draw. The task applies it
(`sim.task.OpenCabinetTask`): the MJCF before compiling (camera, light, textures, distractors), the
compiled model (friction, damping, mass) and every depth image solvers and agents receive.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

AXES = ("camera_pose", "camera_fov", "light", "texture", "distractors", "physics", "depth_noise", "instruction")
LEVELS = ("mild", "strong")


class PerturbError(ValueError):
    """A perturbation that is unknown or makes a scene invalid (one line, naming it)."""


@dataclass(frozen=True)
class Level:
    """The numbers of one level of every axis."""

    #: camera_pose: the camera moves by up to this far (m; a uniform direction, uniform length) and
    #: turns by up to this angle (degrees, about a uniform axis)
    camera_shift_m: float
    camera_turn_deg: float
    #: camera_fov: vertical field of view x (1 + u), u uniform in +-this
    fov_fraction: float
    #: light: every light's and the headlight's intensity x a factor log-uniform in this range
    light_intensity: tuple[float, float]
    #: light: colour temperature (K) uniform in this range (6500 K is white)
    light_temperature_k: tuple[float, float]
    #: light: a tint of a uniform hue with up to this saturation (0: none; "coloured" light)
    light_tint: float
    #: light: each light's direction turns by up to this angle (degrees)
    light_turn_deg: float
    #: texture: unseen textures on the floor and walls; also on the cabinet (carcass and fronts,
    #: not the handles) where True
    texture_cabinet: bool
    #: distractors: everyday objects on the cabinet's top, and on the floor beside it (away from the
    #: hand's start, never in front of the cabinet)
    distractors_top: int
    distractors_beside: int
    #: physics: handle friction, hinge/slide friction loss, joint damping and the moving parts' mass
    #: (with their inertia), each x a factor log-uniform in this range
    physics_factor: tuple[float, float]
    #: depth_noise: axial noise sigma(z) = scale * (1.2 mm + 1.9 mm * (z - 0.4 m)^2) (a structured-light
    #: sensor's, Nguyen et al. 2012); missing pixels (depth 0) at depth edges, on dark surfaces and at random
    depth_sigma_scale: float
    depth_edge_dropout: float
    depth_dark_dropout: float
    depth_random_dropout: float
    #: instruction: "paraphrase" (one of the three fixed rewordings, drawn per scene) or "grammar"
    #: (a rewording drawn from the grammar of `language.rewordings`)
    instruction: str


@dataclass(frozen=True)
class PerturbConfig:
    """Both levels of every axis, and the checks that keep a perturbed scene valid."""

    mild: Level = Level(camera_shift_m=0.03, camera_turn_deg=3.0, fov_fraction=0.05,
                        light_intensity=(0.6, 1.4), light_temperature_k=(4500.0, 8000.0), light_tint=0.0,
                        light_turn_deg=10.0, texture_cabinet=False, distractors_top=2, distractors_beside=0,
                        physics_factor=(0.7, 1.5), depth_sigma_scale=1.0, depth_edge_dropout=0.3,
                        depth_dark_dropout=0.3, depth_random_dropout=0.005, instruction="paraphrase")
    strong: Level = Level(camera_shift_m=0.10, camera_turn_deg=10.0, fov_fraction=0.15,
                          light_intensity=(0.3, 2.0), light_temperature_k=(2700.0, 10000.0), light_tint=0.35,
                          light_turn_deg=30.0, texture_cabinet=True, distractors_top=4, distractors_beside=2,
                          physics_factor=(0.4, 3.0), depth_sigma_scale=3.0, depth_edge_dropout=0.8,
                          depth_dark_dropout=0.7, depth_random_dropout=0.02, instruction="grammar")
    #: the camera must stay this far (m) outside the cabinet's bounds
    camera_clearance_m: float = 0.05
    #: no distractor within this distance (m) of the hand's start or of its way to the cabinet's front
    hand_clearance_m: float = 0.12
    #: distractors on the floor beside the cabinet: this far (m) from its side, on the side away from the hand
    beside_gap_m: float = 0.08
    #: distractors on top stay this far (m) behind the cabinet's front edge
    top_setback_m: float = 0.06

    def level(self, name: str) -> Level:
        if name not in LEVELS:
            raise PerturbError(f"unknown perturbation level {name!r}; known: {', '.join(LEVELS)}")
        return getattr(self, name)


#: The levels every run uses (`TaskConfig.perturb_config`'s default; the pre-run scene check reads it).
DEFAULT_CONFIG = PerturbConfig()


def parse_perturb(items) -> str | None:
    """``AXIS=LEVEL`` strings (or one comma-joined string) -> the canonical spec (axes in `AXES`
    order, comma-joined), or None for none. Raises `PerturbError` naming an unknown axis or level."""
    if items is None:
        return None
    if isinstance(items, str):
        items = [items]
    chosen: dict[str, str] = {}
    for item in items:
        for part in str(item).split(","):
            part = part.strip()
            if not part:
                continue
            axis, sep, level = part.partition("=")
            axis, level = axis.strip(), level.strip()
            if not sep:
                raise PerturbError(f"perturbation {part!r}: write AXIS=LEVEL, e.g. camera_pose=mild")
            if axis not in AXES:
                raise PerturbError(f"perturbation {part!r}: unknown axis {axis!r}; known: {', '.join(AXES)}")
            if level not in LEVELS:
                raise PerturbError(f"perturbation {part!r}: unknown level {level!r}; known: {', '.join(LEVELS)}")
            if chosen.get(axis, level) != level:
                raise PerturbError(f"perturbation {axis!r} given twice ({chosen[axis]} and {level})")
            chosen[axis] = level
    if not chosen:
        return None
    return ",".join(f"{a}={chosen[a]}" for a in AXES if a in chosen)


def perturb_items(spec: str | None) -> dict[str, str]:
    """axis -> level of a canonical spec (empty for None)."""
    if not spec:
        return {}
    return dict(part.split("=", 1) for part in spec.split(","))


def _log_uniform(rng, lo_hi) -> float:
    lo, hi = lo_hi
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _unit(rng) -> np.ndarray:
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def _axis_angle(axis, angle_rad) -> np.ndarray:
    """Rotation matrix of ``angle_rad`` about the unit ``axis``."""
    x, y, z = axis
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    C = 1 - c
    return np.array([[c + x * x * C, x * y * C - z * s, x * z * C + y * s],
                     [y * x * C + z * s, c + y * y * C, y * z * C - x * s],
                     [z * x * C - y * s, z * y * C + x * s, c + z * z * C]])


def temperature_rgb(kelvin: float) -> np.ndarray:
    """RGB (max 1) of black-body light at ``kelvin`` (Tanner Helland's fit), relative to 6500 K."""

    def raw(k):
        t = k / 100.0
        r = 255.0 if t <= 66 else 329.698727446 * (t - 60) ** -0.1332047592
        g = 99.4708025861 * math.log(t) - 161.1195681661 if t <= 66 else 288.1221695283 * (t - 60) ** -0.0755148492
        b = 255.0 if t >= 66 else (0.0 if t <= 19 else 138.5177312231 * math.log(t - 10) - 305.0447927307)
        return np.clip(np.array([r, g, b]), 1.0, 255.0)

    rgb = raw(kelvin) / raw(6500.0)
    return rgb / rgb.max()


@dataclass(frozen=True)
class Distractor:
    """One everyday object: a name, its parts (type, centre offset, size, rgba) and where it stands."""

    name: str
    pos: tuple[float, float, float]  # centre of its base, world (m)
    half: tuple[float, float, float]  # half extents of its bounding box (m)
    parts: tuple = ()

    def box(self) -> tuple[np.ndarray, np.ndarray]:
        p, h = np.asarray(self.pos, float), np.asarray(self.half, float)
        return p - np.array([h[0], h[1], 0.0]), p + np.array([h[0], h[1], 2 * h[2]])


def _object(rng, name: str, small: bool) -> tuple[tuple[float, float, float], tuple]:
    """(half extents, parts) of an everyday object; parts' offsets are from the base centre."""
    colour = tuple(float(c) for c in np.clip(rng.uniform(0.1, 0.95, 3), 0, 1)) + (1.0,)
    if small:
        kind = ["mug", "book", "bottle", "box", "vase"][int(rng.integers(5))]
    else:
        kind = ["bin", "carton", "plant"][int(rng.integers(3))]
    if kind == "mug":
        r, h = rng.uniform(0.035, 0.05), rng.uniform(0.045, 0.06)
        parts = (("cylinder", (0, 0, h), (r, h), colour), ("box", (0, r + 0.012, h), (0.006, 0.012, h * 0.6), colour))
        half = (r, r + 0.024, h)
    elif kind == "book":
        hx, hy, hz = rng.uniform(0.07, 0.11), rng.uniform(0.1, 0.14), rng.uniform(0.01, 0.025)
        parts = (("box", (0, 0, hz), (hx, hy, hz), colour),)
        half = (hx, hy, hz)
    elif kind == "bottle":
        r, h = rng.uniform(0.03, 0.045), rng.uniform(0.08, 0.13)
        parts = (("cylinder", (0, 0, h), (r, h), colour),
                 ("cylinder", (0, 0, 2 * h + 0.03), (r * 0.4, 0.03), colour))
        half = (r, r, h + 0.03)
    elif kind == "box":
        hx, hy, hz = rng.uniform(0.04, 0.1), rng.uniform(0.04, 0.1), rng.uniform(0.03, 0.08)
        parts = (("box", (0, 0, hz), (hx, hy, hz), (0.66, 0.5, 0.32, 1.0)),)
        half = (hx, hy, hz)
    elif kind == "vase":
        r, h = rng.uniform(0.04, 0.07), rng.uniform(0.08, 0.15)
        parts = (("cylinder", (0, 0, h), (r, h), colour), ("sphere", (0, 0, 2 * h), (r * 0.8,), (0.2, 0.6, 0.2, 1.0)))
        half = (r, r, h + 0.4 * r)
    elif kind == "bin":
        r, h = rng.uniform(0.12, 0.17), rng.uniform(0.2, 0.32)
        parts = (("cylinder", (0, 0, h), (r, h), colour),)
        half = (r, r, h)
    elif kind == "carton":
        hx, hy, hz = rng.uniform(0.12, 0.2), rng.uniform(0.1, 0.17), rng.uniform(0.1, 0.2)
        parts = (("box", (0, 0, hz), (hx, hy, hz), (0.66, 0.5, 0.32, 1.0)),)
        half = (hx, hy, hz)
    else:  # plant
        r, h = rng.uniform(0.1, 0.14), rng.uniform(0.12, 0.2)
        parts = (("cylinder", (0, 0, h), (r, h), (0.72, 0.38, 0.24, 1.0)),
                 ("sphere", (0, 0, 2 * h + r), (r * 1.3,), (0.2, 0.5, 0.2, 1.0)))
        half = (r * 1.3, r * 1.3, h + 1.15 * r)
    return tuple(float(x) for x in half), parts


@dataclass(frozen=True)
class SceneShift:
    """The concrete values of a perturbation for one scene (all None/neutral for axes not perturbed)."""

    spec: str | None = None
    config: PerturbConfig = PerturbConfig()
    camera_offset: tuple[float, float, float] | None = None
    camera_turn: tuple[tuple[float, ...], ...] | None = None  # 3x3 rotation, world frame
    fov_factor: float = 1.0
    light_factor: float = 1.0
    light_colour: tuple[float, float, float] = (1.0, 1.0, 1.0)
    light_turns: tuple = ()  # per light: 3x3 rotations
    texture_seed: int | None = None
    texture_cabinet: bool = False
    distractors: tuple[Distractor, ...] = ()
    physics: dict = field(default_factory=dict)  # handle_friction, joint_frictionloss, joint_damping, mass
    depth: Level | None = None
    depth_seed: int = 0
    instruction: tuple[str, int] | None = None  # ("paraphrase" | "grammar", draw)

    @classmethod
    def draw(cls, spec: str | None, seed: int, bounds, config: PerturbConfig = PerturbConfig()) -> "SceneShift":
        """The draw of ``spec`` for the scene of ``seed`` (its scene seed) and a cabinet's ``bounds``
        ((min, max), world, m). Each axis has its own random stream, so adding an axis never changes
        another's draw."""
        items = perturb_items(spec)
        if not items:
            return cls()
        lo, hi = (np.asarray(b, float) for b in bounds)
        values: dict = {"spec": spec, "config": config}

        def rng(axis):
            return np.random.default_rng([int(seed), 48, AXES.index(axis)])

        for axis, level_name in items.items():
            level, r = config.level(level_name), rng(axis)
            if axis == "camera_pose":
                offset = _unit(r) * level.camera_shift_m * r.uniform()
                turn = _axis_angle(_unit(r), math.radians(level.camera_turn_deg * r.uniform()))
                values["camera_offset"] = tuple(float(x) for x in offset)
                values["camera_turn"] = tuple(tuple(float(x) for x in row) for row in turn)
            elif axis == "camera_fov":
                values["fov_factor"] = float(1.0 + r.uniform(-1, 1) * level.fov_fraction)
            elif axis == "light":
                values["light_factor"] = _log_uniform(r, level.light_intensity)
                colour = temperature_rgb(r.uniform(*level.light_temperature_k))
                if level.light_tint > 0:
                    import colorsys

                    tint = np.array(colorsys.hsv_to_rgb(r.uniform(), r.uniform(0, level.light_tint), 1.0))
                    colour = colour * tint
                values["light_colour"] = tuple(float(c) for c in colour / colour.max())
                values["light_turns"] = tuple(
                    tuple(tuple(float(x) for x in row)
                          for row in _axis_angle(_unit(r), math.radians(level.light_turn_deg * r.uniform())))
                    for _ in range(8))
            elif axis == "texture":
                values["texture_seed"] = int(r.integers(2**31))
                values["texture_cabinet"] = bool(level.texture_cabinet)
            elif axis == "distractors":
                values["distractors"] = tuple(_place_distractors(r, level, lo, hi, config))
            elif axis == "physics":
                values["physics"] = {k: _log_uniform(r, level.physics_factor)
                                     for k in ("handle_friction", "joint_frictionloss", "joint_damping", "mass")}
            elif axis == "depth_noise":
                values["depth"] = level
                values["depth_seed"] = int(r.integers(2**31))
            elif axis == "instruction":
                values["instruction"] = (level.instruction, int(r.integers(2**31)))
        return cls(**values)

    # ------------------------------------------------------------------ camera
    def move_camera(self, pose):
        """The camera pose moved and turned, its field of view scaled (`sim.camera.CameraPose`)."""
        from opend_mj.sim.camera import CameraPose

        if self.camera_offset is None and self.fov_factor == 1.0:
            return pose
        pos, rot = np.asarray(pose.pos, float), np.asarray(pose.rot, float)
        if self.camera_offset is not None:
            pos = pos + np.asarray(self.camera_offset)
            rot = np.asarray(self.camera_turn) @ rot
        return CameraPose(pos=pos, rot=rot, fovy=float(pose.fovy) * self.fov_factor)

    # ------------------------------------------------------------------ checks
    def check(self, bounds, camera_pos, hand_start, label: str = "") -> None:
        """Raise `PerturbError` where the scene is invalid: the camera inside (or within
        ``camera_clearance_m`` of) the cabinet, a distractor at the hand's start, on its way to the
        cabinet's front, or in front of the cabinet. ``label`` names the scene in the message."""
        lo, hi = (np.asarray(b, float) for b in bounds)
        c = self.config
        where = f"{label}: " if label else ""
        cam = np.asarray(camera_pos, float)
        if np.all(cam > lo - c.camera_clearance_m) and np.all(cam < hi + c.camera_clearance_m):
            raise PerturbError(f"{where}perturbation {self.spec} puts the camera inside the cabinet "
                               f"(camera at {np.round(cam, 3).tolist()}, cabinet {np.round(lo, 3).tolist()}"
                               f"-{np.round(hi, 3).tolist()})")
        start = np.asarray(hand_start, float)
        pad = c.hand_clearance_m
        # the hand's way: from its start to anywhere on the cabinet's front, and the space in front
        path_lo = np.minimum(start - pad, np.array([lo[0] - 0.6, lo[1] - pad, lo[2] - pad]))
        path_hi = np.maximum(start + pad, np.array([lo[0] + 0.01, hi[1] + pad, hi[2]]))
        for d in self.distractors:
            dlo, dhi = d.box()
            if np.all(dlo < path_hi) and np.all(path_lo < dhi):
                raise PerturbError(f"{where}perturbation {self.spec} puts a distractor ({d.name} at "
                                   f"{np.round(d.pos, 3).tolist()}) in the hand's path or in front of the cabinet")

    # ------------------------------------------------------------------ MJCF
    def apply_mjcf(self, arena, cabinet, handle_geoms) -> None:
        """Light, textures and distractors into the scene's MJCF (before it compiles)."""
        if self.spec is None:
            return
        root = arena.mjcf_model
        if self.light_factor != 1.0 or self.light_colour != (1.0, 1.0, 1.0) or self.light_turns:
            colour = np.asarray(self.light_colour) * self.light_factor
            hl = root.visual.headlight
            for attr in ("ambient", "diffuse", "specular"):
                value = getattr(hl, attr)
                if value is not None:
                    setattr(hl, attr, (np.asarray(value, float) * colour).tolist())
            for i, light in enumerate(arena.lights):
                light.diffuse = (np.asarray(light.diffuse, float) * colour).tolist()
                light.specular = (np.asarray(light.specular, float) * colour).tolist()
                if self.light_turns:
                    d = np.asarray(self.light_turns[i % len(self.light_turns)]) @ np.asarray(light.dir, float)
                    light.dir = d.tolist()
        if self.texture_seed is not None:
            _retexture(root, cabinet, handle_geoms, np.random.default_rng(self.texture_seed), self.texture_cabinet)
        for i, d in enumerate(self.distractors):
            body = root.worldbody.add("body", name=f"distractor{i}_{d.name}", pos=list(d.pos))
            for j, (typ, off, size, rgba) in enumerate(d.parts):
                body.add("geom", name=f"distractor{i}_{j}", type=typ, pos=list(off), size=list(size), rgba=list(rgba),
                         contype=1, conaffinity=1, group=1, friction=[0.8, 0.005, 0.0001])

    # ------------------------------------------------------------------ compiled model
    def apply_model(self, physics, cabinet, handle_geoms) -> None:
        """Friction, damping and mass of the cabinet's moving parts in the compiled model, as
        factors on its nominal values (kept on first use, so applying twice changes nothing)."""
        if not self.physics:
            return
        import mujoco

        model = physics.model.ptr
        joints = [cabinet.joint_element(j) for j in cabinet._joints]
        dofs = np.array([int(physics.bind(j).dofadr) for j in joints])
        geoms = np.array([physics.model.name2id(f"cabinet/{g}", "geom") for g in handle_geoms], int)
        bodies = np.array([physics.model.name2id(b.full_identifier, "body") for b in cabinet.moving_bodies()], int)
        nominal = getattr(self, "_nominal", None)
        if nominal is None or nominal[0] is not model:
            nominal = (model, model.dof_damping[dofs].copy(), model.dof_frictionloss[dofs].copy(),
                       model.geom_friction[geoms, 0].copy() if len(geoms) else np.zeros(0),
                       model.body_mass[bodies].copy(), model.body_inertia[bodies].copy())
            object.__setattr__(self, "_nominal", nominal)
        _, damping, frictionloss, friction, mass, inertia = nominal
        f = self.physics
        model.dof_damping[dofs] = damping * f["joint_damping"]
        model.dof_frictionloss[dofs] = frictionloss * f["joint_frictionloss"]
        if len(geoms):
            model.geom_friction[geoms, 0] = friction * f["handle_friction"]
        model.body_mass[bodies] = mass * f["mass"]
        model.body_inertia[bodies] = inertia * f["mass"]
        mujoco.mj_setConst(model, physics.data.ptr)

    # ------------------------------------------------------------------ depth sensor
    def depth_sensor(self) -> "DepthSensor | None":
        return DepthSensor(self.depth, self.depth_seed) if self.depth is not None else None


def _place_distractors(rng, level: Level, lo, hi, config: PerturbConfig) -> list[Distractor]:
    """Objects on the cabinet's top (set back from its front) and on the floor beside its -y side
    (the hand starts on the +y side), none overlapping another."""
    placed: list[Distractor] = []

    def free(d: Distractor) -> bool:
        a_lo, a_hi = d.box()
        return all(not (np.all(a_lo < b_hi + 0.01) and np.all(b_lo < a_hi + 0.01))
                   for b_lo, b_hi in (p.box() for p in placed))

    for i in range(level.distractors_top):
        for _ in range(30):
            half, parts = _object(rng, "", small=True)
            x0, x1 = lo[0] + config.top_setback_m + half[0], hi[0] - half[0]
            y0, y1 = lo[1] + half[1], hi[1] - half[1]
            if x1 < x0 or y1 < y0:
                break
            d = Distractor(name=f"top{i}", pos=(float(rng.uniform(x0, x1)), float(rng.uniform(y0, y1)),
                                                float(hi[2]) + 0.001), half=half, parts=parts)
            if free(d):
                placed.append(d)
                break
    for i in range(level.distractors_beside):
        for _ in range(30):
            half, parts = _object(rng, "", small=False)
            x0, x1 = lo[0] + 0.02 + half[0], max(lo[0] + 0.02 + half[0], hi[0] - half[0])
            y = lo[1] - config.beside_gap_m - half[1] - float(rng.uniform(0, 0.25))
            d = Distractor(name=f"beside{i}", pos=(float(rng.uniform(x0, x1)), y, 0.001), half=half, parts=parts)
            if free(d):
                placed.append(d)
                break
    return placed


def _unseen_texture(rng, size: int = 128) -> np.ndarray:
    """A texture no training render has: smooth random blobs in three saturated colours
    (camouflage-like), (size, size, 3) 0-255."""
    import colorsys

    coarse = rng.normal(size=(8, 8))
    yy, xx = np.mgrid[0:size, 0:size] / size * 7
    i0, j0 = np.floor(yy).astype(int), np.floor(xx).astype(int)
    fy, fx = yy - i0, xx - j0
    field_ = (coarse[i0, j0] * (1 - fy) * (1 - fx) + coarse[i0 + 1, j0] * fy * (1 - fx)
              + coarse[i0, j0 + 1] * (1 - fy) * fx + coarse[i0 + 1, j0 + 1] * fy * fx)
    field_ += 0.3 * np.sin(xx * rng.uniform(6, 12) + yy * rng.uniform(-6, 6))
    hue = rng.uniform()
    palette = np.array([colorsys.hsv_to_rgb((hue + k / 3) % 1, rng.uniform(0.6, 1.0), rng.uniform(0.35, 0.95))
                        for k in range(3)])
    bands = np.digitize(field_, np.quantile(field_, [1 / 3, 2 / 3]))
    return palette[bands] * 255.0


def _retexture(root, cabinet, handle_geoms, rng, with_cabinet: bool) -> None:
    """The floor and walls (and, ``with_cabinet``, the cabinet but its handles) in unseen textures."""
    from opend_mj.sim.rooms.textures import png_asset

    for name in ("floor", "wall"):
        mat = root.find("material", name)
        if mat is None:
            continue
        tex = root.asset.add("texture", name=f"unseen_{name}", type="2d", file=png_asset(_unseen_texture(rng)))
        mat.texture = tex
        mat.rgba = [1, 1, 1, 1]
        mat.texuniform = "true"
        mat.texrepeat = [float(rng.uniform(1.0, 3.0))] * 2
    if not with_cabinet:
        return
    cab_root = cabinet.mjcf_model
    tex = cab_root.asset.add("texture", name="unseen_cabinet", type="2d", file=png_asset(_unseen_texture(rng)))
    colour = np.clip(rng.uniform(0.2, 1.0, 3), 0, 1)
    mat = cab_root.asset.add("material", name="unseen_cabinet", texture=tex, texuniform="true",
                             texrepeat=[4.0, 4.0], rgba=[*colour.tolist(), 1.0], specular=0.3)
    handles = set(handle_geoms)
    for geom in cab_root.find_all("geom"):
        if geom.name in handles:
            continue
        if geom.rgba is not None and len(geom.rgba) == 4 and float(geom.rgba[3]) == 0.0:
            continue  # invisible collision geoms stay invisible
        geom.material = mat
        geom.rgba = None


class DepthSensor:
    """A real depth camera's image from a rendered one: axial noise growing with distance, missing
    pixels (depth 0, as real sensors report them) at depth edges, on dark surfaces and at random.
    Deterministic: the k-th image of a scene gets the k-th draw of its seed."""

    def __init__(self, level: Level, seed: int):
        self.level = level
        self.seed = int(seed)
        self.count = 0

    def __call__(self, rgb: np.ndarray, depth: np.ndarray) -> np.ndarray:
        lv = self.level
        rng = np.random.default_rng([self.seed, self.count])
        self.count += 1
        z = np.asarray(depth, np.float32)
        valid = np.isfinite(z) & (z > 0)
        sigma = lv.depth_sigma_scale * (0.0012 + 0.0019 * (np.where(valid, z, 0.4) - 0.4) ** 2)
        out = (z + rng.normal(size=z.shape) * sigma).astype(np.float32)
        jump = np.zeros(z.shape, bool)
        dz = np.abs(np.diff(z, axis=1)) > 0.03
        jump[:, 1:] |= dz
        jump[:, :-1] |= dz
        dz = np.abs(np.diff(z, axis=0)) > 0.03
        jump[1:, :] |= dz
        jump[:-1, :] |= dz
        grey = np.asarray(rgb, np.float32).mean(axis=-1) if rgb is not None else np.full(z.shape, 255.0)
        dark = grey < 30.0  # near-black surfaces return too little of the projector's light
        u = rng.uniform(size=z.shape)
        missing = ((jump & (u < lv.depth_edge_dropout)) | (dark & (u < lv.depth_dark_dropout))
                   | (rng.uniform(size=z.shape) < lv.depth_random_dropout))
        out[missing | ~valid] = 0.0
        out[~valid] = z[~valid]
        return out


def sensor_depth(rgb: np.ndarray, depth: np.ndarray, level: "Level | str", seed: int, frames: int = 1,
                 config: PerturbConfig = DEFAULT_CONFIG) -> np.ndarray:
    """A rendered depth image as the depth_noise sensor at ``level`` (a `Level` or "mild" / "strong")
    gives it, ``frames`` frames of the still scene fused as the task fuses them
    (`OpenCabinetTask.sense_depth`): training data for solvers that must read a real sensor."""
    lv = config.level(level) if isinstance(level, str) else level
    sensor = DepthSensor(lv, seed)
    return fuse_depth([sensor(rgb, depth) for _ in range(max(1, int(frames)))])


def fuse_depth(frames: list[np.ndarray]) -> np.ndarray:
    """One depth image from several frames of a still scene, as a depth camera's temporal filter
    gives it: per pixel, the median of the frames that have a reading (0, none, where no frame has
    one). Independent noise shrinks about as 1/sqrt(frames); a pixel missing in some frames is filled.
    One frame, or identical frames, come back unchanged."""
    if len(frames) == 1:
        return frames[0]
    stack = np.stack([np.asarray(f, np.float32) for f in frames])
    read = np.isfinite(stack) & (stack > 0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # "All-NaN slice": no frame read that pixel
        fused = np.nanmedian(np.where(read, stack, np.nan), axis=0)
    return np.where(read.any(axis=0), fused, stack[0]).astype(np.float32)
