"""The data shipped with the package: the built-in hands and the trained checkpoints.

The repository's top-level ``hands/`` and ``checkpoints/`` folders are their source. A wheel carries
copies as package data, ``opend_mj/_data/hands`` and ``opend_mj/_data/checkpoints`` (``setup.py``
copies them at build time); a clone (an editable install, or ``src`` on ``PYTHONPATH``) has no
``_data`` and reads the top-level folders. This module is the only one that knows either layout:
everything else asks it for a folder or a file. MuJoCo and torch read files by path, so the package
must be installed as files (not imported from a zip archive).
"""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path

#: The kinds of shipped data, each a folder of the repository and of ``opend_mj/_data``.
KINDS = ("hands", "checkpoints")


def package_dir() -> Path:
    """The folder of the imported ``opend_mj`` package."""
    root = resources.files("opend_mj")
    if not isinstance(root, Path):
        raise RuntimeError(f"opend_mj is imported from {root}, not from files: install it unzipped")
    return root.resolve()


def _candidates(kind: str) -> tuple[Path, Path]:
    """(inside the installed package, in a clone) for ``kind``."""
    if kind not in KINDS:
        raise ValueError(f"unknown kind of shipped data {kind!r}; known: {', '.join(KINDS)}")
    package = package_dir()
    return package / "_data" / kind, package.parents[1] / kind  # a clone: <root>/src/opend_mj


def data_dir(kind: str) -> Path:
    """The folder of the shipped ``kind`` ("hands" or "checkpoints"): the package's copy where it has
    one (an installed wheel), else the clone's top-level folder. Raises FileNotFoundError naming both
    places when neither exists (a broken install)."""
    packaged, checkout = _candidates(kind)
    if packaged.is_dir():
        return packaged
    if checkout.is_dir() and (checkout.parent / "pyproject.toml").is_file():
        return checkout
    raise FileNotFoundError(f"no shipped {kind}: neither {packaged} (installed package) nor {checkout} "
                            "(a clone of opend-mj) exists; reinstall the package")


def hands_dir() -> Path:
    """The folder of the built-in hands (``<name>/hand.xml``, ``spec.json``, ...)."""
    return data_dir("hands")


def shipped_checkpoint(name: str) -> Path:
    """The shipped checkpoint file ``name`` (e.g. ``fasterrcnn.pt``); it may not exist."""
    return data_dir("checkpoints") / name


def default_checkpoint(name: str) -> Path:
    """The checkpoint a solver or policy loads when none is given: ``checkpoints/<name>`` in the
    current folder where there is one (where ``opend train`` and ``opend train-policy`` write by
    default), else the shipped one."""
    here = Path("checkpoints") / name
    return here if here.is_file() else shipped_checkpoint(name)


def in_package(path: str | os.PathLike) -> bool:
    """Whether ``path`` lies inside the installed package's folder (nothing may be written there)."""
    return Path(path).resolve().is_relative_to(package_dir())


__all__ = ["KINDS", "data_dir", "default_checkpoint", "hands_dir", "in_package", "package_dir", "shipped_checkpoint"]
