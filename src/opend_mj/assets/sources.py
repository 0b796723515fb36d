"""Reading a PartNet-Mobility source folder into world-frame parts, ready for compilation.

A source is `mobility.urdf` + `textured_objs/*.obj`. Links joined by fixed joints are merged into one
part; every revolute or prismatic joint starts a new part. All geometry is brought into one z-up
world frame (the URDF's base joint already rotates PartNet's y-up meshes), scaled to metres and
re-centred: bounding box centred on x = y = 0, bottom at z = 0, front facing -x.
"""

from __future__ import annotations

import hashlib
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from opend_mj.assets.meshes import MeshError, load_mesh_file


class SourceError(ValueError):
    """A source folder that cannot be compiled; the message names the file and the problem.

    `kind` is the rejection reason recorded in the manifest: "urdf_error", "mesh_error" or
    "size_error" (a cabinet or part far outside furniture sizes).
    """

    def __init__(self, message: str, kind: str = "urdf_error"):
        super().__init__(message)
        self.kind = kind


@dataclass
class VisualPiece:
    """One visual mesh with one material, in world coordinates (metres)."""

    link: str
    name: str
    file: Path
    vertices: np.ndarray
    faces: np.ndarray
    uv: np.ndarray | None
    rgba: tuple[float, float, float, float]
    image: object | None  # PIL image of the diffuse texture

    @property
    def is_handle(self) -> bool:
        return "handle" in self.name.lower()


@dataclass
class JointInfo:
    name: str
    kind: str  # "hinge" or "slide"
    axis: np.ndarray  # unit vector, world frame
    anchor: np.ndarray  # a point on the axis, world frame
    lower: float
    upper: float


@dataclass
class Part:
    """A rigid body of the compiled cabinet: a movable link and the links fixed to it."""

    name: str
    parent: str | None
    joint: JointInfo | None
    links: list[str]
    visuals: list[VisualPiece] = field(default_factory=list)

    @property
    def handles(self) -> list[VisualPiece]:
        return [v for v in self.visuals if v.is_handle]


@dataclass
class CabinetSource:
    id: str
    path: Path
    parts: list[Part]
    semantics: dict[str, str]
    notes: list[str] = field(default_factory=list)

    def part(self, name: str) -> Part:
        return next(p for p in self.parts if p.name == name)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        pts = np.vstack([v.vertices for p in self.parts for v in p.visuals])
        return pts.min(axis=0), pts.max(axis=0)


URDF_NAME = "mobility.urdf"
CARCASS = "carcass"


@dataclass(frozen=True)
class SourceLimits:
    """What a source may hold before it is refused: furniture sizes and sane numbers.

    Lengths are in metres after scaling (`CompilerConfig.scale`). Not part of the compiler's cache key:
    a source within these limits compiles exactly as before; one outside them is refused, not built.
    """

    #: Largest extent of the whole cabinet, or of any part (m): furniture, not a building.
    max_extent: float = 5.0
    #: Smallest largest-extent of a part with visual meshes (m): under 1 mm it is a speck, not a door.
    min_part_size: float = 0.001
    #: Largest translation of any `<origin>` (m).
    max_offset: float = 50.0
    #: Largest `<origin rpy>` angle (rad).
    max_angle: float = 100.0
    #: Largest revolute limit, either side of closed (rad): one full turn.
    max_turn: float = 2 * math.pi
    #: Smallest and largest magnitude of a `<mesh scale>` factor.
    min_mesh_scale: float = 1e-3
    max_mesh_scale: float = 1e3


#: Link and joint names: what MuJoCo and dm_control accept as they are ('/' is dm_control's scope
#: separator) and what reads well in records. Names outside this are refused with the name.
SAFE_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.\-]{0,99}")
#: Names that would collide with the compiler's own bodies or MuJoCo's world body.
RESERVED_NAMES = (CARCASS, "world")

#: URDF numeric attributes: element tag -> attribute -> allowed value counts.
_NUMERIC = {
    "origin": {"xyz": (3,), "rpy": (3,)},
    "axis": {"xyz": (3,)},
    "limit": {"lower": (1,), "upper": (1,), "effort": (1,), "velocity": (1,)},
    "dynamics": {"damping": (1,), "friction": (1,)},
    "mesh": {"scale": (1, 3)},
    "mass": {"value": (1,)},
    "inertia": {k: (1,) for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")},
    "box": {"size": (3,)},
    "cylinder": {"radius": (1,), "length": (1,)},
    "sphere": {"radius": (1,)},
    "color": {"rgba": (4,)},
}


def source_files(path: Path) -> list[Path]:
    """The files whose content defines a source (for the content hash)."""
    files = [path / URDF_NAME]
    for sub in ("textured_objs", "images"):
        if (path / sub).is_dir():
            files += sorted(p for p in (path / sub).rglob("*") if p.is_file() and not p.name.endswith(".stl"))
    return files


def source_hash(path: Path) -> str:
    digest = hashlib.sha256()
    for f in source_files(path):
        if f.is_file():
            digest.update(str(f.relative_to(path)).encode())
            digest.update(f.read_bytes())
    return digest.hexdigest()[:24]


def _load_urdf(urdf_path: Path, scale: float, limits: SourceLimits):
    import yourdfpy
    from lxml import etree

    if not urdf_path.is_file():
        raise SourceError(f"{urdf_path}: no mobility.urdf in this folder")
    try:
        tree = etree.parse(str(urdf_path))
    except (etree.XMLSyntaxError, OSError, UnicodeError) as exc:  # lxml raises OSError for a bad encoding
        raise SourceError(f"{urdf_path}: malformed URDF XML ({exc})") from exc
    for tag in ("link", "joint"):
        seen: set[str] = set()
        for el in tree.getroot().findall(tag):
            name = el.get("name")
            if name in seen:
                raise SourceError(f"{urdf_path}: duplicate {tag} name {name!r}")
            seen.add(name)
            _check_name(urdf_path, tag, name)
    _check_numbers(tree.getroot(), urdf_path, scale, limits)
    try:
        return yourdfpy.URDF.load(
            str(urdf_path), build_scene_graph=False, load_meshes=False,
            build_collision_scene_graph=False, load_collision_meshes=False,
        )
    except Exception as exc:
        raise SourceError(f"{urdf_path}: invalid URDF ({type(exc).__name__}: {exc})") from exc


def _material(visual) -> tuple[tuple[float, float, float, float], object | None, np.ndarray | None]:
    """Colour, texture image and uv of a trimesh visual (any kind trimesh produces)."""
    rgba = (0.7, 0.7, 0.7, 1.0)
    image = None
    uv = getattr(visual, "uv", None)
    material = getattr(visual, "material", None)
    if material is not None:
        diffuse = getattr(material, "diffuse", None)
        if diffuse is None:
            diffuse = getattr(material, "baseColorFactor", None)
        if diffuse is not None:
            d = np.asarray(diffuse, dtype=float).reshape(-1)
            d = d / 255.0 if d.max() > 1.0 else d
            rgba = tuple(float(x) for x in (list(d[:3]) + [1.0]))
        image = getattr(material, "image", None)
        if image is None:
            image = getattr(material, "baseColorTexture", None)
    elif hasattr(visual, "main_color"):
        c = np.asarray(visual.main_color, dtype=float) / 255.0
        rgba = (float(c[0]), float(c[1]), float(c[2]), 1.0)
    if image is None or uv is None or len(uv) == 0:
        return rgba, None, None
    return (1.0, 1.0, 1.0, 1.0), image, np.asarray(uv, dtype=float)


def read_source(path: Path, scale: float, max_faces: int | None = None,
                limits: SourceLimits = SourceLimits()) -> CabinetSource:
    """Parse and validate a PartNet-Mobility folder; raise SourceError naming the file and problem.

    Every number is checked where it is read (finite, within `limits`), and so is the size of the
    result: a cabinet or part far outside furniture sizes is refused with its size."""
    path = Path(path)
    if not path.is_dir():
        raise SourceError(f"{path}: not a directory")
    urdf_path = path / URDF_NAME
    urdf = _load_urdf(urdf_path, scale, limits)
    robot = urdf.robot

    links = {link.name: link for link in robot.links}
    joint_of_child = {}
    for joint in robot.joints:
        if joint.parent not in links or joint.child not in links:
            raise SourceError(f"{urdf_path}: joint {joint.name} refers to an unknown link")
        if joint.child in joint_of_child:
            raise SourceError(f"{urdf_path}: link {joint.child} has two parent joints")
        joint_of_child[joint.child] = joint
    roots = [name for name in links if name not in joint_of_child]
    if len(roots) != 1:
        raise SourceError(f"{urdf_path}: expected one root link, found {len(roots)}: {roots}")

    children: dict[str, list] = {name: [] for name in links}
    for joint in robot.joints:
        children[joint.parent].append(joint)

    notes: list[str] = []
    world: dict[str, np.ndarray] = {roots[0]: np.eye(4)}
    owner: dict[str, str] = {roots[0]: CARCASS}
    parts: dict[str, Part] = {CARCASS: Part(CARCASS, None, None, [roots[0]])}
    order = [roots[0]]
    while order:
        name = order.pop(0)
        for joint in sorted(children[name], key=lambda j: j.name):
            origin = joint.origin if joint.origin is not None else np.eye(4)
            world[joint.child] = world[name] @ origin
            kind = {"revolute": "hinge", "prismatic": "slide"}.get(joint.type)
            if joint.type in ("floating", "planar"):
                raise SourceError(f"{urdf_path}: joint {joint.name} has unsupported type {joint.type}")
            if joint.type == "continuous":
                notes.append(f"continuous joint {joint.name} compiled as fixed (not a door or drawer)")
            if kind is None:
                owner[joint.child] = owner[name]
                parts[owner[name]].links.append(joint.child)
            else:
                limit = joint.limit
                lower = None if limit is None else limit.lower
                upper = None if limit is None else limit.upper
                if lower is None or upper is None or not np.isfinite([lower, upper]).all():
                    raise SourceError(f"{urdf_path}: joint {joint.name} ({joint.type}) has no limits")
                if not upper > lower:
                    raise SourceError(f"{urdf_path}: joint {joint.name} has an empty range [{lower}, {upper}]")
                axis = np.asarray(joint.axis if joint.axis is not None else (1.0, 0.0, 0.0), dtype=float)
                if not np.linalg.norm(axis) > 0:
                    raise SourceError(f"{urdf_path}: joint {joint.name} has a zero axis")
                axis_world = world[joint.child][:3, :3] @ (axis / np.linalg.norm(axis))
                if kind == "slide":
                    lower, upper = lower * scale, upper * scale
                parts[joint.child] = Part(
                    name=joint.child,
                    parent=owner[name],
                    joint=JointInfo(joint.name, kind, axis_world, world[joint.child][:3, 3] * scale,
                                    float(lower), float(upper)),
                    links=[joint.child],
                )
                owner[joint.child] = joint.child
            order.append(joint.child)

    for link_name, link in links.items():
        part = parts[owner[link_name]]
        for index, visual in enumerate(link.visuals):
            geometry = visual.geometry
            if geometry is None or geometry.mesh is None:
                if geometry is not None and (geometry.box or geometry.cylinder or geometry.sphere):
                    notes.append(f"primitive visual on {link_name} ignored (PartNet uses meshes)")
                    continue
                raise SourceError(f"{urdf_path}: visual {index} of link {link_name} has no mesh")
            mesh_file = _inside(path, geometry.mesh.filename, urdf_path)
            mesh_scale = np.ones(3) if geometry.mesh.scale is None else np.broadcast_to(
                np.asarray(geometry.mesh.scale, dtype=float), (3,))
            origin = visual.origin if visual.origin is not None else np.eye(4)
            transform = world[link_name] @ origin
            try:
                loaded = load_mesh_file(mesh_file, max_faces)
            except MeshError as exc:
                raise SourceError(f"{exc} (visual '{visual.name}' of link {link_name})", "mesh_error") from exc
            for mesh, vis in loaded:
                verts = np.asarray(mesh.vertices, dtype=float) * mesh_scale
                verts = (verts @ transform[:3, :3].T + transform[:3, 3]) * scale
                rgba, image, uv = _material(vis)
                if uv is not None and len(uv) != len(verts):
                    image, uv = None, None
                part.visuals.append(VisualPiece(
                    link=link_name, name=visual.name or f"{link_name}_{index}", file=mesh_file,
                    vertices=verts, faces=np.asarray(mesh.faces, dtype=np.int64), uv=uv,
                    rgba=rgba, image=image,
                ))

    ordered = [parts[CARCASS]] + [parts[n] for n in sorted(parts) if n != CARCASS]
    source = CabinetSource(id=path.name, path=path, parts=ordered,
                           semantics=_read_semantics(path), notes=notes)
    if not any(p.visuals for p in ordered):
        raise SourceError(f"{urdf_path}: no visual meshes at all")
    _check_sizes(source, urdf_path, limits)
    lo, hi = source.bounds
    shift = np.array([-(lo[0] + hi[0]) / 2, -(lo[1] + hi[1]) / 2, -lo[2]])
    for part in ordered:
        for v in part.visuals:
            v.vertices = v.vertices + shift
        if part.joint is not None:
            part.joint.anchor = part.joint.anchor + shift
    return source


def _check_name(urdf_path: Path, tag: str, name: str | None) -> None:
    """Refuse a link or joint name that MuJoCo (or dm_control, or the compiler) would not take as it is."""
    if not name:
        raise SourceError(f"{urdf_path}: a {tag} has no name")
    if name in RESERVED_NAMES:
        raise SourceError(f"{urdf_path}: {tag} name {name!r} is reserved (the compiler's or MuJoCo's own body)")
    if not SAFE_NAME.fullmatch(name):
        bad = sorted({c for c in name if not re.fullmatch(r"[A-Za-z0-9_.\-]", c)}) or [name[:1]]
        shown = name if len(name) <= 60 else name[:57] + "..."
        raise SourceError(f"{urdf_path}: {tag} name {shown!r} is not a safe MuJoCo name (characters "
                          f"{''.join(bad)!r}; use letters, digits, '_', '.', '-', at most 100)")


def _where(el) -> str:
    """Where an element sits in a URDF, for messages: e.g. "joint 'joint_0' <origin>"."""
    parts = []
    node = el
    while node is not None and isinstance(node.tag, str) and node.tag != "robot":
        name = node.get("name")
        if node is el:
            parts.append(f"<{node.tag}>")
        elif node.tag in ("joint", "link"):
            parts.append(f"{node.tag} {name!r}")
        elif node.tag in ("visual", "collision", "inertial"):
            parts.append(f"{node.tag} {name!r}" if name else node.tag)
        node = node.getparent()
    return " ".join(reversed(parts))


def _check_numbers(root, urdf_path: Path, scale: float, limits: SourceLimits) -> None:
    """Every numeric attribute of the URDF: numbers, finite, as many as the element takes, and not absurd."""
    for el in root.iter(*_NUMERIC):
        for attr, counts in _NUMERIC[el.tag].items():
            text = el.get(attr)
            if text is None:
                continue

            def bad(problem: str) -> SourceError:
                return SourceError(f"{urdf_path}: {_where(el)} {attr}={text!r}: {problem}")

            try:
                values = [float(x) for x in text.split()]
            except ValueError:
                raise bad("not a number") from None
            if len(values) not in counts:
                raise bad(f"{len(values)} values, expected {' or '.join(map(str, counts))}")
            if not all(math.isfinite(v) for v in values):
                raise bad("not finite")
            largest = max(abs(v) for v in values)
            if el.tag == "origin" and attr == "xyz" and largest * scale > limits.max_offset:
                raise bad(f"an offset of {largest * scale:.3g} m, beyond {limits.max_offset:g} m")
            if el.tag == "origin" and attr == "rpy" and largest > limits.max_angle:
                raise bad(f"an angle beyond {limits.max_angle:g} rad")
            if el.tag == "mesh" and not all(limits.min_mesh_scale <= abs(v) <= limits.max_mesh_scale
                                            for v in values):
                raise bad(f"a scale factor outside {limits.min_mesh_scale:g} to {limits.max_mesh_scale:g}")
            if el.tag in ("mass", "box", "cylinder", "sphere") and min(values) < 0:
                raise bad("negative")
            if el.tag == "inertia" and attr in ("ixx", "iyy", "izz") and values[0] < 0:
                raise bad("a negative moment of inertia")
            if el.tag == "limit" and attr in ("lower", "upper"):
                kind = el.getparent().get("type") if el.getparent() is not None else None
                if kind == "revolute" and largest > limits.max_turn:
                    raise bad(f"beyond one turn ({limits.max_turn:.4g} rad)")
                if kind == "prismatic" and largest * scale > limits.max_extent:
                    raise bad(f"a travel of {largest * scale:.3g} m, beyond {limits.max_extent:g} m")


def _check_sizes(source: CabinetSource, urdf_path: Path, limits: SourceLimits) -> None:
    """Refuse a cabinet or part far outside furniture sizes, with its size (m)."""

    def dims(size) -> str:
        return " x ".join(f"{x:.3g}" for x in size) + " m"

    lo, hi = source.bounds
    if not np.all(np.isfinite([lo, hi])):
        raise SourceError(f"{urdf_path}: the cabinet's geometry is not finite", "size_error")
    if (hi - lo).max() > limits.max_extent:
        raise SourceError(f"{urdf_path}: the cabinet measures {dims(hi - lo)}, beyond {limits.max_extent:g} m "
                          f"(not furniture: a mesh, a scale or an origin out of proportion)", "size_error")
    for part in source.parts:
        if not part.visuals:
            continue
        pts = np.vstack([v.vertices for v in part.visuals])
        size = pts.max(axis=0) - pts.min(axis=0)
        if size.max() < limits.min_part_size:
            raise SourceError(f"{urdf_path}: part {part.name} measures {dims(size)}, under "
                              f"{limits.min_part_size * 1000:g} mm", "size_error")
    for part in source.parts:
        j = part.joint
        if j is None or j.kind != "hinge":
            continue
        outside = np.maximum(0.0, np.maximum(lo - j.anchor, j.anchor - hi))
        if float(np.linalg.norm(outside)) > limits.max_extent:
            raise SourceError(f"{urdf_path}: joint {j.name}'s hinge axis passes {np.linalg.norm(outside):.3g} m "
                              f"from the cabinet, beyond {limits.max_extent:g} m", "size_error")


def _inside(root: Path, filename: str, urdf_path: Path) -> Path:
    """The mesh path of a URDF visual, refused (not read) if it leaves the source folder."""
    name = str(filename)
    if name.startswith("package://") or name.startswith("file://"):
        name = name.split("://", 1)[1]
    candidate = Path(name)
    resolved = (root / candidate).resolve()
    if candidate.is_absolute() or not resolved.is_relative_to(root.resolve()):
        raise SourceError(f"{urdf_path}: mesh path {filename!r} leaves the source folder (refused, not read)",
                          "mesh_error")
    return root / candidate


def _read_semantics(path: Path) -> dict[str, str]:
    sem = path / "semantics.txt"
    out: dict[str, str] = {}
    if sem.is_file():
        for line in sem.read_text(errors="replace").splitlines():
            fields = line.split()
            if len(fields) >= 3:
                out[fields[0]] = fields[2]
    return out
