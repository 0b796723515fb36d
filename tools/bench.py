"""`make bench`: every benchmark, written to BENCHMARKS.md with machine, versions and date.

Sections (each a subprocess, so that its peak memory can be read):
  assets  - tools/bench_assets.py: build seconds per cabinet cold / cached, hulls, mj_step of cabinets
  hands   - tools/bench_hands.py: steps/s of each hand alone and grasping
  task    - tools/bench_task.py: recorded episodes through the Task vs raw mj_step (ratio), real-time
            factors of the Task, the episode loop and whole episodes, RGB / depth frames/s; at the
            default physics timestep (1/480 s) and at 1/120 s
  episodes- here: episodes/min with 1 and 2 workers (scaling); success, contact penetration and speed
            at three physics timesteps; handle solver inference ms per image
  envs    - tools/bench_env.py: raw mj_step ceiling, state steps/s and their ratio to it, the
            shared-memory vector env with 1 and 2 processes, RGB-D at 128 and 256 against the renderer
            (interleaved chunks, wall and CPU time)
  demos   - tools/bench_demos.py: demonstrations recorded per minute (1 and 2 workers), bytes per
            demonstration, training samples per second and the peak memory of training
  agents  - tools/bench_agent_channel.py: the agent channel's round trip per step beside the physics
            step, and the BC policy's act in its own process and in the simulator's

    python tools/bench.py [--quick] [--sections assets,hands,task,episodes,envs,demos,agents] [--out BENCHMARKS.md]
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import opend_mj  # noqa: E402,F401  (off-screen EGL before mujoco loads)

ROOT = Path(__file__).resolve().parents[1]
PY = sys.executable


def _run(args: list[str]) -> tuple[str, float, float]:
    """Run a section; return its stdout, wall seconds and the peak RSS (MiB) of its processes."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    start = time.perf_counter()
    proc = subprocess.run([PY, *args], cwd=ROOT, capture_output=True, text=True,
                          env={**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")})
    seconds = time.perf_counter() - start
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    if proc.returncode != 0:
        print(proc.stdout[-3000:], proc.stderr[-3000:], file=sys.stderr)
        raise SystemExit(f"benchmark section {' '.join(args)} failed with exit code {proc.returncode}")
    return proc.stdout, seconds, max(peak, before) / 1024.0


def _tables(text: str) -> str:
    """Keep the Markdown tables and headings a section printed (drop progress lines)."""
    keep = [ln for ln in text.splitlines() if ln.startswith(("|", "#", "(", "procedural:", "mj_step"))]
    return "\n".join(keep)


def _run_timed(jobs, workers: int) -> tuple[list[dict], float]:
    from opend_mj.evaluation.pool import run_jobs
    from opend_mj.evaluation.results import load_results

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "r.jsonl"
        start = time.perf_counter()
        run_jobs(jobs, out, workers=workers, progress=False)
        seconds = time.perf_counter() - start
        return load_results(out), seconds


def episodes_section(cabinets: Path, n_episodes: int, repeats: int) -> str:
    """Oracle episodes (allegro): workers scaling, physics timesteps, solver inference."""
    from opend_mj.evaluation.jobs import make_jobs

    jobs = make_jobs(cabinets, ["allegro"], "oracle", split="test", limit=n_episodes)
    rates = {1: [], 2: []}
    for workers in (1, 2):
        for _ in range(repeats):
            records, seconds = _run_timed(jobs, workers)
            rates[workers].append(len(records) / seconds * 60)
    med1, med2 = statistics.median(rates[1]), statistics.median(rates[2])
    lines = [f"Oracle episodes, allegro, first {len(jobs)} test targets, median of {repeats} runs each "
             "(everything `opend run` does: scene build, the one RGB-D frame, the planner; episodes of one "
             "cabinet share its scene; each worker process's first episode also pays for its imports, "
             "about 2 s, which is why a short run scales worse).", "",
             "| figure | value |", "|---|---:|",
             f"| episodes/min, 1 worker | {med1:.1f} |",
             f"| episodes/min, 2 workers | {med2:.1f} |",
             f"| scaling 2 workers / 1 | {med2 / med1:.2f}x |", ""]

    lines += ["### Physics timestep: speed against contact softness", "",
              f"The same {len(jobs)} oracle episodes (allegro, 1 worker) at three physics timesteps "
              "(`opend run --physics-timestep`). MuJoCo keeps a contact's time constant at least two "
              "timesteps, so coarser steps make the contacts softer: the penetration columns show how much.", "",
              "| physics timestep | substeps / control step | successes | episodes/min | real-time factor, "
              "whole episode | median of max penetration, mm | worst penetration, mm |",
              "|---|---:|---:|---:|---:|---:|---:|"]
    for denominator in (480, 240, 120):
        tjobs = [replace(j, physics_timestep=None if denominator == 480 else 1 / denominator) for j in jobs]
        records, seconds = _run_timed(tjobs, 1)
        pen = [r["max_penetration_mm"] for r in records if r.get("max_penetration_mm") is not None]
        sim = sum(r.get("sim_seconds") or 0 for r in records)
        default = " (default)" if denominator == 480 else ""
        lines.append(f"| 1/{denominator} s{default} | {denominator // 60} "
                     f"| {sum(bool(r.get('success')) for r in records)} / {len(records)} "
                     f"| {len(records) / seconds * 60:.0f} | {sim / seconds:.1f}x "
                     f"| {statistics.median(pen):.2f} | {max(pen):.2f} |")
    lines.append("")
    lines += _inference_lines(cabinets)
    return "\n".join(lines)


def _inference_lines(cabinets: Path) -> list[str]:
    """Milliseconds per image of each shipped learned solver (CPU), on one rendered test image."""
    from opend_mj.sim.camera import RGBDCamera
    from opend_mj.assets.layout import load_manifest
    from opend_mj.policy.solvers import get_solver
    from opend_mj.sim.task import EpisodeSpec, TaskConfig, make_environment

    cab, tgt = load_manifest(cabinets).targets("test")[0]
    env = make_environment(EpisodeSpec(cabinets / cab["path"], tgt["joint"], "allegro"), TaskConfig(enable_rgbd=False))
    env.reset()
    with RGBDCamera(env.physics, "front", 256, 256) as cam:
        rgb, depth = cam.render()
    view = env.task.camera_view(env.physics)
    rows = ["### Handle solver inference (CPU, 256 x 256, one image at a time)", "",
            "| solver | ms per image (median of 10, after one warm-up) |", "|---|---:|"]
    for name in ("cliport", "fasterrcnn"):
        try:
            solver = get_solver(name)
        except Exception as exc:  # noqa: BLE001 (no checkpoint: say so, do not fail the benchmark)
            rows.append(f"| {name} | unavailable: {exc} |")
            continue
        solver.solve(rgb, depth, env.task.instruction, view)
        times = []
        for _ in range(10):
            start = time.perf_counter()
            solver.solve(rgb, depth, env.task.instruction, view)
            times.append((time.perf_counter() - start) * 1000)
        rows.append(f"| {name} | {statistics.median(times):.0f} |")
    env.close()
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=ROOT / "BENCHMARKS.md")
    parser.add_argument("--cabinets", type=Path, default=ROOT / "cabinets")
    parser.add_argument("--sections", default="assets,hands,task,episodes,envs,demos,agents")
    parser.add_argument("--quick", action="store_true", help="smaller counts (a few minutes in all)")
    args = parser.parse_args()
    sections = [s.strip() for s in args.sections.split(",") if s.strip()]
    quick = args.quick
    load_before = os.getloadavg()

    import mujoco
    import numpy

    versions = {"python": platform.python_version(), "mujoco": mujoco.__version__, "numpy": numpy.__version__}
    for name in ("dm_control", "torch", "coacd", "trimesh"):
        try:
            versions[name] = __import__(name).__version__
        except Exception:
            pass
    try:
        cpu = next(ln.split(":", 1)[1].strip() for ln in open("/proc/cpuinfo") if ln.startswith("model name"))
    except (OSError, StopIteration):
        cpu = platform.processor()
    header = [
        "# Benchmarks", "",
        f"Written by `make bench` (`python tools/bench.py{' --quick' if quick else ''}`) on "
        f"{datetime.date.today().isoformat()}.", "",
        f"- machine: {cpu}, {os.cpu_count()} cores, {platform.system()} {platform.release()}",
        "- versions: " + ", ".join(f"{k} {v}" for k, v in versions.items()),
        "- rendering: MuJoCo EGL through Mesa llvmpipe (no GPU)", "",
        "Figures are medians over cabinets / repeated runs; wall-clock figures depend on the machine's load.",
        "",
    ]
    body = []
    if "assets" in sections:
        count = "60" if quick else "346"
        out, secs, mem = _run(["tools/bench_assets.py", "--out", "build/bench-cabinets", "--count", count])
        body += [f"## Asset build ({count} procedural sources + the real cabinet 45780)", "", _tables(out), "",
                 f"Section wall time {secs:.0f} s, peak memory of one process {mem:.0f} MiB.", ""]
    if "hands" in sections:
        out, secs, mem = _run(["tools/bench_hands.py", "--seconds", "2" if quick else "4"])
        body += ["## Hands", "", _tables(out), "", f"Peak memory {mem:.0f} MiB.", ""]
    if "task" in sections:
        body += ["## Task", ""]
        for timestep in ("1/480", "1/120"):
            out, secs, mem = _run(["tools/bench_task.py", "--cabinets", str(args.cabinets), "--count",
                                   "3" if quick else "8", "--timestep", timestep])
            body += [_tables(out), ""]
        body += [f"Peak memory {mem:.0f} MiB.", ""]
    if "episodes" in sections:
        before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        text = episodes_section(args.cabinets, 6 if quick else 48, 1 if quick else 3)
        mem = max(before, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
                  resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss) / 1024.0
        body += ["## Episodes", "", text, "", f"Peak memory of one process {mem:.0f} MiB.", ""]
    if "envs" in sections:
        out, secs, mem = _run(["tools/bench_env.py", "--cabinets", str(args.cabinets),
                               "--steps", "300" if quick else "1500", "--image-steps", "100" if quick else "300"])
        body += ["## Environments (gymnasium)", "", _tables(out), "", f"Peak memory {mem:.0f} MiB.", ""]
    if "demos" in sections:
        out, secs, mem = _run(["tools/bench_demos.py", "--cabinets", str(args.cabinets),
                               "--episodes", "8" if quick else "24"])
        body += [out.strip(), ""]  # the section as tools/bench_demos.py prints it
    if "agents" in sections:
        out, secs, mem = _run(["tools/bench_agent_channel.py", "--cabinets", str(args.cabinets),
                               "--steps", "500" if quick else "2000"])
        body += [out.strip(), ""]  # the section as tools/bench_agent_channel.py prints it
    load_after = os.getloadavg()
    header.insert(-1, f"Load average (1 min) when the run started / ended: {load_before[0]:.2f} / {load_after[0]:.2f} "
                      f"on {os.cpu_count()} cores: above about 1, other work shared the cores and the worker "
                      "scaling figures understate what an idle machine gives.")
    header.insert(-1, "")
    args.out.write_text("\n".join(header + body) + "\n")
    print(args.out.read_text())


if __name__ == "__main__":
    main()
