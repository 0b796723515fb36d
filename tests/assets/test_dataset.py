"""The dataset stage: parallel build, manifest, deterministic split by cabinet, the CLI."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner

from opend_mj.cli import main
from opend_mj.assets.config import DatasetConfig
from opend_mj.assets.dataset import assign_split, build_dataset, format_split_table, list_sources
from opend_mj.assets.layout import MANIFEST, load_manifest, split_table

N = 12


@pytest.fixture(scope="module")
def sources(proc_sources) -> list[Path]:
    return proc_sources[:N]


@pytest.fixture(scope="module")
def built(sources, tmp_path_factory):
    out = tmp_path_factory.mktemp("dataset")
    # in this process: the process pool is tested by test_cli_build_assets and test_bad_inputs
    manifest = build_dataset(sources, out, workers=1, progress=False, log=lambda *a: None)
    return out, manifest


def _meta(source: Path) -> dict:
    return json.loads((source / "meta.json").read_text())["procedural"]


def test_manifest_lists_every_source(built, sources):
    out, manifest = built
    on_disk = json.loads((out / MANIFEST).read_text())
    built_ids = [c["id"] for c in on_disk["cabinets"]]
    rejected_ids = [r["id"] for r in on_disk["rejected"]]
    assert sorted(built_ids + rejected_ids) == sorted(s.name for s in sources)
    assert not set(built_ids) & set(rejected_ids)
    # The generator knows which of its cabinets the language rule can describe: exactly those build.
    assert sorted(built_ids) == sorted(s.name for s in sources if _meta(s)["describable"])
    assert built_ids and rejected_ids
    assert on_disk["info"]["sources"] == N
    assert on_disk["info"]["built"] + on_disk["info"]["cached"] == len(built_ids)


def test_rejections_have_reasons(built):
    _, manifest = built
    for r in manifest.rejected:
        assert r["reason"] == "language_invalid", r
        assert r["id"] in r["message"] and r["message"]


def test_manifest_targets(built, sources):
    out, manifest = built
    by_id = {s.name: s for s in sources}
    for cab in manifest.cabinets:
        assert (out / cab["path"] / "cabinet.xml").is_file()
        info = json.loads((out / cab["path"] / "cabinet.json").read_text())
        assert [t["joint"] for t in cab["targets"]] == [t["joint"] for t in info["targets"]]
        meta = {t["joint"]: t for t in _meta(by_id[cab["id"]])["targets"]}
        assert sorted(meta) == sorted(t["joint"] for t in cab["targets"]), "every door and drawer is a target"
        for t in cab["targets"]:
            assert t["type"] == meta[t["joint"]]["type"]
            assert t["instruction"].endswith(t["type"])
            assert t["handle_orientation"] in ("horizontal", "vertical")
        instructions = [t["instruction"] for t in cab["targets"]]
        assert len(set(instructions)) == len(instructions), "targets of one cabinet read differently"
        assert cab["split"] in ("train", "test")
        assert cab["hulls"] == info["stats"]["hulls"] > 0


def test_load_manifest_round_trip(built):
    out, manifest = built
    loaded = load_manifest(out)
    assert loaded.cabinets == manifest.cabinets and loaded.rejected == manifest.rejected
    train, test = loaded.targets("train"), loaded.targets("test")
    assert len(train) + len(test) == len(loaded.targets("all"))
    assert all(c["split"] == "train" for c, _ in train) and all(c["split"] == "test" for c, _ in test)
    with pytest.raises(FileNotFoundError, match="build-assets"):
        load_manifest(out / "nowhere")


def test_split_by_cabinet_with_the_configured_fraction(built):
    _, manifest = built
    ids = [c["id"] for c in manifest.cabinets]
    n_test = sum(c["split"] == "test" for c in manifest.cabinets)
    assert n_test == round(DatasetConfig().test_fraction * len(ids))


def test_split_is_deterministic_and_order_free():
    ids = [f"cab_{i:03d}" for i in range(200)]
    split = assign_split(ids, 0.224, 0)
    assert assign_split(ids[::-1], 0.224, 0) == split
    assert assign_split(sorted(ids, key=hash), 0.224, 0) == split
    assert sum(v == "test" for v in split.values()) == round(0.224 * 200)
    assert assign_split(ids, 0.224, 1) != split, "the split seed changes the split"
    # A cabinet's split depends on the other ids only through the test count: adding one more
    # cabinet moves at most one cabinet across.
    more = assign_split(ids + ["cab_999"], 0.224, 0)
    assert sum(more[i] != split[i] for i in ids) <= 1


def test_build_order_does_not_change_split(built, sources):
    out, manifest = built
    again = build_dataset(sources[::-1], out, workers=1, progress=False, log=lambda *a: None)
    assert again.info["built"] == 0 and again.info["cached"] == len(manifest.cabinets)
    assert {c["id"]: c["split"] for c in again.cabinets} == {c["id"]: c["split"] for c in manifest.cabinets}


def test_split_table_counts(built):
    _, manifest = built
    table = split_table(manifest.cabinets)
    for split in ("train", "test"):
        cabs = [c for c in manifest.cabinets if c["split"] == split]
        ts = [t for c in cabs for t in c["targets"]]
        assert table["cabinets"][split] == len(cabs)
        assert table["drawers"][split] == sum(t["type"] == "drawer" for t in ts)
        assert table["doors"][split] == sum(t["type"] == "door" for t in ts)
        assert table["targets"][split] == len(ts)
    for row in table.values():
        assert row["total"] == row["train"] + row["test"]
    assert table["targets"]["total"] == table["drawers"]["total"] + table["doors"]["total"]
    assert json.loads((_ := built[0] / MANIFEST).read_text())["summary"] == table


def test_split_table_by_hand():
    cabinets = [
        {"id": "a", "split": "train", "targets": [{"type": "drawer"}, {"type": "door"}, {"type": "door"}]},
        {"id": "b", "split": "test", "targets": [{"type": "drawer"}]},
        {"id": "c", "split": "train", "targets": [{"type": "drawer"}]},
    ]
    table = split_table(cabinets)
    assert table["cabinets"] == {"train": 2, "test": 1, "total": 3}
    assert table["drawers"] == {"train": 2, "test": 1, "total": 3}
    assert table["doors"] == {"train": 2, "test": 0, "total": 2}
    assert table["targets"] == {"train": 4, "test": 1, "total": 5}
    text = format_split_table(table)
    assert "| drawers  |     2 |    1 |     3 |" in text
    assert "| cabinets |     2 |    1 |     3 |" in text


def test_list_sources(sources, tmp_path):
    root = sources[0].parent
    listed = list_sources(root)
    assert [p.name for p in listed][:N] == [s.name for s in sources]
    assert [p.name for p in list_sources(root, [sources[3].name, sources[1].name])] == [
        sources[1].name, sources[3].name]
    with pytest.raises(FileNotFoundError):
        list_sources(root, ["no_such_id"])
    with pytest.raises(FileNotFoundError):
        list_sources(tmp_path / "missing")


@pytest.mark.slow
def test_cli_build_assets(tmp_path):
    out = tmp_path / "cabinets"
    result = CliRunner().invoke(main, ["build-assets", "--count", str(N), "--out", str(out), "--workers", "2",
                                       "--no-progress"])
    assert result.exit_code == 0, result.output
    manifest = json.loads((out / MANIFEST).read_text())
    assert manifest["info"]["sources"] == N
    assert f"cabinets valid of {N} sources" in result.output
    assert format_split_table(manifest["summary"]) in result.output
    assert "| drawers  |" in result.output and "| cabinets |" in result.output
    # A second run is all cached.
    again = CliRunner().invoke(main, ["build-assets", "--count", str(N), "--out", str(out), "--workers", "1",
                                      "--no-progress"])
    assert again.exit_code == 0, again.output
    assert f"0 built, {len(manifest['cabinets'])} cached" in again.output


def test_cli_fails_when_nothing_builds(sources, tmp_path):
    broken = tmp_path / "broken"
    for i, src in enumerate(sources[:2]):
        copy = shutil.copytree(src, broken / f"bad_{i}")
        (copy / "mobility.urdf").unlink()
    result = CliRunner().invoke(main, ["build-assets", "--source", str(broken), "--out", str(tmp_path / "out"),
                                       "--workers", "1", "--no-progress"])
    assert result.exit_code != 0
    assert "no cabinet was built" in result.output
    assert "urdf_error 2" in result.output


def test_cli_rejects_a_missing_source_folder(tmp_path):
    result = CliRunner().invoke(main, ["build-assets", "--source", str(tmp_path / "nope"), "--out",
                                       str(tmp_path / "out"), "--no-progress"])
    assert result.exit_code == 2
    assert "does not exist" in result.output


def test_cli_cache_dir_reaches_the_build(tmp_path, monkeypatch):
    """`--cache-dir` is the decomposition cache the build uses (default: the user cache dir)."""
    import opend_mj.assets.dataset as dataset

    seen = []
    real = dataset.build_dataset

    def spy(*args, **kwargs):
        seen.append(kwargs.get("cache_dir"))
        return real(*args, **kwargs)

    monkeypatch.setattr(dataset, "build_dataset", spy)
    cache = tmp_path / "decompositions"
    result = CliRunner().invoke(main, ["build-assets", "--count", "2", "--out", str(tmp_path / "out"),
                                       "--workers", "1", "--no-progress", "--cache-dir", str(cache)])
    assert result.exit_code == 0, result.output
    assert seen == [cache]
    result = CliRunner().invoke(main, ["build-assets", "--count", "2", "--out", str(tmp_path / "out2"),
                                       "--workers", "1", "--no-progress"])
    assert result.exit_code == 0, result.output
    assert seen[1] is None
