"""The cabinet compiler: a PartNet-Mobility source folder -> `cabinets/<id>/` (MJCF + meshes + JSON).

Output per cabinet:
- `cabinet.xml`: a static `carcass` body and one body per movable part (world-aligned frames at the
  joint anchor), convex collision geoms (boxes where a hull is a box, meshes otherwise), handle
  collision geoms `handle_<link>_<i>`, textured visual meshes that do not collide, explicit
  inertials, joint damping / frictionloss / armature from the config, and `<contact><exclude>`
  between the carcass and every movable part (plus movable pairs that touch at rest);
- `meshes/`: visual OBJ files and PNG textures;
- `cabinet.json`: every target (joint, door or drawer, range, hinge side, drawer length, handle box
  in the cabinet frame, orientation, instruction) and build statistics.

A cabinet whose `cabinet.json` records the same source hash and compiler digest is not rebuilt.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from opend_mj.assets.config import CompilerConfig
from opend_mj.assets.layout import CABINET_JSON, CABINET_XML
from opend_mj.assets.meshes import (
    DecompositionStats,
    Hull,
    collision_hulls,
    mass_properties,
)
from opend_mj.assets.sources import (
    CARCASS,
    CabinetSource,
    Part,
    SourceError,
    read_source,
    source_hash,
)
from opend_mj.language import LanguageConfig, LanguageInvalid, TargetLayout, describe
from opend_mj.transforms import mat_to_quat

#: Bump when the compiler's output changes for the same input and config (invalidates the cache).
COMPILER_VERSION = 3


@dataclass
class CompileResult:
    """What happened to one source: built, cached or rejected (with the reason)."""

    id: str
    status: str  # "built" | "cached" | "rejected"
    reason: str | None = None  # rejection kind: urdf_error, mesh_error, size_error, language_invalid, no_target,
    # physics_error
    message: str | None = None
    seconds: float = 0.0
    info: dict = field(default_factory=dict)  # the cabinet.json content when built or cached


def default_cache_dir() -> Path:
    """Where decompositions are cached across output folders: $OPEND_CACHE_DIR, else
    $XDG_CACHE_HOME/opend-mj, else ~/.cache/opend-mj."""
    import os

    if os.environ.get("OPEND_CACHE_DIR"):
        return Path(os.environ["OPEND_CACHE_DIR"]).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base).expanduser() / "opend-mj"


def _fmt(values, precision: int = 6) -> str:
    return " ".join(f"{float(v):.{precision}g}" if abs(float(v)) >= 1e-12 else "0" for v in np.ravel(values))


# --------------------------------------------------------------------------------------------------
# Targets and language


def _target_records(source: CabinetSource) -> list[dict]:
    """One record per movable part that carries a handle (a door or a drawer)."""
    records = []
    for part in source.parts:
        if part.joint is None or not part.handles:
            continue
        joint = part.joint
        handle_pts = np.vstack([h.vertices for h in part.handles])
        lo, hi = handle_pts.min(axis=0), handle_pts.max(axis=0)
        size = hi - lo
        body_pts = np.vstack([v.vertices for v in part.visuals])
        kind = "drawer" if joint.kind == "slide" else "door"
        closed = float(np.clip(0.0, joint.lower, joint.upper))
        open_sign = 1 if (joint.upper - closed) >= (closed - joint.lower) else -1
        travel = (joint.upper - closed) if open_sign > 0 else (closed - joint.lower)
        record = {
            "joint": joint.name,
            "link": part.name,
            "type": kind,
            "joint_type": joint.kind,
            "range": [joint.lower, joint.upper],
            "closed_value": closed,
            "open_sign": open_sign,
            "open_travel": float(travel),
            "axis": joint.axis.round(6).tolist(),
            "anchor": joint.anchor.round(6).tolist(),
            "handle": {
                "box_min": lo.round(6).tolist(),
                "box_max": hi.round(6).tolist(),
                "center": ((lo + hi) / 2).round(6).tolist(),
                "orientation": "horizontal" if size[1] >= size[2] else "vertical",
                "size": size.round(6).tolist(),
            },
            "part_box_min": body_pts.min(axis=0).round(6).tolist(),
            "part_box_max": body_pts.max(axis=0).round(6).tolist(),
        }
        if kind == "drawer":
            extent = body_pts @ joint.axis
            record["drawer_length"] = float(extent.max() - extent.min())
        else:
            centre = body_pts.mean(axis=0)
            record["hinge_side"] = "left" if joint.anchor[1] > centre[1] else "right"
            radial = body_pts - joint.anchor
            radial -= np.outer(radial @ joint.axis, joint.axis)
            record["door_width"] = float(np.linalg.norm(radial, axis=1).max())
        records.append(record)
    return records


def describe_targets(records: list[dict], config: LanguageConfig) -> None:
    """Add `instruction`, `vertical`, `horizontal` to each target record (raise LanguageInvalid)."""
    layouts = [TargetLayout(r["joint"], r["type"], r["handle"]["center"][1], r["handle"]["center"][2])
               for r in records]
    descriptions = describe(layouts, config)
    for r in records:
        d = descriptions[r["joint"]]
        r["instruction"] = d.instruction
        r["vertical"] = d.vertical
        r["horizontal"] = d.horizontal


# --------------------------------------------------------------------------------------------------
# MJCF writing


class _MjcfWriter:
    """Builds cabinet.xml and the mesh folder for one source."""

    def __init__(self, source: CabinetSource, out_dir: Path, config: CompilerConfig, cache_dir: Path | None):
        self.source = source
        self.out_dir = out_dir
        self.config = config
        self.cache_dir = cache_dir
        self.stats = DecompositionStats()
        self._memo: dict = {}  # decompositions of this cabinet by piece shape (copies of one part)
        self.counts = {"hulls": 0, "boxes": 0, "mesh_hulls": 0, "capped_hulls": 0, "visual_meshes": 0, "textures": 0}
        self.root = ET.Element("mujoco", model=f"cabinet_{source.id}")
        ET.SubElement(self.root, "compiler", angle="radian")
        self._defaults()
        self.asset = ET.SubElement(self.root, "asset")
        self.worldbody = ET.SubElement(self.root, "worldbody")
        self.contact = ET.SubElement(self.root, "contact")
        self._textures: dict[str, str] = {}
        self.handle_geoms: dict[str, list[str]] = {}

    def _defaults(self) -> None:
        c = self.config
        default = ET.SubElement(self.root, "default")
        cab = ET.SubElement(default, "default", {"class": "cabinet"})
        ET.SubElement(cab, "geom", friction=_fmt(c.friction), solref="0.004 1", solimp="0.95 0.99 0.001")
        vis = ET.SubElement(cab, "default", {"class": "visual"})
        ET.SubElement(vis, "geom", contype="0", conaffinity="0", group="2", mass="0", density="0")
        col = ET.SubElement(cab, "default", {"class": "collision"})
        ET.SubElement(col, "geom", group="3", rgba="0.6 0.5 0.4 1")
        han = ET.SubElement(cab, "default", {"class": "handle"})
        ET.SubElement(han, "geom", group="3", condim=str(c.handle_condim), rgba="0.9 0.3 0.2 1")

    def write(self) -> ET.Element:
        meshes_dir = self.out_dir / "meshes"
        meshes_dir.mkdir(parents=True, exist_ok=True)
        bodies: dict[str, ET.Element] = {}
        for part in self.source.parts:
            if part.joint is None:
                parent_el, pos = self.worldbody, np.zeros(3)
            else:
                parent = self.source.part(part.parent)
                parent_el = bodies[part.parent]
                parent_anchor = parent.joint.anchor if parent.joint is not None else np.zeros(3)
                pos = part.joint.anchor - parent_anchor
            body = ET.SubElement(parent_el, "body", name=part.name, pos=_fmt(pos), childclass="cabinet")
            bodies[part.name] = body
            self._part(part, body)
            if part.joint is not None:
                self.contact.append(ET.Element("exclude", body1=CARCASS, body2=part.name))
        return self.root

    def _origin(self, part: Part) -> np.ndarray:
        return part.joint.anchor if part.joint is not None else np.zeros(3)

    def _part(self, part: Part, body: ET.Element) -> None:
        c = self.config
        origin = self._origin(part)
        body_hulls = self._hulls([v for v in part.visuals if not v.is_handle], origin)
        handle_hulls = self._hulls(part.handles, origin, handle=True)
        all_hulls = body_hulls + handle_hulls
        mass, com, inertia = mass_properties(all_hulls, c.density)
        if part.joint is not None:
            target = float(np.clip(mass, c.min_link_mass, c.max_link_mass))
            inertia = inertia * (target / mass if mass > 0 else 1.0)
            mass = target
        else:
            mass = max(mass, 1.0)
        inertia = (inertia + inertia.T) / 2 + np.eye(3) * 1e-6
        ET.SubElement(body, "inertial", pos=_fmt(com), mass=f"{mass:.6g}", fullinertia=_fmt(
            [inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[0, 1], inertia[0, 2], inertia[1, 2]]))
        if part.joint is not None:
            j = part.joint
            physics = c.drawer if j.kind == "slide" else c.door
            if c.counterbalance and _gravity_loaded(j):
                body.set("gravcomp", "1")
            ET.SubElement(body, "joint", name=j.name, type=j.kind, axis=_fmt(j.axis), pos="0 0 0",
                          range=_fmt([j.lower, j.upper]), limited="true",
                          damping=f"{physics.damping:g}", frictionloss=f"{physics.frictionloss:g}",
                          armature=f"{physics.armature:g}", solreflimit=_fmt(physics.limit_solref))
        self._visuals(part, body, origin)
        for i, hull in enumerate(body_hulls):
            self._geom(body, hull, f"col_{part.name}_{i}", "collision")
        names = [f"handle_{part.name}_{i}" for i in range(len(handle_hulls))]
        for name, hull in zip(names, handle_hulls):
            self._geom(body, hull, name, "handle")
        if names:
            self.handle_geoms[part.name] = names

    def _hulls(self, visuals, origin: np.ndarray, handle: bool = False) -> list[Hull]:
        if not visuals:
            return []
        verts, faces, groups, offset = [], [], [], 0
        files = {}
        for v in visuals:
            verts.append(v.vertices - origin)
            faces.append(v.faces + offset)
            groups.append(np.full(len(v.faces), files.setdefault(v.file, len(files))))
            offset += len(v.vertices)
        return collision_hulls(np.vstack(verts), np.vstack(faces), self.config, self.cache_dir, self.stats,
                               groups=np.concatenate(groups), handle=handle, memo=self._memo)

    def _geom(self, body: ET.Element, hull: Hull, name: str, cls: str) -> None:
        p = self.config.precision
        self.counts["hulls"] += 1
        if hull.box is not None:
            centre, rot, half = hull.box
            if np.linalg.det(rot) < 0:
                rot = rot.copy()
                rot[:, 0] *= -1
            ET.SubElement(body, "geom", {"name": name, "class": cls, "type": "box", "pos": _fmt(centre, p),
                                         "quat": _fmt(mat_to_quat(rot), p), "size": _fmt(half, p)})
            self.counts["boxes"] += 1
            return
        mesh = ET.SubElement(self.asset, "mesh", name=name, vertex=_fmt(hull.vertices, p))
        cap = self.config.max_hull_vertices
        if cap > 0 and len(hull.vertices) > cap:
            mesh.set("maxhullvert", str(max(4, cap)))
            self.counts["capped_hulls"] += 1
        ET.SubElement(body, "geom", {"name": name, "class": cls, "type": "mesh", "mesh": name})
        self.counts["mesh_hulls"] += 1

    def _texture(self, image) -> str:
        from PIL import Image

        if not isinstance(image, Image.Image):
            image = Image.fromarray(np.asarray(image))
        image = image.convert("RGB")
        if max(image.size) > 1024:
            image.thumbnail((1024, 1024))
        key = hashlib.sha1(image.tobytes()).hexdigest()[:12]
        if key not in self._textures:
            file = f"tex_{key}.png"
            image.save(self.out_dir / "meshes" / file, optimize=False)
            ET.SubElement(self.asset, "texture", name=f"tex_{key}", type="2d", file=f"meshes/{file}")
            ET.SubElement(self.asset, "material", name=f"mat_tex_{key}", texture=f"tex_{key}",
                          specular="0.2", shininess="0.3")
            self._textures[key] = f"mat_tex_{key}"
            self.counts["textures"] += 1
        return self._textures[key]

    def _visuals(self, part: Part, body: ET.Element, origin: np.ndarray) -> None:
        groups: dict[tuple, list] = {}
        for v in part.visuals:
            if v.image is not None:
                key = ("tex", hashlib.sha1(v.image.tobytes()).hexdigest())
            else:
                key = ("rgba", tuple(round(x, 3) for x in v.rgba))
            groups.setdefault(key, []).append(v)
        for k, (key, members) in enumerate(sorted(groups.items(), key=lambda kv: str(kv[0]))):
            name = f"vis_{part.name}_{k}"
            textured = key[0] == "tex"
            lines, offset = [], 0
            for v in members:
                local = v.vertices - origin
                lines += [f"v {_fmt(x, 7)}" for x in local]
                if textured:
                    lines += [f"vt {u:.6g} {w:.6g}" for u, w in v.uv]
                    lines += [f"f {a}/{a} {b}/{b} {c}/{c}" for a, b, c in (v.faces + offset + 1)]
                else:
                    lines += [f"f {a} {b} {c}" for a, b, c in (v.faces + offset + 1)]
                offset += len(local)
            if offset < 4:  # MuJoCo rejects meshes of fewer than 4 vertices: a lone triangle is not drawn
                continue
            (self.out_dir / "meshes" / f"{name}.obj").write_text("\n".join(lines) + "\n")
            ET.SubElement(self.asset, "mesh", name=name, file=f"meshes/{name}.obj", inertia="shell")
            attrs = {"name": name, "class": "visual", "type": "mesh", "mesh": name}
            if textured:
                attrs["material"] = self._texture(members[0].image)
            else:
                attrs["rgba"] = _fmt(key[1], 4)
            ET.SubElement(body, "geom", attrs)
            self.counts["visual_meshes"] += 1


def _gravity_loaded(joint) -> bool:
    """Whether gravity moves this joint: a hinge whose axis is not vertical, a slide that is not level."""
    vertical = abs(float(np.asarray(joint.axis, dtype=float)[2]))
    return vertical < 0.99 if joint.kind == "hinge" else vertical > 0.01


def _write_xml(root: ET.Element, path: Path) -> None:
    ET.indent(root, space="  ")
    path.write_text(ET.tostring(root, encoding="unicode") + "\n")


def _rest_contacts(xml_path: Path) -> list[tuple[str, str]]:
    """Body pairs of the cabinet that touch when every joint is closed (MuJoCo alone)."""
    import mujoco

    model = mujoco.MjModel.from_xml_path(str(xml_path))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    pairs = set()
    for i in range(data.ncon):
        con = data.contact[i]
        b1 = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, model.geom_bodyid[con.geom1])
        b2 = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, model.geom_bodyid[con.geom2])
        pairs.add(tuple(sorted((b1, b2))))
    return sorted(pairs)


# --------------------------------------------------------------------------------------------------
# Entry point


def compile_cabinet(
    source_dir: Path,
    out_root: Path,
    config: CompilerConfig = CompilerConfig(),
    language: LanguageConfig = LanguageConfig(),
    cache_dir: Path | None = None,
    force: bool = False,
) -> CompileResult:
    """Compile one source folder into `out_root/<id>/`; never raises for bad input (returns rejected)."""
    start = time.perf_counter()
    source_dir = Path(source_dir)
    cabinet_id = source_dir.name
    out_dir = Path(out_root) / cabinet_id

    def rejected(reason: str, message: str) -> CompileResult:
        if out_dir.exists():
            shutil.rmtree(out_dir, ignore_errors=True)
        message = " ".join(str(message).split())  # one line, whatever the underlying error printed
        return CompileResult(cabinet_id, "rejected", reason, message, time.perf_counter() - start)

    try:
        content_hash = source_hash(source_dir) if (source_dir / "mobility.urdf").is_file() else None
    except OSError as exc:
        return rejected("urdf_error", f"{source_dir}: cannot read source files ({exc})")
    key = f"{content_hash}-{config.digest()}-v{COMPILER_VERSION}"
    info_path = out_dir / CABINET_JSON
    if not force and content_hash and info_path.is_file():
        try:
            info = json.loads(info_path.read_text())
            if info.get("build_key") == key and (out_dir / CABINET_XML).is_file():
                return CompileResult(cabinet_id, "cached", seconds=time.perf_counter() - start, info=info)
        except (OSError, json.JSONDecodeError):
            pass

    try:
        source = read_source(source_dir, config.scale, config.max_mesh_faces)
    except SourceError as exc:
        return rejected(exc.kind, str(exc))
    records = _target_records(source)
    if not records:
        return rejected("no_target", f"{source_dir / 'mobility.urdf'}: no door or drawer with a handle")
    try:
        describe_targets(records, language)
    except LanguageInvalid as exc:
        return rejected("language_invalid", f"{source_dir}: {exc}")

    if out_dir.exists():
        shutil.rmtree(out_dir)
    out_dir.mkdir(parents=True)
    writer = _MjcfWriter(source, out_dir, config, cache_dir or default_cache_dir())
    try:
        # trimesh computes a centre of mass with every volume, dividing by 0 for flat hulls (they weigh
        # nothing and are skipped): numpy's warning about it would leak into the build's output
        with np.errstate(divide="ignore", invalid="ignore"):
            root = writer.write()
    except Exception as exc:  # decomposition on a broken mesh, qhull failures
        return rejected("mesh_error", f"{source_dir}: collision geometry failed ({type(exc).__name__}: {exc})")
    xml_path = out_dir / CABINET_XML
    _write_xml(root, xml_path)
    try:
        touching = [p for p in _rest_contacts(xml_path) if CARCASS not in p]
        if touching:  # movable parts that touch when closed (e.g. double doors meeting in the middle)
            for b1, b2 in touching:
                writer.contact.append(ET.Element("exclude", body1=b1, body2=b2))
            _write_xml(root, xml_path)
        remaining = _rest_contacts(xml_path)
    except Exception as exc:  # MuJoCo rejects the model
        return rejected("physics_error", f"{xml_path}: MuJoCo cannot load the compiled model ({exc})")
    if remaining:
        return rejected("physics_error", f"{xml_path}: parts still touch at rest: {remaining}")

    for r in records:
        r["handle"]["geoms"] = writer.handle_geoms.get(r["link"], [])
        if not r["handle"]["geoms"]:  # every handle piece was too small to collide: nothing to grasp
            return rejected("mesh_error", f"{source_dir}: the handle of {r['link']} ({r['joint']}) has no "
                                          f"collision geometry (pieces under {config.min_piece_size} m)")
    lo, hi = source.bounds
    info = {
        "id": cabinet_id,
        "source": str(source_dir.resolve()),
        "build_key": key,
        "scale": config.scale,
        "bounds": {"min": lo.round(6).tolist(), "max": hi.round(6).tolist()},
        "targets": records,
        "excluded_touching_pairs": [list(p) for p in touching],
        "notes": source.notes,
        "stats": {
            **writer.counts,
            "convex_pieces": writer.stats.convex_pieces,
            "decomposed_pieces": writer.stats.decomposed_pieces,
            "coacd_hulls": writer.stats.coacd_hulls,
            "dropped_pieces": writer.stats.dropped_pieces,
            "split_hulls": writer.stats.split_hulls,
            "split_cache_hits": writer.stats.cache_hits,
            "split_seconds": round(writer.stats.split_seconds, 3),
            "max_split_deviation": round(writer.stats.max_deviation, 5),
            "seconds": round(time.perf_counter() - start, 3),
        },
    }
    info_path.write_text(json.dumps(info, indent=1) + "\n")
    return CompileResult(cabinet_id, "built", seconds=time.perf_counter() - start, info=info)
