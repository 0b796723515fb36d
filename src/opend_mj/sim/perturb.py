"""Perturbations of an episode: the shifts a deployment meets (camera, light, textures, distractors,
physics, depth sensor, instruction, the hand's start), each at a ``mild`` and a ``strong`` level
(`opend run --perturb`).

An axis is one object (`Axis`): its name, the numbers of its two levels, its draw for one scene and
where that draw applies (the camera's pose, the hand's start, the scene's MJCF before it compiles,
the compiled model, the depth sensor, the instruction). `AXIS_LIST` lists them; `PerturbConfig` holds
them and the checks that keep a perturbed scene valid (documented in docs/robustness.md). A perturbation is written
``AXIS=LEVEL`` (several joined by commas, e.g. ``camera_pose=mild,light=strong``); `parse_perturb`
checks and canonicalises it. `SceneShift.draw` is the one place where axes are drawn: from the
scene's seed (`evaluation.episode.scene_seed`: the episode seed and the cabinet), each axis from its
own stream, so every solver, agent, hand and target of a cabinet meets the same draw. The task
applies it (`sim.task.OpenCabinetTask`).

A new axis: a subclass of `Axis` with its levels, `draw` and the hooks where it applies, appended to
`AXIS_LIST` (appending keeps every other axis's stream, so their draws stay the same), and a row in
docs/robustness.md.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

import numpy as np

from opend_mj.sim.depth_sensor import (  # noqa: F401  (fuse_depth, sensor_depth: policy.learned.train reads them here)
    DEPTH_NOISE_LEVELS,
    DepthNoise,
    DepthSensor,
    fuse_depth,
    sensor_depth,
)
from opend_mj.sim.scene_props import Distractor, place_distractors, retexture

LEVELS = ("mild", "strong")


class PerturbError(ValueError):
    """A perturbation that is unknown or makes a scene invalid (one line, naming it)."""


@dataclass(frozen=True)
class Axis:
    """One perturbation axis: its ``name``, the values of its two levels (``mild``, ``strong``; each
    axis's own kind of value), its draw for one scene (`draw`) and where that draw applies (the hooks
    below; an axis overrides those where it applies, the others do nothing)."""

    name: ClassVar[str] = ""
    mild: Any = None
    strong: Any = None

    def level(self, name: str):
        if name not in LEVELS:
            raise PerturbError(f"unknown perturbation level {name!r}; known: {', '.join(LEVELS)}")
        return getattr(self, name)

    def draw(self, rng: np.random.Generator, level, scene: "DrawContext"):
        """The axis's concrete value for one scene at ``level`` (a value of `mild` / `strong`),
        drawn from ``rng``, the axis's own stream of the scene."""
        raise NotImplementedError

    # ---------------------------------------------------------------- where the draw applies
    def move_camera(self, value, pose):
        """The front camera's pose (`sim.camera.CameraPose`) under the draw."""
        return pose

    def move_start(self, value, offset: np.ndarray) -> np.ndarray:
        """The offset (world, m) of the hand root's start from the task's nominal start under the draw."""
        return offset

    def apply_mjcf(self, value, arena, cabinet, handle_geoms) -> None:
        """The draw into the scene's MJCF, before it compiles."""

    def apply_model(self, value, physics, cabinet, handle_geoms, nominal: dict) -> None:
        """The draw into the compiled model; ``nominal``: this axis's cache of the values it scales
        (kept per compiled model, so applying twice changes nothing)."""

    def depth_sensor(self, value) -> DepthSensor | None:
        """What turns each rendered depth image into the one solvers and agents receive."""
        return None

    def reword(self, value, target) -> str | None:
        """The instruction of ``target`` (`sim.cabinet.Target`) under the draw (None: its own)."""
        return None

    def check(self, value, path: tuple[np.ndarray, np.ndarray], refuse) -> None:
        """Call ``refuse(what)`` where the draw puts something in the hand's way (``path``: the box,
        world (min, max), of the hand's way from its start to the cabinet's front and of the space in
        front of the cabinet)."""


@dataclass(frozen=True)
class DrawContext:
    """What an axis's draw may read about its scene."""

    #: the cabinet's bounds (min, max), world (m)
    lo: np.ndarray
    hi: np.ndarray
    #: the seed sequence of the axis's stream (scene seed, 48, axis index): for draws per target
    stream: tuple[int, ...]


# ---------------------------------------------------------------------------------------- camera
@dataclass(frozen=True)
class CameraMove:
    offset: tuple[float, float, float]  # world (m)
    turn: tuple[tuple[float, ...], ...]  # 3x3 rotation, world frame


@dataclass(frozen=True)
class CameraPoseAxis(Axis):
    """The camera moves by up to ``shift_m`` (a uniform direction, uniform length) and turns by up
    to ``turn_deg`` degrees (about a uniform axis): (shift_m, turn_deg) per level."""

    name: ClassVar[str] = "camera_pose"
    mild: tuple[float, float] = (0.03, 3.0)
    strong: tuple[float, float] = (0.10, 10.0)

    def draw(self, rng, level, scene) -> CameraMove:
        shift_m, turn_deg = level
        offset = _unit(rng) * shift_m * rng.uniform()
        turn = _axis_angle(_unit(rng), math.radians(turn_deg * rng.uniform()))
        return CameraMove(tuple(float(x) for x in offset), tuple(tuple(float(x) for x in row) for row in turn))

    def move_camera(self, value: CameraMove, pose):
        from opend_mj.sim.camera import CameraPose

        return CameraPose(pos=np.asarray(pose.pos, float) + np.asarray(value.offset),
                          rot=np.asarray(value.turn) @ np.asarray(pose.rot, float), fovy=float(pose.fovy))


@dataclass(frozen=True)
class CameraFovAxis(Axis):
    """Vertical field of view x (1 + u), u uniform in +- the level's fraction."""

    name: ClassVar[str] = "camera_fov"
    mild: float = 0.05
    strong: float = 0.15

    def draw(self, rng, level, scene) -> float:
        return float(1.0 + rng.uniform(-1, 1) * level)

    def move_camera(self, value: float, pose):
        from opend_mj.sim.camera import CameraPose

        return CameraPose(pos=np.asarray(pose.pos, float), rot=np.asarray(pose.rot, float),
                          fovy=float(pose.fovy) * value)


# ---------------------------------------------------------------------------------------- light
@dataclass(frozen=True)
class LightLevel:
    #: every light's and the headlight's intensity x a factor log-uniform in this range
    intensity: tuple[float, float]
    #: colour temperature (K) uniform in this range (6500 K is white)
    temperature_k: tuple[float, float]
    #: a tint of a uniform hue with up to this saturation (0: none; "coloured" light)
    tint: float
    #: each light's direction turns by up to this angle (degrees)
    turn_deg: float


@dataclass(frozen=True)
class LightShift:
    factor: float
    colour: tuple[float, float, float]
    turns: tuple  # per light (cycled): 3x3 rotations


@dataclass(frozen=True)
class LightAxis(Axis):
    name: ClassVar[str] = "light"
    mild: LightLevel = LightLevel(intensity=(0.6, 1.4), temperature_k=(4500.0, 8000.0), tint=0.0, turn_deg=10.0)
    strong: LightLevel = LightLevel(intensity=(0.3, 2.0), temperature_k=(2700.0, 10000.0), tint=0.35, turn_deg=30.0)

    def draw(self, rng, level: LightLevel, scene) -> LightShift:
        factor = _log_uniform(rng, level.intensity)
        colour = temperature_rgb(rng.uniform(*level.temperature_k))
        if level.tint > 0:
            import colorsys

            tint = np.array(colorsys.hsv_to_rgb(rng.uniform(), rng.uniform(0, level.tint), 1.0))
            colour = colour * tint
        turns = tuple(tuple(tuple(float(x) for x in row)
                            for row in _axis_angle(_unit(rng), math.radians(level.turn_deg * rng.uniform())))
                      for _ in range(8))
        return LightShift(factor, tuple(float(c) for c in colour / colour.max()), turns)

    def apply_mjcf(self, value: LightShift, arena, cabinet, handle_geoms) -> None:
        colour = np.asarray(value.colour) * value.factor
        hl = arena.mjcf_model.visual.headlight
        for attr in ("ambient", "diffuse", "specular"):
            current = getattr(hl, attr)
            if current is not None:
                setattr(hl, attr, (np.asarray(current, float) * colour).tolist())
        for i, light in enumerate(arena.lights):
            light.diffuse = (np.asarray(light.diffuse, float) * colour).tolist()
            light.specular = (np.asarray(light.specular, float) * colour).tolist()
            if value.turns:
                d = np.asarray(value.turns[i % len(value.turns)]) @ np.asarray(light.dir, float)
                light.dir = d.tolist()


# ---------------------------------------------------------------------------------------- texture
@dataclass(frozen=True)
class TextureDraw:
    seed: int
    cabinet: bool


@dataclass(frozen=True)
class TextureAxis(Axis):
    """Unseen textures on the floor and walls; also on the cabinet (carcass and fronts, not the
    handles) where the level is True."""

    name: ClassVar[str] = "texture"
    mild: bool = False
    strong: bool = True

    def draw(self, rng, level: bool, scene) -> TextureDraw:
        return TextureDraw(int(rng.integers(2**31)), bool(level))

    def apply_mjcf(self, value: TextureDraw, arena, cabinet, handle_geoms) -> None:
        retexture(arena.mjcf_model, cabinet, handle_geoms, np.random.default_rng(value.seed), value.cabinet)


# ---------------------------------------------------------------------------------------- distractors
@dataclass(frozen=True)
class DistractorsAxis(Axis):
    """Everyday objects on the cabinet's top, and on the floor beside it (away from the hand's start,
    never in front of the cabinet): (on the top, beside) per level."""

    name: ClassVar[str] = "distractors"
    mild: tuple[int, int] = (2, 0)
    strong: tuple[int, int] = (4, 2)
    #: distractors on top stay this far (m) behind the cabinet's front edge
    top_setback_m: float = 0.06
    #: distractors on the floor beside the cabinet: this far (m) from its side, on the side away from the hand
    beside_gap_m: float = 0.08

    def draw(self, rng, level, scene) -> tuple[Distractor, ...]:
        return tuple(place_distractors(rng, *level, scene.lo, scene.hi, self.top_setback_m, self.beside_gap_m))

    def apply_mjcf(self, value, arena, cabinet, handle_geoms) -> None:
        root = arena.mjcf_model
        for i, d in enumerate(value):
            body = root.worldbody.add("body", name=f"distractor{i}_{d.name}", pos=list(d.pos))
            for j, (typ, off, size, rgba) in enumerate(d.parts):
                body.add("geom", name=f"distractor{i}_{j}", type=typ, pos=list(off), size=list(size), rgba=list(rgba),
                         contype=1, conaffinity=1, group=1, friction=[0.8, 0.005, 0.0001])

    def check(self, value, path, refuse) -> None:
        path_lo, path_hi = path
        for d in value:
            dlo, dhi = d.box()
            if np.all(dlo < path_hi) and np.all(path_lo < dhi):
                refuse(f"a distractor ({d.name} at {np.round(d.pos, 3).tolist()}) in the hand's path or in front of "
                       "the cabinet")


# ---------------------------------------------------------------------------------------- physics
PHYSICS_FACTORS = ("handle_friction", "joint_frictionloss", "joint_damping", "mass")


@dataclass(frozen=True)
class PhysicsAxis(Axis):
    """Handle friction, hinge/slide friction loss, joint damping and the moving parts' mass (with
    their inertia), each x a factor log-uniform in the level's range."""

    name: ClassVar[str] = "physics"
    mild: tuple[float, float] = (0.7, 1.5)
    strong: tuple[float, float] = (0.4, 3.0)

    def draw(self, rng, level, scene) -> dict[str, float]:
        return {k: _log_uniform(rng, level) for k in PHYSICS_FACTORS}

    def apply_model(self, value: dict, physics, cabinet, handle_geoms, nominal: dict) -> None:
        import mujoco

        model = physics.model.ptr
        joints = [cabinet.joint_element(j) for j in cabinet._joints]
        dofs = np.array([int(physics.bind(j).dofadr) for j in joints])
        geoms = np.array([physics.model.name2id(f"cabinet/{g}", "geom") for g in handle_geoms], int)
        bodies = np.array([physics.model.name2id(b.full_identifier, "body") for b in cabinet.moving_bodies()], int)
        if nominal.get("model") is not model:
            nominal.update(model=model, values=(
                model.dof_damping[dofs].copy(), model.dof_frictionloss[dofs].copy(),
                model.geom_friction[geoms, 0].copy() if len(geoms) else np.zeros(0),
                model.body_mass[bodies].copy(), model.body_inertia[bodies].copy()))
        damping, frictionloss, friction, mass, inertia = nominal["values"]
        model.dof_damping[dofs] = damping * value["joint_damping"]
        model.dof_frictionloss[dofs] = frictionloss * value["joint_frictionloss"]
        if len(geoms):
            model.geom_friction[geoms, 0] = friction * value["handle_friction"]
        model.body_mass[bodies] = mass * value["mass"]
        model.body_inertia[bodies] = inertia * value["mass"]
        mujoco.mj_setConst(model, physics.data.ptr)


# ---------------------------------------------------------------------------------------- depth sensor
@dataclass(frozen=True)
class DepthNoiseAxis(Axis):
    """The depth image solvers and agents receive is a real sensor's (`sim.depth_sensor`)."""

    name: ClassVar[str] = "depth_noise"
    mild: DepthNoise = DEPTH_NOISE_LEVELS["mild"]
    strong: DepthNoise = DEPTH_NOISE_LEVELS["strong"]

    def draw(self, rng, level: DepthNoise, scene) -> tuple[DepthNoise, int]:
        return level, int(rng.integers(2**31))

    def depth_sensor(self, value) -> DepthSensor:
        return DepthSensor(*value)


# ---------------------------------------------------------------------------------------- instruction
@dataclass(frozen=True)
class InstructionAxis(Axis):
    """The instruction reworded: "paraphrase" (one of the three fixed rewordings) or "grammar" (a
    rewording drawn from the grammar of `language.rewordings`), drawn per target of the scene."""

    name: ClassVar[str] = "instruction"
    mild: str = "paraphrase"
    strong: str = "grammar"

    def draw(self, rng, level: str, scene) -> tuple[str, tuple[int, ...]]:
        return level, scene.stream  # each target's rewording comes from the stream and its joint

    def reword(self, value, target) -> str:
        from opend_mj.language import Description, paraphrase, rewordings

        mode, stream = value
        record = target.record
        description = Description(record["vertical"], record["horizontal"], record["type"])
        rng = np.random.default_rng([*stream, zlib.crc32(target.joint.encode())])
        if mode == "paraphrase":
            return paraphrase(description, 1 + int(rng.integers(3)))
        return rewordings(description, n=1, seed=int(rng.integers(2**31)))[0]


# ------------------------------------------------------------------------------------ hand start
@dataclass(frozen=True)
class HandStartAxis(Axis):
    """The hand root starts elsewhere (a robot placed another way): up to ``back`` m further from the
    cabinet's front (-x), up to ``out`` m further out beside it (+y, away from the camera's view) and
    up or down by up to ``up`` m, each uniform: (back, out, up) per level. The start's height stays
    within `sim.task.START_HEIGHT`. Its strong level also serves as training data that covers the
    far approaches of wide cabinets (`opend demos --perturb hand_start=strong`)."""

    name: ClassVar[str] = "hand_start"
    mild: tuple[float, float, float] = (0.05, 0.15, 0.10)
    strong: tuple[float, float, float] = (0.15, 0.60, 0.25)

    def draw(self, rng, level, scene) -> tuple[float, float, float]:
        back, out, up = level
        return (-float(rng.uniform(0, back)), float(rng.uniform(0, out)), float(rng.uniform(-up, up)))

    def move_start(self, value, offset: np.ndarray) -> np.ndarray:
        return np.asarray(offset, float) + np.asarray(value, float)


#: Every axis, in the order of their random streams (append a new one at the end).
AXIS_LIST: tuple[Axis, ...] = (CameraPoseAxis(), CameraFovAxis(), LightAxis(), TextureAxis(), DistractorsAxis(),
                               PhysicsAxis(), DepthNoiseAxis(), InstructionAxis(), HandStartAxis())
AXES = tuple(a.name for a in AXIS_LIST)


@dataclass(frozen=True)
class PerturbConfig:
    """Every axis (with both levels' numbers), and the checks that keep a perturbed scene valid."""

    axes: tuple[Axis, ...] = AXIS_LIST
    #: the camera must stay this far (m) outside the cabinet's bounds
    camera_clearance_m: float = 0.05
    #: no distractor within this distance (m) of the hand's start or of its way to the cabinet's front
    hand_clearance_m: float = 0.12

    def axis(self, name: str) -> Axis:
        for a in self.axes:
            if a.name == name:
                return a
        raise PerturbError(f"unknown perturbation axis {name!r}; known: {', '.join(a.name for a in self.axes)}")

    def with_axis(self, axis: Axis) -> "PerturbConfig":
        """This config with ``axis`` in place of the axis of its name (other numbers for its levels)."""
        return replace(self, axes=tuple(axis if a.name == axis.name else a for a in self.axes))


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
class SceneShift:
    """The concrete values of a perturbation for one scene: ``values`` maps each perturbed axis's
    name to its draw (`Axis.draw`); an axis not perturbed has none (``shift[name]`` is None)."""

    spec: str | None = None
    config: PerturbConfig = DEFAULT_CONFIG
    values: dict = field(default_factory=dict)
    #: per axis, the compiled model's values it scales (`Axis.apply_model`): a cache, not part of the draw
    _nominal: dict = field(default_factory=dict, init=False, compare=False, repr=False)

    @classmethod
    def draw(cls, spec: str | None, seed: int, bounds, config: PerturbConfig = DEFAULT_CONFIG) -> "SceneShift":
        """The draw of ``spec`` for the scene of ``seed`` (its scene seed) and a cabinet's ``bounds``
        ((min, max), world, m). Each axis has its own random stream (its index in ``config.axes``), so
        adding an axis never changes another's draw."""
        items = perturb_items(spec)
        if not items:
            return cls()
        lo, hi = (np.asarray(b, float) for b in bounds)
        values = {}
        for index, axis in enumerate(config.axes):
            if axis.name in items:
                stream = (int(seed), 48, index)
                values[axis.name] = axis.draw(np.random.default_rng(list(stream)), axis.level(items[axis.name]),
                                              DrawContext(lo, hi, stream))
        return cls(spec=spec, config=config, values=values)

    def __getitem__(self, axis: str):
        """The draw of ``axis`` (None where it is not perturbed)."""
        return self.values.get(axis)

    def _drawn(self):
        """(axis, its draw) of every perturbed axis, in stream order."""
        return [(axis, self.values[axis.name]) for axis in self.config.axes if axis.name in self.values]

    # ------------------------------------------------------------------ where the draws apply
    def move_camera(self, pose):
        """The camera pose moved and turned, its field of view scaled (`sim.camera.CameraPose`)."""
        for axis, value in self._drawn():
            pose = axis.move_camera(value, pose)
        return pose

    def start_offset(self) -> np.ndarray:
        """The offset (world, m) of the hand root's start from the nominal start (zeros: none)."""
        offset = np.zeros(3)
        for axis, value in self._drawn():
            offset = axis.move_start(value, offset)
        return offset

    def apply_mjcf(self, arena, cabinet, handle_geoms) -> None:
        """Light, textures and distractors into the scene's MJCF (before it compiles)."""
        for axis, value in self._drawn():
            axis.apply_mjcf(value, arena, cabinet, handle_geoms)

    def apply_model(self, physics, cabinet, handle_geoms) -> None:
        """Friction, damping and mass of the cabinet's moving parts in the compiled model, as
        factors on its nominal values (kept on first use, so applying twice changes nothing)."""
        for axis, value in self._drawn():
            axis.apply_model(value, physics, cabinet, handle_geoms, self._nominal.setdefault(axis.name, {}))

    def depth_sensor(self) -> DepthSensor | None:
        """The depth sensor of this scene (None: the rendered depth is what solvers receive)."""
        for axis, value in self._drawn():
            sensor = axis.depth_sensor(value)
            if sensor is not None:
                return sensor
        return None

    def reword(self, target) -> str | None:
        """``target``'s instruction under the instruction axis (None: not reworded)."""
        for axis, value in self._drawn():
            worded = axis.reword(value, target)
            if worded is not None:
                return worded
        return None

    # ------------------------------------------------------------------ checks
    def check(self, bounds, camera_pos, hand_start, label: str = "") -> None:
        """Raise `PerturbError` where the scene is invalid: the camera inside (or within
        ``camera_clearance_m`` of) the cabinet, or an axis's draw in the hand's way (`Axis.check`:
        a distractor at the hand's start, on its way to the cabinet's front, or in front of the
        cabinet). ``label`` names the scene in the message."""
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

        def refuse(what: str):
            raise PerturbError(f"{where}perturbation {self.spec} puts {what}")

        for axis, value in self._drawn():
            axis.check(value, (path_lo, path_hi), refuse)
