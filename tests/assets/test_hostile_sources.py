"""Hostile sources: every number is checked where it is read, sizes are furniture sizes, names are
MuJoCo's, and nothing reaches a later stage (language, MuJoCo, the feasibility check) to fail there
with the wrong reason. Each case is refused in one line naming the file, the element and the value."""

from __future__ import annotations

import re
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest

from opend_mj.assets.compiler import compile_cabinet
from opend_mj.assets.procedural import find_cabinets, write_source


@pytest.fixture(scope="module")
def door(tmp_path_factory) -> Path:
    """A generated cabinet with one side-hinged door: revolute joint_0 (link_0), carcass link_1."""
    (cabinet,) = find_cabinets(lambda c: len(c.targets) == 1 and c.targets[0].kind == "door"
                               and c.targets[0].hinge in ("left", "right"))
    return write_source(cabinet, tmp_path_factory.mktemp("good"))


def _joint0(src: Path) -> dict[str, str]:
    """joint_0's origin coordinates (x, y, z), axis and upper limit as written in the URDF."""
    text = (src / "mobility.urdf").read_text()
    joint = text[text.index('<joint name="joint_0"'):]
    x, y, z = re.search(r'<origin xyz="([^"]+)"/>', joint).group(1).split()
    return {"x": x, "y": y, "z": z, "axis": re.search(r'<axis xyz="([^"]+)"/>', joint).group(1),
            "upper": re.search(r'upper="([^"]+)"', joint).group(1)}


def _copy(door: Path, tmp_path: Path) -> Path:
    return Path(shutil.copytree(door, tmp_path / "src" / "cab"))


def _edit(src: Path, old: str, new: str) -> Path:
    urdf = src / "mobility.urdf"
    text = urdf.read_text()
    assert old in text, old
    urdf.write_text(text.replace(old, new, 1))
    return urdf


def _refused(src: Path, tmp_path: Path, reason: str, *words: str) -> str:
    result = compile_cabinet(src, tmp_path / "out", cache_dir=tmp_path / "cache")
    assert (result.status, result.reason) == ("rejected", reason), result.message
    assert "\n" not in result.message and str(src) in result.message, result.message
    for w in words:
        assert re.search(w, result.message), (w, result.message)
    return result.message


@pytest.mark.parametrize("origin, words", [
    ('<origin xyz="nan {y} {z}"/>', [r"joint 'joint_0' <origin> xyz='nan {y} {z}'", "not finite"]),
    ('<origin xyz="{x} inf {z}"/>', [r"joint 'joint_0' <origin> xyz=.*inf", "not finite"]),
    ('<origin xyz="{x} {y} {z}" rpy="0 nan 0"/>', [r"joint 'joint_0' <origin> rpy='0 nan 0'", "not finite"]),
    ('<origin xyz="{x} {y} {z}" rpy="-inf 0 0"/>', [r"rpy='-inf 0 0'", "not finite"]),
    ('<origin xyz="1e9 {y} {z}"/>', [r"xyz='1e9", "offset of 7e\\+08 m"]),
])
def test_non_finite_or_absurd_joint_origin(door, tmp_path, origin, words):
    """Not "targets joint_0 and joint_1 both read 'door'" found by the language stage on NaN geometry:
    the joint, its origin and the value, from where the URDF is read."""
    src = _copy(door, tmp_path)
    joint = _joint0(src)
    _edit(src, '<origin xyz="{x} {y} {z}"/>'.format(**joint), origin.format(**joint))
    _refused(src, tmp_path, "urdf_error", *(w.format(**{k: re.escape(v) for k, v in joint.items()}) for w in words))


@pytest.mark.parametrize("limit, words", [
    ('<limit lower="0.0" upper="nan"/>', [r"joint 'joint_0' <limit> upper='nan'", "not finite"]),
    ('<limit lower="-inf" upper="{upper}"/>', [r"<limit> lower='-inf'", "not finite"]),
    ('<limit lower="0.0" upper="40"/>', [r"upper='40'", "beyond one turn"]),
    ('<limit lower="0.0" upper="one"/>', [r"upper='one'", "not a number"]),
])
def test_bad_joint_limit_is_named_as_such(door, tmp_path, limit, words):
    """A NaN limit is a non-finite number, not "has no limits"."""
    src = _copy(door, tmp_path)
    upper = _joint0(src)["upper"]
    _edit(src, f'<limit lower="0.0" upper="{upper}"/>', limit.format(upper=upper))
    message = _refused(src, tmp_path, "urdf_error", *words)
    assert "has no limits" not in message


@pytest.mark.parametrize("attr, words", [
    ('<axis xyz="0 nan 0"/>', [r"<axis> xyz='0 nan 0'", "not finite"]),
    ('<axis xyz="0 1"/>', [r"<axis> xyz='0 1'", "2 values, expected 3"]),
])
def test_bad_axis(door, tmp_path, attr, words):
    src = _copy(door, tmp_path)
    _edit(src, f'<axis xyz="{_joint0(src)["axis"]}"/>', attr)
    _refused(src, tmp_path, "urdf_error", *words)


def test_bad_mass_and_inertia(door, tmp_path):
    """Inertials are read and checked even though the compiler computes its own."""
    src = _copy(door, tmp_path)
    _edit(src, '<link name="link_0">', '<link name="link_0"><inertial><mass value="nan"/></inertial>')
    _refused(src, tmp_path, "urdf_error", r"link 'link_0' inertial <mass> value='nan'", "not finite")
    src = _copy(door, tmp_path / "b")
    _edit(src, '<link name="link_0">',
          '<link name="link_0"><inertial><mass value="1"/><inertia ixx="-1" iyy="1" izz="1"/></inertial>')
    _refused(src, tmp_path / "b", "urdf_error", r"<inertia> ixx='-1'", "negative moment")


def test_one_mesh_scaled_1000x_is_refused_with_its_size(door, tmp_path):
    """Not built with its door "jammed" by a carcass panel 1000 times too big: refused, with the size."""
    src = _copy(door, tmp_path)
    _edit(src, '<mesh filename="textured_objs/original-2.obj"/>',
          '<mesh filename="textured_objs/original-2.obj" scale="1000 1000 1000"/>')
    _refused(src, tmp_path, "size_error", r"the cabinet measures [\d.e+]+ x [\d.e+]+ x [\d.e+]+ m, beyond 5 m")


def test_an_obj_in_other_units_is_refused_with_its_size(door, tmp_path):
    """The same, with the OBJ's own vertices 1000 times too large (a mesh in millimetres)."""
    src = _copy(door, tmp_path)
    obj = src / "textured_objs" / "original-2.obj"
    obj.write_text("\n".join("v " + " ".join(str(float(x) * 1000) for x in ln.split()[1:]) if ln.startswith("v ")
                             else ln for ln in obj.read_text().splitlines()) + "\n")
    _refused(src, tmp_path, "size_error", "the cabinet measures", "beyond 5 m")


def test_a_part_under_a_millimetre_is_refused(door, tmp_path):
    src = _copy(door, tmp_path)
    for k in (0, 1):  # the door panel and its handle: a tetrahedron of 0.1 mm
        (src / "textured_objs" / f"original-{k}.obj").write_text(
            "v 0 0 0\nv 0.0001 0 0\nv 0 0.0001 0\nv 0 0 0.0001\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n")
    _refused(src, tmp_path, "size_error", r"part link_0 measures 7e-05 x 7e-05 x 7e-05 m, under 1 mm")


def test_absurd_mesh_scale(door, tmp_path):
    src = _copy(door, tmp_path)
    _edit(src, '<mesh filename="textured_objs/original-2.obj"/>',
          '<mesh filename="textured_objs/original-2.obj" scale="0 1 1"/>')
    _refused(src, tmp_path, "urdf_error", r"<mesh> scale='0 1 1'", "scale factor outside")


@pytest.mark.parametrize("name", ["door/left", "world", "carcass", "x y", "j\u00fcrgen", "n" * 120])
def test_names_mujoco_would_refuse_are_refused_by_the_compiler(door, tmp_path, name):
    """A joint or link named with a '/' (dm_control's scope separator), MuJoCo's world body, the
    compiler's own carcass, or characters outside a safe set: refused with the name by the compiler,
    not later by MuJoCo's parser in the feasibility check."""
    src = _copy(door, tmp_path)
    tag = "joint" if name != "carcass" else "link"
    if tag == "joint":
        _edit(src, 'joint name="joint_0"', f'joint name="{name}"')
    else:
        text = (src / "mobility.urdf").read_text().replace('"link_0"', f'"{name}"')
        (src / "mobility.urdf").write_text(text)
    shown = re.escape(repr(name if len(name) <= 60 else name[:57] + "...")[1:-1])
    _refused(src, tmp_path, "urdf_error", f"{tag} name '{shown}'")


def test_safe_names_still_build(door, tmp_path):
    src = _copy(door, tmp_path)
    _edit(src, 'joint name="joint_0"', 'joint name="Door-1.left_hinge"')
    result = compile_cabinet(src, tmp_path / "out", cache_dir=tmp_path / "cache")
    assert result.status == "built", result.message
    assert result.info["targets"][0]["joint"] == "Door-1.left_hinge"


def test_the_build_leaks_no_library_warning(door, tmp_path):
    """trimesh's "invalid value encountered in divide" (center_mass = integrated[1:4] / volume) on flat
    hulls no longer reaches the build's output; the hull's mass is 0 as before."""
    from opend_mj.assets.meshes import Hull, mass_properties

    flat = Hull(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], dtype=float))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        mass, com, _ = mass_properties([flat], 600.0)
        assert mass == 0.0 and np.all(np.isfinite(com))
        assert flat.volume == 0.0
        src = _copy(door, tmp_path)
        assert compile_cabinet(src, tmp_path / "out", cache_dir=tmp_path / "cache").status == "built"


def test_an_obj_with_short_vertex_lines_is_a_mesh_error(door, tmp_path):
    """'v 1e300' (one coordinate) inserted in an OBJ: trimesh reads it and failed deep in its area
    computation (a ValueError of shapes); now a mesh error naming the file (found by the fuzzer)."""
    src = _copy(door, tmp_path)
    obj = src / "textured_objs" / "original-2.obj"
    obj.write_text(obj.read_text().replace("v ", "v 1e300\nv ", 1))
    message = _refused(src, tmp_path, "mesh_error", "mesh is malformed")
    assert str(obj) in message
