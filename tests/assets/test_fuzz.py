"""The fuzzer (tools/fuzz.py) over cabinet sources and results files: a short seeded run here, a
long one with `make fuzz`. Every case ends built (and pushed open in its room) or refused in one
line naming its file, within its time limit; a hang ends the fuzzer with the stack where it hung."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
FUZZ = ROOT / "tools" / "fuzz.py"


def _fuzz(*args: str, timeout: float) -> str:
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src") + os.pathsep + os.environ.get("PYTHONPATH", "")}
    try:
        proc = subprocess.run([sys.executable, str(FUZZ), *args], capture_output=True, text=True, timeout=timeout,
                              env=env, cwd=ROOT)
    except subprocess.TimeoutExpired as exc:
        pytest.fail(f"the fuzzer hung past {timeout} s: {exc.stdout!s:.2000}")
    assert proc.returncode == 0, f"fuzz failures:\n{proc.stdout[-4000:]}\n{proc.stderr[-4000:]}"
    assert "Traceback" not in proc.stdout
    return proc.stdout


def _counts(out: str) -> dict[str, int]:
    return {f"{m[0]} {m[1]}": int(m[2]) for m in re.findall(r"^\| (source|results) \| ([^|]+?) \| (\d+) \|$", out,
                                                             re.MULTILINE)}


def test_fuzz_sources_and_results_files():
    out = _fuzz("--cases", "60", "--results-cases", "20", "--seed", "7", "--case-seconds", "60", timeout=300)
    assert "fuzz: 80 cases tried, 0 failed" in out, out
    counts = _counts(out)
    assert sum(counts.values()) == 80
    # the mutations reach every outcome: built cabinets, refusals of several kinds, scored and refused results
    assert counts.get("source built", 0) > 0
    assert sum(n for k, n in counts.items() if k.startswith("source refused")) > 0
    assert counts.get("results scored", 0) > 0 and any(k.startswith("results refused") for k in counts)


@pytest.mark.slow
def test_fuzz_a_real_source(real_source):
    """A few mutations of the PartNet-Mobility sample (real meshes, textures)."""
    out = _fuzz("--cases", "2", "--results-cases", "0", "--seed", "3", "--real", str(real_source),
                "--real-only", timeout=600)
    assert "fuzz: 2 cases tried, 0 failed" in out, out
