"""Broken sources: each is rejected with the right reason and a message naming the file and the problem,
and a dataset build over good and broken sources builds the good ones and records the broken ones."""

from __future__ import annotations

import re
import shutil
from pathlib import Path
from typing import Callable

import pytest

from opend_mj.assets.compiler import compile_cabinet
from opend_mj.assets.dataset import build_dataset
from opend_mj.assets.procedural import find_cabinets, write_source


def _single(kind: str):
    """The first describable generated cabinet (seed 0) with one target, of this kind, side-hinged if a door."""
    (cabinet,) = find_cabinets(lambda c: len(c.targets) == 1 and c.targets[0].kind == kind
                               and c.targets[0].hinge in ("", "left", "right"))
    return cabinet


def _obj(source: Path, k: int) -> Path:
    return source / "textured_objs" / f"original-{k}.obj"


def _urdf(source: Path) -> Path:
    return source / "mobility.urdf"


def missing_mesh(src: Path) -> Path:
    _obj(src, 1).unlink()
    return _obj(src, 1)


def malformed_urdf(src: Path) -> Path:
    text = _urdf(src).read_text()
    _urdf(src).write_text(text[: len(text) // 2])
    return _urdf(src)


def revolute_without_limit(src: Path) -> Path:
    text = _urdf(src).read_text()
    assert 'type="revolute"' in text
    _urdf(src).write_text(re.sub(r"\s*<limit [^>]*/>", "", text))
    return _urdf(src)


def empty_obj(src: Path) -> Path:
    _obj(src, 0).write_text("")
    return _obj(src, 0)


def degenerate_obj(src: Path) -> Path:
    # Faces whose corners are collinear or repeated: zero area everywhere.
    _obj(src, 0).write_text("v 0 0 0\nv 0.1 0 0\nv 0.2 0 0\nv 0.3 0 0\nf 1 2 3\nf 2 3 4\nf 1 1 2\n")
    return _obj(src, 0)


def nan_vertices(src: Path) -> Path:
    path = _obj(src, 0)
    lines = path.read_text().splitlines()
    first = next(i for i, line in enumerate(lines) if line.startswith("v "))
    lines[first] = "v nan 0.1 nan"
    path.write_text("\n".join(lines) + "\n")
    return path


def no_urdf(src: Path) -> Path:
    _urdf(src).unlink()
    return _urdf(src)


def unknown_link(src: Path) -> Path:
    text = _urdf(src).read_text()
    _urdf(src).write_text(text.replace('<child link="link_0"/>', '<child link="link_42"/>', 1))
    return _urdf(src)


def garbage_mesh(src: Path) -> Path:
    _obj(src, 0).write_bytes(b"\x00\x01\x02 not a mesh \xff\xfe" * 50)
    return _obj(src, 0)


#: name -> (break it, expected reason, words the message must contain)
CASES: dict[str, tuple[Callable[[Path], Path], str, str]] = {
    "missing_mesh": (missing_mesh, "mesh_error", r"missing"),
    "malformed_urdf": (malformed_urdf, "urdf_error", r"malformed"),
    "revolute_without_limit": (revolute_without_limit, "urdf_error", r"joint_0.*(no limit|limit)"),
    "empty_obj": (empty_obj, "mesh_error", r"empty"),
    "degenerate_obj": (degenerate_obj, "mesh_error", r"degenerate|zero area"),
    "nan_vertices": (nan_vertices, "mesh_error", r"NaN"),
    "no_urdf": (no_urdf, "urdf_error", r"no mobility\.urdf"),
    "unknown_link": (unknown_link, "urdf_error", r"unknown link|link_42"),
    "garbage_mesh": (garbage_mesh, "mesh_error", r"mesh"),
}


@pytest.fixture(scope="module")
def good_sources(tmp_path_factory) -> list[Path]:
    root = tmp_path_factory.mktemp("good")
    return [write_source(_single("door"), root), write_source(_single("drawer"), root)]


def _broken(good: Path, root: Path, name: str) -> tuple[Path, Path]:
    src = Path(shutil.copytree(good, root / name))
    return src, CASES[name][0](src)


@pytest.mark.parametrize("name", sorted(CASES))
def test_broken_source_is_rejected(name, good_sources, tmp_path):
    src, broken_file = _broken(good_sources[0], tmp_path / "src", name)
    _, reason, problem = CASES[name]
    result = compile_cabinet(src, tmp_path / "out", cache_dir=tmp_path / "cache")
    assert result.status == "rejected"
    assert result.reason == reason, result.message
    assert str(broken_file) in result.message, f"the message names the file: {result.message}"
    assert re.search(problem, result.message, re.IGNORECASE), result.message
    assert not (tmp_path / "out" / name).exists(), "a rejected source leaves no half-built cabinet"


def test_rejection_replaces_a_stale_build(good_sources, tmp_path):
    """A source that built before and is broken now is rejected, and its old output is removed."""
    src = Path(shutil.copytree(good_sources[0], tmp_path / "src" / "cab"))
    out = tmp_path / "out"
    assert compile_cabinet(src, out).status == "built"
    empty_obj(src)
    result = compile_cabinet(src, out)
    assert (result.status, result.reason) == ("rejected", "mesh_error")
    assert not (out / "cab").exists()


def test_good_sources_compile(good_sources, tmp_path):
    for src in good_sources:
        assert compile_cabinet(src, tmp_path / "out").status == "built"


@pytest.mark.slow
def test_dataset_over_good_and_broken_sources(good_sources, tmp_path):
    broken_root = tmp_path / "broken"
    broken = [_broken(good_sources[0], broken_root, name)[0] for name in sorted(CASES)]
    sources = [good_sources[0], *broken, good_sources[1]]
    manifest = build_dataset(sources, tmp_path / "out", workers=2, progress=False, log=lambda *a: None)
    assert sorted(c["id"] for c in manifest.cabinets) == sorted(s.name for s in good_sources)
    rejected = {r["id"]: r for r in manifest.rejected}
    assert sorted(rejected) == sorted(CASES)
    for name, (_, reason, problem) in CASES.items():
        assert rejected[name]["reason"] == reason, rejected[name]
        assert re.search(problem, rejected[name]["message"], re.IGNORECASE)
    assert (tmp_path / "out" / "manifest.json").is_file()


def tiny_handle(src: Path) -> Path:
    """The handle mesh is a single 1 mm triangle: too small to carry collision geometry."""
    _obj(src, 1).write_text("v 0 0 0\nv 0.001 0 0\nv 0 0.001 0\nf 1 2 3\n")
    return _obj(src, 1)


def test_handle_too_small_to_grasp_is_rejected(good_sources, tmp_path):
    src, _ = Path(shutil.copytree(good_sources[0], tmp_path / "src" / "cab")), None
    tiny_handle(src)
    result = compile_cabinet(src, tmp_path / "out")
    assert (result.status, result.reason) == ("rejected", "mesh_error"), result.message
    assert "handle of link_0" in result.message and "no collision geometry" in result.message


def test_lone_triangle_visual_is_fine(good_sources, tmp_path):
    """A visual piece made of one triangle with a material of its own (PartNet has such decals) builds."""
    import mujoco

    src = Path(shutil.copytree(good_sources[0], tmp_path / "src" / "cab"))
    objs = src / "textured_objs"
    (objs / "decal.mtl").write_text("newmtl decal\nKd 0.9 0.1 0.1\n")
    (objs / "decal.obj").write_text("mtllib decal.mtl\nusemtl decal\nv 0 0 0\nv 0.05 0 0\nv 0 0.05 0\nf 1 2 3\n")
    text = _urdf(src).read_text()
    carcass = re.search(r'<child link="(link_\d+)"/>\s*<parent link="base"/>', text).group(1)
    visual = ('<link name="%s">\n\t\t<visual name="decal">\n\t\t\t<geometry>\n'
              '\t\t\t\t<mesh filename="textured_objs/decal.obj"/>\n\t\t\t</geometry>\n\t\t</visual>\n' % carcass)
    _urdf(src).write_text(text.replace(f'<link name="{carcass}">\n', visual, 1))
    result = compile_cabinet(src, tmp_path / "out")
    assert result.status == "built", result.message
    mujoco.MjModel.from_xml_path(str(tmp_path / "out" / "cab" / "cabinet.xml"))


def _set_mesh_path(src: Path, new: str) -> Path:
    text = _urdf(src).read_text()
    _urdf(src).write_text(text.replace('filename="textured_objs/original-0.obj"', f'filename="{new}"'))
    return _urdf(src)


def mesh_path_escapes(src: Path) -> Path:
    return _set_mesh_path(src, "../../somewhere/x.obj")


def mesh_path_absolute(src: Path) -> Path:
    return _set_mesh_path(src, "/etc/hostname")


def duplicate_joint(src: Path) -> Path:
    text = _urdf(src).read_text()
    names = re.findall(r'<joint name="([^"]+)"', text)
    _urdf(src).write_text(text.replace(f'<joint name="{names[1]}"', f'<joint name="{names[0]}"', 1))
    return _urdf(src)


def duplicate_link(src: Path) -> Path:
    text = _urdf(src).read_text()
    _urdf(src).write_text(text.replace("</robot>", '<link name="base"/>\n</robot>'))
    return _urdf(src)


def huge_mesh(src: Path) -> Path:
    path = _obj(src, 0)
    verts = "".join(f"v {i * 1e-3} {(i % 7) * 1e-3} {(i % 3) * 1e-3}\n" for i in range(300))
    faces = "f 1 2 3\n" * 250
    path.write_text(verts + faces)
    return path


SAFETY_CASES = {
    "mesh_path_escapes": (mesh_path_escapes, "mesh_error", r"leaves the source folder"),
    "mesh_path_absolute": (mesh_path_absolute, "mesh_error", r"leaves the source folder"),
    "duplicate_joint": (duplicate_joint, "urdf_error", r"duplicate joint"),
    "duplicate_link": (duplicate_link, "urdf_error", r"duplicate link"),
    "huge_mesh": (huge_mesh, "mesh_error", r"more than the limit"),
}


@pytest.mark.parametrize("name", sorted(SAFETY_CASES))
def test_unsafe_or_huge_source_is_rejected_in_one_line(name, good_sources, tmp_path, monkeypatch):
    import dataclasses

    from opend_mj.assets.config import CompilerConfig

    src = Path(shutil.copytree(good_sources[0], tmp_path / "src" / name))
    broken_file = SAFETY_CASES[name][0](src)
    _, reason, problem = SAFETY_CASES[name]
    opened = []
    if name.startswith("mesh_path"):
        from opend_mj.assets import sources

        real = sources.load_mesh_file
        monkeypatch.setattr(sources, "load_mesh_file", lambda p, *a: opened.append(p) or real(p, *a))
    config = dataclasses.replace(CompilerConfig(), max_mesh_faces=200)
    result = compile_cabinet(src, tmp_path / "out", config, cache_dir=tmp_path / "cache")
    assert (result.status, result.reason) == ("rejected", reason), result.message
    assert str(broken_file) in result.message
    assert re.search(problem, result.message, re.IGNORECASE), result.message
    assert "\n" not in result.message
    assert not any("somewhere" in str(p) or str(p).startswith("/etc") for p in opened), "refused, not read"


def test_dataset_goes_on_after_unsafe_sources(good_sources, tmp_path):
    broken = []
    for name in ("mesh_path_escapes", "duplicate_joint"):
        src = Path(shutil.copytree(good_sources[0], tmp_path / "broken" / name))
        SAFETY_CASES[name][0](src)
        broken.append(src)
    manifest = build_dataset([good_sources[0], *broken], tmp_path / "out", workers=1, progress=False,
                             log=lambda *a: None, cache_dir=tmp_path / "cache")
    assert [c["id"] for c in manifest.cabinets] == [good_sources[0].name]
    assert sorted(r["id"] for r in manifest.rejected) == ["duplicate_joint", "mesh_path_escapes"]
