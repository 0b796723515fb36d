"""`make bench-demos`: demonstrations recorded per minute, bytes per demonstration, and training.

Records the planner's oracle episodes (allegro, generated cabinets, train split) with `opend demos`'
library function into temporary files, with 1 and 2 worker processes, then trains the
behaviour-cloning policy on the 1-worker file with `opend train-policy` (CPU, 1 thread, the default
model and batch, a few hundred steps) in a process of its own, whose peak resident memory is read
from the kernel (``wait4``). Prints a Markdown section; ``--write FILE`` also puts it into FILE
(BENCHMARKS.md) in place of its "## Demonstrations" section (added at the end where there is none),
so that the other sections stay as `make bench` wrote them.

    python tools/bench_demos.py [--cabinets cabinets] [--episodes 24] [--steps 500] [--write BENCHMARKS.md]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench_sections import write_section  # tools/, beside this script

import opend_mj  # noqa: F401  (off-screen EGL before mujoco loads)

ROOT = Path(__file__).resolve().parents[1]
TITLE = "## Demonstrations"


def record(cabinets: Path, out: Path, episodes: int, workers: int) -> tuple[dict, float]:
    """(counts of `record_demos`, wall seconds) of recording the first ``episodes`` train targets."""
    from opend_mj.apps.planner_demos import demo_jobs, record_demos

    jobs = demo_jobs(cabinets, ["allegro"], "oracle", split="train", limit=episodes)
    start = time.perf_counter()
    counts = record_demos(jobs, out, workers=workers, progress=False)
    return counts, time.perf_counter() - start


def train(demos: Path, out: Path, steps: int) -> tuple[dict, float, float]:
    """(the training summary, wall seconds, peak RSS in MiB) of `opend train-policy` in its own process."""
    cmd = [sys.executable, "-m", "opend_mj.cli", "train-policy", "--demos", str(demos), "--hand", "allegro",
           "--out", str(out), "--steps", str(steps), "--threads", "1", "--no-progress"]
    log = out.with_suffix(".log")
    start = time.perf_counter()
    with open(log, "w") as f:
        proc = subprocess.Popen(cmd, cwd=ROOT, stdout=f, stderr=subprocess.STDOUT)
        _, status, usage = os.wait4(proc.pid, 0)
    seconds = time.perf_counter() - start
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"train-policy failed:\n{log.read_text()[-3000:]}")
    return json.loads(out.with_suffix(".json").read_text()), seconds, usage.ru_maxrss / 1024.0


def section(cabinets: Path, episodes: int, steps: int) -> str:
    from opend_mj.apps.demos import FORMAT_VERSION
    from opend_mj.policy.learned.bc_model import BCConfig

    rows, size = [], None
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        record(cabinets, tmp / "warm-up.hdf5", 1, 1)  # this process's imports, outside the timing
        for workers in (1, 2):
            out = tmp / f"w{workers}.hdf5"
            counts, seconds = record(cabinets, out, episodes, workers)
            rows.append(f"| demonstrations recorded per minute, {workers} worker{'s' if workers > 1 else ''} | "
                        f"{counts['kept'] / seconds * 60:.1f} ({counts['kept']} of {counts['ran']} episodes kept, "
                        f"{seconds:.0f} s) |")
            if workers == 1:
                size = out.stat().st_size / max(counts["kept"], 1)
                kept = counts["kept"]
        summary, seconds, peak = train(tmp / "w1.hdf5", tmp / "bc.pt", steps)
    history = summary["history"]
    batch = BCConfig().batch_size
    # the optimiser loop's rate: between the first and the last logged step (data loading excluded)
    loop = (history[-1]["step"] - history[0]["step"]) * batch / (history[-1]["seconds"] - history[0]["seconds"])
    rows += [
        f"| bytes per demonstration (format {FORMAT_VERSION}: float32, gzip) | {size / 1e3:.0f} kB "
        f"({summary['samples'] / max(summary['demos'], 1):.0f} steps each on average) |",
        f"| training samples per second (CPU, 1 thread, batch {batch}) | {loop:.0f} |",
        f"| training, whole run ({summary['demos']} demos, {summary['samples']} steps, {steps} optimiser steps) | "
        f"{seconds:.0f} s |",
        f"| peak memory of training (resident, the whole `opend train-policy` process) | {peak:.0f} MiB |",
    ]
    text = [TITLE, "",
            f"`make bench-demos` (`python tools/bench_demos.py`): the planner's oracle episodes recorded as "
            f"demonstrations (`opend demos`: allegro, the first {episodes} train targets of the generated "
            f"cabinets, one seed), then `opend train-policy` on the {kept} demonstrations of the 1-worker run "
            f"(the default model, {steps} steps). The 1-worker run follows an untimed warm-up episode; "
            f"each of the 2 worker processes' first episode also pays for its imports (about 2 s). Load "
            f"average (1 min) before / after: {{load}}; above about 1, other work shared the cores and the "
            f"rates understate what an idle machine gives.", "",
            "| figure | value |", "|---|---|", *rows, ""]
    return "\n".join(text)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cabinets", type=Path, default=ROOT / "cabinets")
    parser.add_argument("--episodes", type=int, default=24)
    parser.add_argument("--steps", type=int, default=500, help="optimiser steps (>= 500: the rate is read "
                        "between the logged steps 250 and the last)")
    parser.add_argument("--write", type=Path, default=None, help="also write the section into this file")
    args = parser.parse_args()
    if args.steps < 500:
        parser.error("--steps must be at least 500")
    before = os.getloadavg()[0]
    text = section(args.cabinets, args.episodes, args.steps)
    text = text.replace("{load}", f"{before:.2f} / {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    print(text)
    if args.write is not None:
        write_section(args.write, TITLE, text)


if __name__ == "__main__":
    main()
