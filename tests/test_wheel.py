"""The wheel as a pip user gets it: built from the sources, installed into a fresh virtual environment,
and run from an empty folder (the hands and checkpoints come from the package, outputs go to the
current folder and the user cache, nothing is written into the package).

The fresh environment reuses this one's installed dependencies through a ``.pth`` file (no download);
only the wheel is installed into it, with ``--no-deps --no-index``.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from email.parser import Parser
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
REPOSITORY = "https://github.com/opend-mj/opend-mj"
RAW = "https://raw.githubusercontent.com/opend-mj/opend-mj/main"
#: What a wheel is built from (an sdist holds the same: MANIFEST.in).
BUILD_INPUTS = ("pyproject.toml", "setup.py", "MANIFEST.in", "README.md", "src", "hands", "checkpoints")
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")


def _run(cmd, cwd, env, timeout=300) -> str:
    proc = subprocess.run([str(c) for c in cmd], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, f"{' '.join(map(str, cmd))} exited {proc.returncode}:\n{proc.stdout}\n{proc.stderr}"
    return proc.stdout


def build_wheel(dest: Path, work: Path) -> Path:
    """The wheel built from a copy of the build inputs (so the repository's own build/ and stale files
    play no part)."""
    source = work / "source"
    for name in BUILD_INPUTS:
        if (ROOT / name).is_dir():
            shutil.copytree(ROOT / name, source / name,
                            ignore=shutil.ignore_patterns("__pycache__", "*.egg-info", "_data"))
        else:
            source.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, source / name)
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", source, "-w", dest],
         cwd=work, env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"})
    (wheel,) = dest.glob("opend_mj-*.whl")
    return wheel


def fresh_venv(folder: Path) -> Path:
    """A virtual environment whose own site-packages is empty but that sees this interpreter's
    installed packages after its own (a ``.pth`` line); returns its python."""
    _run([sys.executable, "-m", "venv", "--without-pip", folder], cwd=folder.parent, env=dict(os.environ))
    python = folder / "bin" / "python"
    own = Path(_run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                    cwd=folder, env=dict(os.environ)).strip())
    ours = dict.fromkeys([sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]])
    (own / "opend_test_deps.pth").write_text("".join(f"{p}\n" for p in ours))
    return python


def package_files(package: Path) -> dict[str, tuple[int, int]]:
    """(size, mtime in ns) of every file in the installed package but Python's bytecode caches."""
    return {str(p.relative_to(package)): (p.stat().st_size, p.stat().st_mtime_ns) for p in package.rglob("*")
            if p.is_file() and "__pycache__" not in p.parts}


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    work = tmp_path_factory.mktemp("wheel")
    return build_wheel(work / "dist", work)


@pytest.mark.slow
def test_metadata_readme_links_are_absolute_and_exist(wheel):
    """Every link of the package page's README is absolute, and each one into the repository names a
    file that exists here."""
    with zipfile.ZipFile(wheel) as archive:
        metadata = archive.read(next(n for n in archive.namelist() if n.endswith(".dist-info/METADATA")))
    message = Parser().parsestr(metadata.decode())
    readme = message.get_payload()
    assert message["Description-Content-Type"] == "text/markdown"
    assert readme.startswith("# opend-mj")
    assert "Programming Language :: Python :: 3.11" in message.get_all("Classifier")
    links = LINK.findall(readme)
    assert len(links) > 10
    relative = [t for t in links if not re.match(r"https?://", t)]
    assert relative == []
    missing = []
    for target in links:
        for prefix in (f"{REPOSITORY}/blob/main/", f"{RAW}/"):
            if target.startswith(prefix) and not (ROOT / target[len(prefix):].partition("#")[0]).exists():
                missing.append(target)
    assert missing == []


@pytest.mark.slow
def test_installed_wheel_runs_from_an_empty_folder(wheel, tmp_path):
    """Install into a fresh venv, then from an empty folder: build-assets, run (oracle, fasterrcnn,
    --policy bc), score; hands and checkpoints from the package, no file written in it."""
    with zipfile.ZipFile(wheel) as archive:
        names = set(archive.namelist())
    for hand in ("franka", "allegro", "shadow", "skeleton"):
        assert {f"opend_mj/_data/hands/{hand}/{f}" for f in ("hand.xml", "spec.json", "scene.xml")} <= names
    for name in ("fasterrcnn.pt", "fasterrcnn_sensor.pt", "cliport.pt", "bc_allegro.pt", "bc_allegro.md"):
        assert f"opend_mj/_data/checkpoints/{name}" in names
    assert "opend_mj/sim/fast/step.c" in names
    assert not any("build_hands" in n for n in names)

    python = fresh_venv(tmp_path / "venv")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "OPEND_CACHE_DIR")}
    env.update(XDG_CACHE_HOME=str(tmp_path / "cache"), MUJOCO_GL="egl", OPEND_DEBUG="1")
    _run([python, "-m", "pip", "install", "--no-deps", "--no-index", "-q", wheel], cwd=tmp_path, env=env)
    work = tmp_path / "empty"
    work.mkdir()
    where = json.loads(_run([python, "-c", "import json, opend_mj, opend_mj.resources as r; print(json.dumps("
                             "[opend_mj.__file__, str(r.hands_dir()), str(r.default_checkpoint('bc_allegro.pt'))]))"],
                            cwd=work, env=env))
    package = Path(where[0]).parent
    assert package.is_relative_to(tmp_path / "venv")
    assert Path(where[1]) == package / "_data" / "hands"
    assert Path(where[2]) == package / "_data" / "checkpoints" / "bc_allegro.pt"
    before = package_files(package)

    opend = tmp_path / "venv" / "bin" / "opend"
    log = [f"wheel {wheel.name}: {wheel.stat().st_size / 1e6:.1f} MB"]
    log.append(_run([opend, "build-assets", "--count", "10", "--workers", "1", "--no-progress"], cwd=work, env=env))
    manifest = json.loads((work / "cabinets" / "manifest.json").read_text())
    assert manifest["summary"]  # the default output folder is ./cabinets
    runs = {"oracle": ["--solver", "oracle", "--limit", "1"], "fasterrcnn": ["--solver", "fasterrcnn", "--limit", "2"],
            "bc": ["--policy", "bc", "--limit", "1"]}
    for name, args in runs.items():
        log.append(_run([opend, "run", "--hand", "allegro", *args, "--out", f"{name}.jsonl"], cwd=work, env=env))
    records = {name: [json.loads(line) for line in (work / f"{name}.jsonl").read_text().splitlines()] for name in runs}
    assert {name: len(r) for name, r in records.items()} == {"oracle": 1, "fasterrcnn": 2, "bc": 1}
    assert not any(r.get("error") for rs in records.values() for r in rs)
    scores = _run([opend, "score", *(f"{name}.jsonl" for name in runs)], cwd=work, env=env)
    log.append(scores)
    for solver in ("oracle", "fasterrcnn", "bc"):
        assert f"| allegro | {solver}" in scores

    assert package_files(package) == before, "a command wrote into the installed package"
    if shutil.which(os.environ.get("CC", "cc")):  # the compiled control step went to the user cache
        assert list((tmp_path / "cache" / "opend-mj" / "faststep").glob("*/faststep.so"))
    print("\n".join(log))
