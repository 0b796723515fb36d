"""Reading mesh files: OBJ (or any trimesh format) into checked parts, with their textures."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh


class MeshError(ValueError):
    """A mesh file that cannot be used; the message names the file and the problem."""


def load_mesh_file(path: Path, max_faces: int | None = None) -> list[tuple[trimesh.Trimesh, object]]:
    """Load an OBJ (or any trimesh format) as (mesh, visual) parts, one per material.

    Raises MeshError for missing, empty, NaN or degenerate meshes, and for OBJ files with more than
    `max_faces` faces (counted before parsing, so a huge file cannot stall a worker).
    """
    if not path.is_file():
        raise MeshError(f"{path}: mesh file is missing")
    if max_faces is not None and path.suffix.lower() == ".obj":
        count = 0
        with open(path, "rb") as fh:
            for line in fh:
                if line.startswith(b"f "):
                    count += max(1, len(line.split()) - 3)
        if count > max_faces:
            raise MeshError(f"{path}: mesh has {count} faces, more than the limit of {max_faces} "
                            f"(CompilerConfig.max_mesh_faces)")
    try:
        loaded = trimesh.load(path, process=False)
    except Exception as exc:  # trimesh raises many exception types for bad files
        raise MeshError(f"{path}: cannot be read as a mesh ({type(exc).__name__}: {exc})") from exc
    geoms = list(loaded.geometry.values()) if isinstance(loaded, trimesh.Scene) else [loaded]
    parts = [g for g in geoms if isinstance(g, trimesh.Trimesh) and len(g.faces) > 0]
    if not parts:
        raise MeshError(f"{path}: mesh is empty (no faces)")
    for g in parts:
        vertices, faces = np.asarray(g.vertices), np.asarray(g.faces)
        if vertices.ndim != 2 or vertices.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3:
            # e.g. "v 1" lines: trimesh reads vertices of one coordinate and fails later, deep inside
            raise MeshError(f"{path}: mesh is malformed (vertices of shape {vertices.shape}, faces of shape "
                            f"{faces.shape}; expected 3 coordinates and 3 corners)")
        if not np.all(np.isfinite(vertices)):
            raise MeshError(f"{path}: mesh has NaN or infinite vertex coordinates")
    _attach_textures(path, parts)
    area = sum(float(g.area) for g in parts)
    if not area > 0.0:
        raise MeshError(f"{path}: mesh is degenerate (all faces have zero area)")
    return [(g, g.visual) for g in parts]


def _attach_textures(obj_path: Path, parts: list[trimesh.Trimesh]) -> None:
    """Load `map_Kd` textures that trimesh's resolver skipped (PartNet uses `../images/...`)."""
    missing = [g for g in parts if getattr(getattr(g.visual, "material", None), "image", 1) is None]
    if not missing:
        return
    textures: dict[str, Path] = {}
    try:
        lines = obj_path.read_text(errors="replace").splitlines()
    except OSError:
        return
    for mtllib in (ln.split(None, 1)[1].strip() for ln in lines if ln.startswith("mtllib ")):
        mtl = obj_path.parent / mtllib
        if not mtl.is_file():
            continue
        current = None
        for ln in mtl.read_text(errors="replace").splitlines():
            fields = ln.strip().split(None, 1)
            if len(fields) == 2 and fields[0] == "newmtl":
                current = fields[1].strip()
            elif len(fields) == 2 and fields[0] == "map_Kd" and current:
                textures[current] = (mtl.parent / fields[1].strip().split()[-1]).resolve()
    from PIL import Image

    for g in missing:
        image_path = textures.get(g.visual.material.name)
        if image_path is not None and image_path.is_file() and getattr(g.visual, "uv", None) is not None:
            try:
                g.visual.material.image = Image.open(image_path).convert("RGB")
            except OSError:
                pass
