"""opend_mj.resources: where the shipped hands and checkpoints are found (a clone here; an installed
wheel in tests/test_wheel.py), and that no other module locates files from the package's own path."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from click.testing import CliRunner

from opend_mj import resources

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "src" / "opend_mj"


def test_a_clone_reads_its_top_level_folders():
    from opend_mj.sim.hands import HANDS_DIR, get_hand

    assert resources.data_dir("hands") == HANDS_DIR == ROOT / "hands"
    assert resources.data_dir("checkpoints") == ROOT / "checkpoints"
    assert get_hand("allegro").folder == ROOT / "hands" / "allegro"
    assert not resources.in_package(get_hand("allegro").grasp_file)
    with pytest.raises(ValueError, match="unknown kind"):
        resources.data_dir("weights")


def test_every_default_checkpoint_is_shipped():
    from opend_mj.policy.learned.affordance import DEFAULT_CHECKPOINT as CLIPORT
    from opend_mj.policy.learned.detector import DEFAULT_CHECKPOINT, SENSOR_CHECKPOINT
    from opend_mj.sim.hands import builtin_hands

    names = [DEFAULT_CHECKPOINT, SENSOR_CHECKPOINT, CLIPORT, *(f"bc_{h}.pt" for h in builtin_hands())]
    assert [n for n in names if not resources.shipped_checkpoint(n).is_file()] == []


def test_the_packaged_copy_comes_first_and_a_broken_install_is_named(tmp_path, monkeypatch):
    package = tmp_path / "site-packages" / "opend_mj"
    (package / "_data" / "hands").mkdir(parents=True)
    monkeypatch.setattr(resources, "package_dir", lambda: package)
    assert resources.data_dir("hands") == package / "_data" / "hands"
    assert resources.in_package(package / "_data" / "hands" / "allegro" / "grasp.json")
    with pytest.raises(FileNotFoundError, match="neither .*_data/checkpoints .* nor .*checkpoints"):
        resources.data_dir("checkpoints")  # no _data/checkpoints, and site-packages is no clone


def test_a_checkpoint_in_the_current_folder_comes_before_the_shipped_one(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert resources.default_checkpoint("fasterrcnn.pt") == ROOT / "checkpoints" / "fasterrcnn.pt"
    (tmp_path / "checkpoints").mkdir()
    (tmp_path / "checkpoints" / "fasterrcnn.pt").write_bytes(b"")
    assert resources.default_checkpoint("fasterrcnn.pt") == Path("checkpoints") / "fasterrcnn.pt"


def test_search_grasp_does_not_write_into_the_installed_package(tmp_path, monkeypatch):
    from opend_mj.cli import main
    from opend_mj.sim.hands import HANDS_DIR

    monkeypatch.setattr(resources, "package_dir", lambda: HANDS_DIR.parent)  # the hands as if installed
    result = CliRunner().invoke(main, ["search-grasp", "--hand", "franka", "--cabinets", str(tmp_path)])
    assert result.exit_code == 2
    assert "inside the installed package" in result.output and "--out" in result.output


def test_only_the_resolver_knows_where_the_package_lies():
    """No module finds files from its own ``__file__`` (the source tree's layout); importlib.resources
    and opend_mj.resources do."""
    own_file = re.compile(r"(?<![\w.])__file__\b")
    users = sorted(str(p.relative_to(PACKAGE)) for p in PACKAGE.rglob("*.py") if own_file.search(p.read_text()))
    assert users == []
    assert "PROJECT_ROOT" not in "".join(p.read_text() for p in PACKAGE.rglob("*.py"))
