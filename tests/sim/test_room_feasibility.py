"""Cabinets in their rooms: fronts that reach the floor open, and a target that cannot open is excluded."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from opend_mj.assets.procedural import GeneratorConfig, generate_source

FLOOR_FRONTS = GeneratorConfig(base_shares=(1.0, 0.0, 0.0, 0.0))


@pytest.fixture(scope="module")
def floor_cabinet(tmp_path_factory) -> Path:
    """A compiled procedural cabinet whose bottom door and bottom drawer reach down to the floor."""
    from opend_mj.assets.compiler import compile_cabinet

    src = tmp_path_factory.mktemp("src")
    for index in range(200):
        folder = generate_source(index, 0, src, FLOOR_FRONTS)
        meta = json.loads((folder / "meta.json").read_text())["procedural"]
        if meta["describable"] and re.fullmatch(r"door_beside_\d_drawers", meta["layout"]):
            break
    else:
        pytest.fail("no describable door-beside-drawers cabinet among 200")
    out = tmp_path_factory.mktemp("cabinets")
    result = compile_cabinet(folder, out)
    assert result.status == "built", result.message
    return out / folder.name


def _bottom(cabinet_dir: Path) -> dict[str, str]:
    info = json.loads((cabinet_dir / "cabinet.json").read_text())
    low = {}
    for kind in ("door", "drawer"):
        ts = [t for t in info["targets"] if t["type"] == kind]
        low[kind] = min(ts, key=lambda t: t["handle"]["box_min"][2])["joint"]
    return low


def test_fronts_that_reach_the_floor_open_in_their_room(floor_cabinet):
    from opend_mj.sim.feasibility import check_in_room

    bottom = _bottom(floor_cabinet)
    results = {r.joint: r for r in check_in_room(floor_cabinet)}
    for kind, joint in bottom.items():
        r = results[joint]
        assert abs(r.min_clearance) < 0.003, f"the bottom {kind} should stand on the floor: {r.min_clearance}"
        assert r.feasible and r.reached >= 0.9 and not r.room_contacts, r.as_dict()
    assert all(r.feasible for r in results.values())


def test_with_floor_contact_the_same_fronts_are_held(floor_cabinet, monkeypatch):
    """The mechanism is what opens them: give the moving parts floor contact again and a bottom front
    that touches the floor is reported blocked by the room (one whose edge stands a hair above it,
    within the 3 mm above, moves either way)."""
    from opend_mj.sim.cabinet import Cabinet
    from opend_mj.sim.feasibility import BLOCKED_BY_ROOM, check_in_room

    monkeypatch.setattr(Cabinet, "moving_bodies", lambda self: [])
    results = {r.joint: r for r in check_in_room(floor_cabinet)}
    touching = [j for j in _bottom(floor_cabinet).values() if results[j].room_contacts]
    assert touching, {j: results[j].as_dict() for j in _bottom(floor_cabinet).values()}
    for joint in touching:
        assert results[joint].reason == BLOCKED_BY_ROOM and "floor" in results[joint].room_contacts


def test_an_unopenable_target_is_excluded_with_its_reason(tmp_path):
    from opend_mj.assets.dataset import build_dataset
    from opend_mj.assets.layout import load_manifest
    from opend_mj.sim.feasibility import JAMMED, RoomCheck

    src = tmp_path / "src"
    for index in range(200):
        folder = generate_source(index, 0, src, FLOOR_FRONTS)
        meta = json.loads((folder / "meta.json").read_text())["procedural"]
        if meta["describable"] and len(meta["targets"]) >= 2:
            break
    out = tmp_path / "cabinets"
    first = build_dataset([folder], out, workers=1, progress=False, log=lambda *a: None, check=RoomCheck())
    assert first.excluded_targets == [] and first.info["feasibility"]["excluded_targets"] == 0
    joints = [t["joint"] for t in first.cabinets[0]["targets"]]
    # jam one target: a friction far beyond any hand's force holds its joint (the compiled model changes,
    # the build key does not, so the rebuild reuses the cabinet and checks it again)
    xml = out / folder.name / "cabinet.xml"
    text = xml.read_text()
    jammed = joints[0]
    pattern = rf'(<joint name="{jammed}"[^>]*frictionloss=")[^"]*'
    assert re.search(pattern, text)
    xml.write_text(re.sub(pattern, r"\g<1>10000", text))
    info_path = out / folder.name / "cabinet.json"
    info = json.loads(info_path.read_text())
    del info["feasibility"]
    info_path.write_text(json.dumps(info))

    manifest = build_dataset([folder], out, workers=1, progress=False, log=lambda *a: None, check=RoomCheck())
    assert manifest.info["cached"] == 1
    assert [(e["joint"], e["reason"]) for e in manifest.excluded_targets] == [(jammed, JAMMED)]
    assert re.search(r"reaches only \d+% of its range .* touching nothing", manifest.excluded_targets[0]["message"])
    kept = [t["joint"] for t in manifest.cabinets[0]["targets"]]
    assert kept == joints[1:]
    reloaded = load_manifest(out)
    assert reloaded.excluded_targets == manifest.excluded_targets
    stored = json.loads(info_path.read_text())["feasibility"]
    assert [t["joint"] for t in stored["targets"] if not t["feasible"]] == [jammed]
