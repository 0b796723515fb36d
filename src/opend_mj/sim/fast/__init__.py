"""The control step in compiled code: `step.c`, built on first use and loaded with ctypes.

The step of the environments (`OpenDCore.step`) and of the Task (`OpenCabinetTask.before_step` +
`fast_substeps`, what `opend run` drives) runs in one C call per control step when this library
loads; the Python step stays as the reference it is tested against (the same numbers, to the bit)
and as the fallback.

Building: the system C compiler (``$CC``, else ``cc``) compiles `step.c` against the headers and
the ``libmujoco.so`` that the installed ``mujoco`` wheel ships, into a per-user cache
(``$XDG_CACHE_HOME/opend-mj/faststep/<hash>/``, default ``~/.cache``; the hash covers the source,
the mujoco version and library path, and the compiler), once per machine and version. Loading
checks that the library's dot product and libm's sin and cos give numpy's numbers (the Python step
uses numpy's ``a.dot(b)``, ``np.sin`` and ``np.cos``); the dot product is numpy's own BLAS
``ddot`` where it can be found.

``OPEND_FASTSTEP=0`` in the environment turns the compiled step off (no warning). No compiler, a
failed compile or load, or a failed check: one warning per process naming the reason, and the
Python step.
"""

from __future__ import annotations

import ctypes
import hashlib
import math
import os
import shutil
import subprocess
import tempfile
import warnings
from importlib import resources
from pathlib import Path

import numpy as np

#: package data (pyproject.toml), read where the package is installed
SOURCE = Path(str(resources.files(__name__) / "step.c"))
ENV_VAR = "OPEND_FASTSTEP"

_loaded: tuple | None = None  # (library or None, why not)


class FastStepWarning(RuntimeWarning):
    """The compiled step could not be used; the Python step runs instead (same numbers, slower)."""


def cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "opend-mj" / "faststep"


def _mujoco_paths() -> tuple[Path, Path, str]:
    """(include folder, libmujoco.so path, version) of the installed mujoco wheel."""
    import mujoco

    root = Path(mujoco.__file__).parent
    include = root / "include"
    libs = sorted(root.glob("libmujoco.so*")) or sorted(root.glob("libmujoco*.dylib"))
    if not (include / "mujoco" / "mujoco.h").is_file() or not libs:
        raise FileNotFoundError(f"the mujoco wheel at {root} has no include/mujoco/mujoco.h or libmujoco.so")
    return include, libs[-1], mujoco.__version__


def build(out_dir: Path | None = None) -> Path:
    """Compile `step.c` (if not cached) and return the shared library's path. Raises on failure."""
    compiler = os.environ.get("CC", "cc")
    if shutil.which(compiler) is None:
        raise FileNotFoundError(f"no C compiler {compiler!r} on PATH (set CC)")
    include, libmujoco, version = _mujoco_paths()
    source = SOURCE.read_bytes()
    key = hashlib.sha256(source + f"|{version}|{libmujoco}|{compiler}".encode()).hexdigest()[:16]
    folder = (out_dir or cache_dir()) / key
    target = folder / "faststep.so"
    if target.is_file():
        return target
    folder.mkdir(parents=True, exist_ok=True)
    # -ffp-contract=off: no fused multiply-adds (Python rounds each product); no -ffast-math
    fd, tmp = tempfile.mkstemp(suffix=".so", dir=folder)
    os.close(fd)
    cmd = [compiler, "-O2", "-shared", "-fPIC", "-std=c11", "-ffp-contract=off", "-fno-fast-math",
           f"-I{include}", str(SOURCE), "-o", tmp, str(libmujoco), f"-Wl,-rpath,{libmujoco.parent}", "-lm"]
    try:
        result = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
        if result.returncode != 0:
            raise RuntimeError(f"{' '.join(cmd)} failed:\n{result.stderr.strip()}")
        os.replace(tmp, target)  # atomic: parallel workers may build at once
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return target


def _blas_ddot() -> tuple[int, int]:
    """(address, 1 if 64-bit integers) of the BLAS ddot numpy's dot calls, or (0, 0) if not found."""
    candidates = (("scipy_cblas_ddot64_", 1), ("cblas_ddot64_", 1), ("scipy_cblas_ddot", 0), ("cblas_ddot", 0))
    try:
        with open("/proc/self/maps") as maps:
            paths = {parts[-1] for parts in (line.split() for line in maps)
                     if len(parts) >= 6 and "blas" in Path(parts[-1]).name.lower()}
    except OSError:
        return 0, 0
    for path in sorted(paths):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for name, ilp64 in candidates:
            fn = getattr(lib, name, None)
            if fn is not None:
                return ctypes.cast(fn, ctypes.c_void_p).value, ilp64
    return 0, 0


def _check(lib) -> str | None:
    """Why the library's numbers would differ from the Python step's (None: they do not)."""
    from opend_mj.sim.fast.binding import Ctx

    rng = np.random.default_rng(7)
    xs = np.concatenate([rng.uniform(-1.0, 1.0, 2000), rng.uniform(-0.06, 0.06, 2000)]).tolist()
    if any(float(np.sin(x)) != math.sin(x) or float(np.cos(x)) != math.cos(x) for x in xs):
        return "numpy's float64 sin or cos differ from libm's on this machine"
    ctx = Ctx()
    address, ilp64 = _blas_ddot()
    options = ([(address, ilp64)] if address else []) + [(0, 0)]  # numpy's BLAS ddot, else a plain sum
    for ddot, wide in options:
        ctx.ddot, ctx.ddot_ilp64 = ddot or None, wide
        same = True
        for n in (3, 4) * 300:
            scale = 10.0 ** rng.uniform(-4, 2)
            a, b = rng.normal(size=n) * scale, rng.normal(size=n)
            if lib.ofs_dot(ctypes.byref(ctx), a.ctypes.data, b.ctypes.data, n) != float(a.dot(b)):
                same = False
                break
        if same:
            _check.ddot = (ddot, wide)
            return None
    return "the compiled dot product differs from numpy's (BLAS ddot not found)"


_check.ddot = (0, 0)


def _load():
    path = build()
    lib = ctypes.CDLL(str(path))
    for name, args in (("ofs_dot", [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int64]),
                       ("ofs_apply", [ctypes.c_void_p]), ("ofs_write_row", [ctypes.c_void_p, ctypes.c_int64]),
                       ("ofs_substeps", [ctypes.c_void_p, ctypes.c_int64]),
                       ("ofs_fill", [ctypes.c_void_p, ctypes.c_int64, ctypes.c_int64]),
                       ("ofs_env_step", [ctypes.c_void_p, ctypes.c_int64, ctypes.c_int64, ctypes.c_int64])):
        fn = getattr(lib, name)
        fn.argtypes = args
        fn.restype = ctypes.c_double if name == "ofs_dot" else (None if name == "ofs_write_row" else ctypes.c_int64)
    why = _check(lib)
    if why:
        raise RuntimeError(why)
    return lib


def library():
    """The loaded library, or None (``OPEND_FASTSTEP=0``, or it failed: warned once per process)."""
    global _loaded
    if os.environ.get(ENV_VAR, "1").strip().lower() in ("0", "false", "no", "off"):
        return None
    if _loaded is None:
        try:
            _loaded = (_load(), None)
        except Exception as exc:  # noqa: BLE001 - any failure means the Python step, never a crash
            _loaded = (None, f"{type(exc).__name__}: {exc}")
            warnings.warn(f"opend-mj: the compiled control step ({SOURCE.name}) is not available, the Python step "
                          f"runs instead (same results, slower): {_loaded[1]}", FastStepWarning, stacklevel=2)
    return _loaded[0]


def ddot_pointer() -> tuple[int, int]:
    """(address or 0, ilp64) of the dot product the loaded library was checked with."""
    return _check.ddot


def status() -> str:
    """A line saying whether the compiled step is in use, and why not."""
    if library() is not None:
        return "compiled step (step.c)"
    if os.environ.get(ENV_VAR, "1").strip().lower() in ("0", "false", "no", "off"):
        return f"Python step ({ENV_VAR}=0)"
    return f"Python step ({_loaded[1]})"


def _reset_for_tests() -> None:
    """Forget the loaded library (tests of the fallback)."""
    global _loaded
    _loaded = None
