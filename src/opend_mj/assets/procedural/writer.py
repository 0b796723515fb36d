"""Writing a sampled cabinet as a PartNet-Mobility folder (URDF, OBJ + MTL, semantics, meta)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Callable

import numpy as np
from tqdm import tqdm

from opend_mj.assets.procedural.config import GENERATOR_VERSION, GeneratorConfig
from opend_mj.assets.procedural.materials import Material
from opend_mj.assets.procedural.model import SampledCabinet, Visual, sample_cabinet, unshare_vertices
from opend_mj.assets.procedural.pieces import Piece, piece_mesh
from opend_mj.language import LanguageConfig, LanguageInvalid, TargetLayout, describe


def describable(targets: list[tuple[str, float, float]], tol: float = 0.04, max_levels: int = 5) -> bool:
    """Whether targets ``(type, height_m, horizontal_m)`` can all be named apart by Algorithm 1
    (`opend_mj.language.describe`, the rule the compiler applies), with level tolerance ``tol`` and at
    most ``max_levels`` levels and positions per level."""
    if not targets:
        return True
    labels = {n: v for n, v in LanguageConfig().vertical_labels.items() if n <= max_levels}
    config = LanguageConfig(level_tolerance=tol, vertical_labels=labels,
                            horizontal_labels={n: v for n, v in LanguageConfig().horizontal_labels.items()
                                               if n <= max_levels})
    layout = [TargetLayout(key=str(i), kind=kind, y=horizontal, z=height)
              for i, (kind, height, horizontal) in enumerate(targets)]
    try:
        describe(layout, config)
    except LanguageInvalid:
        return False
    return True


def _language_layout(cabinet: SampledCabinet) -> list[tuple[str, float, float]]:
    """(type, handle height above the floor, handle horizontal position) of each target (m)."""
    floor = -cabinet.layout.height / 2
    return [(tg.kind, tg.handle_center[1] - floor, tg.handle_center[0]) for tg in cabinet.targets]


def find_cabinets(where: Callable[[SampledCabinet], bool], count: int = 1, seed: int = 0,
                  config: GeneratorConfig = GeneratorConfig(), stop: int = 2000) -> list[SampledCabinet]:
    """The first ``count`` describable cabinets of ``seed`` (in index order, below ``stop``) for which
    ``where`` holds: a cabinet picked by what it must be (a single door, a top-hinged flap) rather
    than by an index that a new generator version gives to another cabinet. Fewer if there are none."""
    found = []
    for index in range(stop):
        cabinet = sample_cabinet(index, seed, config)
        if (describable(_language_layout(cabinet), config.level_tolerance, config.max_levels)
                and where(cabinet)):
            found.append(cabinet)
            if len(found) == count:
                break
    return found


def _fmt(v: float, decimals: int) -> str:
    s = f"{v:.{decimals}f}"
    return "0" + s[2:] if s.startswith("-0") and float(s) == 0.0 else s


def _obj_text(pieces: list[Piece], mtl_name: str, material: str, scale: float, cfg: GeneratorConfig) -> str:
    lines = [f"mtllib {mtl_name}", f"usemtl {material}"]
    faces_out: list[str] = []
    base = 1
    nd = cfg.decimals
    for p in pieces:
        verts, faces = piece_mesh(p, cfg.cylinder_sides)
        verts = verts / scale
        lines.extend(f"v {_fmt(x, nd)} {_fmt(y, nd)} {_fmt(z, nd)}" for x, y, z in verts)
        faces_out.extend(f"f {a + base} {b + base} {c + base}" for a, b, c in faces)
        base += len(verts)
    return "\n".join(lines + faces_out) + "\n"


def _mtl_text(m: Material) -> str:
    r, g, b = m.kd
    return (f"newmtl {m.name}\nKa 0.1 0.1 0.1\nKd {r:.4f} {g:.4f} {b:.4f}\n"
            f"Ks {m.ks:.4f} {m.ks:.4f} {m.ks:.4f}\nNs {m.ns:.1f}\nd 1\nillum 2\n")


def _vec(v, decimals: int) -> str:
    return " ".join(_fmt(float(x), decimals) for x in v)


def generate_source(index: int, seed: int, out_root: Path, config: GeneratorConfig = GeneratorConfig()) -> Path:
    """Write cabinet ``proc_<index>`` (PartNet-Mobility format) under ``out_root`` and return its folder."""
    return write_source(sample_cabinet(index, seed, config), out_root, config)


def write_source(cabinet: SampledCabinet, out_root: Path, config: GeneratorConfig = GeneratorConfig()) -> Path:
    """Write a sampled cabinet as folder ``<cabinet.id>`` (PartNet-Mobility format) under ``out_root``."""
    cfg = config
    cabinet_id, layout, targets, carcass = cabinet.id, cabinet.layout, cabinet.targets, cabinet.carcass
    seed, index, t, plinth, finish = cabinet.seed, cabinet.index, cabinet.thickness, cabinet.plinth, cabinet.finish
    base = cabinet.base
    folder = Path(out_root) / cabinet_id
    (folder / "textured_objs").mkdir(parents=True, exist_ok=True)
    s, nd = cfg.scale, cfg.decimals
    n = len(targets)
    body_link = f"link_{n}"
    part_id = 0
    obj_id = 0
    files: dict[str, str] = {}

    def emit(visuals: list[Visual], offset: tuple[float, float, float]) -> list[str]:
        nonlocal part_id, obj_id
        vis_xml, col_xml = [], []
        origin = _vec(offset, nd)
        for v in visuals:
            part_id += 1
            name = f"original-{obj_id}"
            obj_id += 1
            files[f"textured_objs/{name}.obj"] = _obj_text(v.pieces, f"{name}.mtl", v.material.name, s, cfg)
            files[f"textured_objs/{name}.mtl"] = _mtl_text(v.material)
            geom = (f'\t\t\t<origin xyz="{origin}"/>\n\t\t\t<geometry>\n'
                    f'\t\t\t\t<mesh filename="textured_objs/{name}.obj"/>\n\t\t\t</geometry>\n')
            vis_xml.append(f'\t\t<visual name="{v.part}-{part_id}">\n{geom}\t\t</visual>\n')
            col_xml.append(f"\t\t<collision>\n{geom}\t\t</collision>\n")
        return vis_xml + col_xml

    xml = ['<?xml version="1.0" ?>\n', f'<robot name="{cabinet_id}">\n', '\t<link name="base"/>\n']
    sem = []
    for i, tg in enumerate(targets):
        p = np.asarray(tg.origin) / s
        xml.append(f'\t<link name="link_{i}">\n')
        xml.extend(emit(unshare_vertices(tg.visuals), tuple(-p)))
        xml.append("\t</link>\n")
        upper = tg.upper / s if tg.joint_type == "prismatic" else tg.upper
        xml.append(
            f'\t<joint name="joint_{i}" type="{tg.joint_type}">\n'
            f'\t\t<origin xyz="{_vec(p, nd)}"/>\n\t\t<axis xyz="{_vec(tg.axis, 1).replace(".0", "")}"/>\n'
            f'\t\t<child link="link_{i}"/>\n\t\t<parent link="{body_link}"/>\n'
            f'\t\t<limit lower="0.0" upper="{_fmt(upper, nd)}"/>\n\t</joint>\n')
        sem.append(f"link_{i} {'slider drawer' if tg.kind == 'drawer' else 'hinge rotation_door'}")
    xml.append(f'\t<link name="{body_link}">\n')
    xml.extend(emit(unshare_vertices(carcass), (0.0, 0.0, 0.0)))
    xml.append("\t</link>\n")
    xml.append(f'\t<joint name="joint_{n}" type="fixed">\n'
               '\t\t<origin rpy="1.570796326794897 0 -1.570796326794897" xyz="0 0 0"/>\n'
               f'\t\t<child link="{body_link}"/>\n\t\t<parent link="base"/>\n\t</joint>\n</robot>\n')
    sem.append(f"{body_link} heavy furniture_body")
    files["mobility.urdf"] = "".join(xml).replace('xyz="0.000000 0.000000 0.000000"', 'xyz="0 0 0"')
    files["semantics.txt"] = "\n".join(sem) + "\n"

    lang = _language_layout(cabinet)
    ok = describable(lang, cfg.level_tolerance, cfg.max_levels)
    meta = {
        "model_id": cabinet_id,
        "anno_id": cabinet_id,
        "model_cat": "StorageFurniture",
        "version": GENERATOR_VERSION,
        "procedural": {
            "generator_version": GENERATOR_VERSION,
            "seed": int(seed),
            "index": int(index),
            "size_m": {k: round(v, 4) for k, v in
                       (("width", layout.width), ("height", layout.height), ("depth", layout.depth))},
            "panel_thickness_m": round(t, 4),
            "plinth_m": round(plinth, 4),
            "base": base,
            "layout": layout.name,
            "describable": bool(ok),
            "describable_intended": bool(layout.describable),
            "handle_kinds": sorted({tg.handle_kind for tg in targets}),
            "handle_finish": finish,
            "targets": [
                {
                    "link": f"link_{i}",
                    "joint": f"joint_{i}",
                    "type": tg.kind,
                    "hinge": tg.hinge or None,
                    "double_door": tg.double,
                    "handle_kind": tg.handle_kind,
                    "handle_orientation": tg.handle_orientation,
                    "handle_center_m": [round(v, 4) for v in tg.handle_center],
                }
                for i, tg in enumerate(targets)
            ],
        },
    }
    files["meta.json"] = json.dumps(meta)
    for rel, text in files.items():
        (folder / rel).write_text(text)
    return folder


def generate_sources(count: int, seed: int, out_root: Path, config: GeneratorConfig = GeneratorConfig(),
                     progress: bool = True) -> list[Path]:
    """Write cabinets ``proc_0000`` ... ``proc_<count-1>`` under ``out_root``."""
    out_root = Path(out_root)
    out_root.mkdir(parents=True, exist_ok=True)
    return [generate_source(i, seed, out_root, config)
            for i in tqdm(range(count), desc="generate", unit="cabinet", disable=not progress)]
