"""Benchmark of the asset pipeline (`make bench-assets`): compile speed, hulls, simulation speed, physics checks.

    python tools/bench_assets.py --out build/bench-cabinets [--count 346] [--workers N]

Generates `--count` procedural sources, then measures
- seconds per source to compile them cold (forced rebuild) with 1 worker and with N workers, and cached;
- collision hulls per cabinet (boxes and convex meshes);
- `mj_step` steps/s of each compiled cabinet alone (every door/drawer given a small initial velocity);
- the rest checks of `opend_mj.assets.checks` over every built cabinet: no contacts at rest, gravity drift
  below 1 % of the range in 5 s, every target driven through >= 95 % of its range and back;
and the same for the real PartNet-Mobility cabinet 45780 where `../shared/partnet-sample/45780` exists
(cold = empty CoACD cache). Prints Markdown tables and writes `<out>/bench.json`.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from opend_mj.assets.checks import check_cabinet, load_cabinet, steps_per_second  # noqa: E402
from opend_mj.assets.compiler import compile_cabinet  # noqa: E402
from opend_mj.assets.dataset import build_dataset  # noqa: E402
from opend_mj.assets.procedural import generate_sources  # noqa: E402

REAL = ROOT.parent / "shared" / "partnet-sample" / "45780"


def _quiet(*_args) -> None:
    pass


def _spread(values: list[float], fmt: str = "{:.0f}") -> str:
    if not values:
        return "-"
    return f"{fmt.format(statistics.median(values))} ({fmt.format(min(values))} - {fmt.format(max(values))})"


def _check(folder: Path, steps: int) -> dict:
    model = load_cabinet(folder)
    result = check_cabinet(model)
    return {
        "steps_per_s": steps_per_second(model, steps),
        "ok": result.ok,
        "failures": result.failures,
        "rest_contacts": len(result.rest_contacts),
        "max_drift": max(result.drift.values(), default=0.0),
        "min_reached": min((d.reached for d in result.drives), default=1.0),
        "max_returned": max((d.returned for d in result.drives), default=0.0),
        "max_overshoot": max((d.overshoot for d in result.drives), default=0.0),
        "drives": len(result.drives),
    }


def bench_procedural(out: Path, count: int, workers: int, seed: int, steps: int) -> dict:
    src_root = out / ".sources"
    t = time.perf_counter()
    sources = generate_sources(count, seed, src_root, progress=False)
    generate_s = time.perf_counter() - t
    cab_root = out / "cabinets"

    timings = {}
    for label, kwargs in (("cold, 1 worker", dict(workers=1, force=True)),
                          (f"cold, {workers} workers", dict(workers=workers, force=True)),
                          (f"cached, {workers} workers", dict(workers=workers, force=False))):
        t = time.perf_counter()
        manifest = build_dataset(sources, cab_root, progress=False, log=_quiet, **kwargs)
        timings[label] = time.perf_counter() - t
        print(f"  {label}: {timings[label]:.1f} s", flush=True)

    infos = [json.loads((cab_root / c["path"] / "cabinet.json").read_text()) for c in manifest.cabinets]
    checks = {}
    for c in manifest.cabinets:
        checks[c["id"]] = _check(cab_root / c["path"], steps)
    reasons: dict[str, int] = {}
    for r in manifest.rejected:
        reasons[r["reason"]] = reasons.get(r["reason"], 0) + 1
    return {
        "sources": len(sources),
        "valid": len(manifest.cabinets),
        "targets": sum(len(c["targets"]) for c in manifest.cabinets),
        "rejected": reasons,
        "generate_s": generate_s,
        "timings_s": timings,
        "hulls": [i["stats"]["hulls"] for i in infos],
        "boxes": [i["stats"]["boxes"] for i in infos],
        "mesh_hulls": [i["stats"]["mesh_hulls"] for i in infos],
        "coacd_hulls": sum(i["stats"]["coacd_hulls"] for i in infos),
        "checks": checks,
    }


def bench_real(out: Path, steps: int) -> dict | None:
    if not (REAL / "mobility.urdf").is_file():
        return None
    cab_root, cache = out / "real", out / "real" / ".cache"
    shutil.rmtree(cache, ignore_errors=True)
    cold = compile_cabinet(REAL, cab_root, cache_dir=cache, force=True)
    if cold.status == "rejected":
        return {"status": "rejected", "reason": cold.reason, "message": cold.message}
    cached = compile_cabinet(REAL, cab_root, cache_dir=cache)
    stats = cold.info["stats"]
    return {"status": cold.status, "cold_s": cold.seconds, "cached_status": cached.status,
            "cached_s": cached.seconds, "hulls": stats["hulls"], "boxes": stats["boxes"],
            "mesh_hulls": stats["mesh_hulls"], "coacd_hulls": stats["coacd_hulls"],
            "check": _check(cab_root / REAL.name, steps)}


def report(proc: dict, real: dict | None, workers: int) -> str:
    n = proc["sources"]
    lines = [
        f"procedural: {n} sources -> {proc['valid']} valid cabinets, {proc['targets']} targets; rejected: "
        + (", ".join(f"{k} {v}" for k, v in sorted(proc["rejected"].items())) or "none"),
        f"(generating the sources took {proc['generate_s']:.1f} s; {os.cpu_count()} cores)",
        "",
        "| compile (procedural)      | total s | s / source | s / valid cabinet |",
        "|---------------------------|--------:|-----------:|------------------:|",
    ]
    for label, s in proc["timings_s"].items():
        lines.append(f"| {label:<25} | {s:7.1f} | {s / n:10.3f} | {s / max(proc['valid'], 1):17.3f} |")
    if proc["hulls"]:
        h, b, m = proc["hulls"], proc["boxes"], proc["mesh_hulls"]
        lines += [
            "",
            "| per cabinet           | mean  | min | max |",
            "|-----------------------|------:|----:|----:|",
            f"| collision hulls       | {statistics.mean(h):5.1f} | {min(h):3d} | {max(h):3d} |",
            f"|   of which boxes      | {statistics.mean(b):5.1f} | {min(b):3d} | {max(b):3d} |",
            f"|   of which mesh hulls | {statistics.mean(m):5.1f} | {min(m):3d} | {max(m):3d} |",
            f"(CoACD hulls over all procedural cabinets: {proc['coacd_hulls']})",
        ]
    checks = list(proc["checks"].values())
    sps = [c["steps_per_s"] for c in checks]
    passed = sum(c["ok"] for c in checks)
    lines += [
        "",
        f"mj_step, cabinet alone, moving parts: median {statistics.median(sps):,.0f} steps/s "
        f"(min {min(sps):,.0f}, max {max(sps):,.0f})" if sps else "mj_step: no cabinet",
        "",
        "| physics checks (all built cabinets)            | pass | of  |",
        "|------------------------------------------------|-----:|----:|",
        f"| no contacts at rest                            | {sum(c['rest_contacts'] == 0 for c in checks):4d} "
        f"| {len(checks):3d} |",
        f"| gravity drift < 1 % of range in 5 s            | {sum(c['max_drift'] < 0.01 for c in checks):4d} "
        f"| {len(checks):3d} |",
        f"| every target driven >= 95 % open and back      | "
        f"{sum(c['min_reached'] >= 0.95 and c['max_returned'] <= 0.05 for c in checks):4d} | {len(checks):3d} |",
        f"| all of the above (cabinets)                    | {passed:4d} | {len(checks):3d} |",
    ]
    if checks:
        lines.append(f"(worst: drift {max(c['max_drift'] for c in checks):.2%}, reached "
                     f"{min(c['min_reached'] for c in checks):.1%}, came back to "
                     f"{max(c['max_returned'] for c in checks):.1%}, overshoot "
                     f"{max(c['max_overshoot'] for c in checks):.2%} of range; "
                     f"{sum(c['drives'] for c in checks)} targets driven)")
    for cid, c in proc["checks"].items():
        if not c["ok"]:
            lines.append(f"  FAIL {cid}: {'; '.join(c['failures'])}")
    if real is None:
        lines += ["", f"real cabinet 45780: not found at {REAL}"]
    elif real["status"] == "rejected":
        lines += ["", f"real cabinet 45780: REJECTED [{real['reason']}] {real['message']}"]
    else:
        c = real["check"]
        lines += [
            "",
            "| real cabinet 45780          |                 |",
            "|-----------------------------|-----------------|",
            f"| cold compile (empty cache)  | {real['cold_s']:.1f} s |",
            f"| cached                      | {real['cached_s'] * 1000:.1f} ms ({real['cached_status']}) |",
            f"| collision hulls             | {real['hulls']} ({real['boxes']} boxes, {real['mesh_hulls']} meshes; "
            f"{real['coacd_hulls']} from CoACD) |",
            f"| mj_step, alone, moving      | {c['steps_per_s']:,.0f} steps/s |",
            f"| physics checks              | {'pass' if c['ok'] else 'FAIL: ' + '; '.join(c['failures'])} |",
        ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=ROOT / "build" / "bench-cabinets")
    parser.add_argument("--count", type=int, default=346)
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--steps", type=int, default=2000, help="mj_step calls per cabinet for steps/s")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    print(f"bench-assets: {args.count} procedural cabinets, {args.workers} workers -> {args.out}", flush=True)
    proc = bench_procedural(args.out, args.count, args.workers, args.seed, args.steps)
    print("  real cabinet ...", flush=True)
    real = bench_real(args.out, args.steps)
    print()
    print(report(proc, real, args.workers))
    (args.out / "bench.json").write_text(json.dumps({"procedural": proc, "real": real}, indent=1, default=str))
    ok = all(c["ok"] for c in proc["checks"].values()) and (real is None or real.get("check", {}).get("ok", False))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
