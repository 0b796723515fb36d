"""Real-cabinet asset benchmark (`make bench-assets-real SOURCE=../shared/opend-train`).

    python tools/bench_assets_real.py --source ../shared/opend-train [--out build/bench-real]
        [--cabinets build/opend-train] [--ids a,b] [--every N] [--phases build,cached,checks,fidelity]

On a folder of PartNet-Mobility sources, with one worker (this process):
- build: every source compiled cold (forced, decomposition cache emptied first: `<out>/cache`),
  seconds per cabinet, hulls per cabinet, decomposition statistics;
- cached: the same build again into the same output folder (every cabinet valid: nothing recompiled),
  and into a second output folder with the decomposition cache warm (compiled, nothing decomposed);
  the first also writes the dataset's `manifest.json` into `--cabinets`;
- checks: the physics checks of `opend_mj.assets.checks` (no contacts at rest, gravity drift,
  full travel when driven) on every built cabinet;
- fidelity: `opend_mj.assets.fidelity` on every built cabinet: distances between visual and collision
  surfaces (handles / the rest; visual -> collision and collision -> visual; max and p99) and the
  bar-to-panel gap of each handle (visual vs collision).
Per-cabinet records go to `<out>/records/<id>.json` (a phase can be re-run alone); the summary is
printed and written to `<out>/summary.md` and `<out>/summary.json`.
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

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from opend_mj.assets.compiler import compile_cabinet  # noqa: E402
from opend_mj.assets.config import CompilerConfig  # noqa: E402
from opend_mj.assets.dataset import build_dataset, list_sources  # noqa: E402

PHASES = ("build", "cached", "checks", "fidelity")


def _quiet(*_args) -> None:
    pass


def _record_path(out: Path, cid: str) -> Path:
    return out / "records" / f"{cid}.json"


def _load(out: Path, cid: str) -> dict:
    """A cabinet's record; the fidelity phase keeps its own file (it may run beside the others)."""
    p = _record_path(out, cid)
    rec = json.loads(p.read_text()) if p.is_file() else {"id": cid}
    f = p.with_suffix(".fidelity.json")
    if f.is_file():
        rec["fidelity"] = json.loads(f.read_text())
    return rec


def _save(out: Path, rec: dict, suffix: str = ".json") -> None:
    rec = {k: v for k, v in rec.items() if k != "fidelity"} if suffix == ".json" else rec
    p = _record_path(out, rec["id"]).with_suffix(suffix) if suffix != ".json" else _record_path(out, rec["id"])
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_suffix(".tmp")
    tmp.write_text(json.dumps(rec, indent=1, default=float))
    tmp.replace(p)


def phase_build(sources: list[Path], out: Path, cabinets: Path, cache: Path) -> None:
    shutil.rmtree(cache, ignore_errors=True)
    cache.mkdir(parents=True)
    config = CompilerConfig()
    for k, src in enumerate(sources):
        t, c = time.perf_counter(), time.process_time()
        res = compile_cabinet(src, cabinets, config, cache_dir=cache, force=True)
        seconds, cpu = time.perf_counter() - t, time.process_time() - c
        rec = _load(out, src.name)
        rec.update(status=res.status, reason=res.reason, message=res.message, cold_s=seconds, cold_cpu_s=cpu)
        if res.status != "rejected":
            s = res.info["stats"]
            rec.update(hulls=s["hulls"], boxes=s["boxes"], mesh_hulls=s["mesh_hulls"],
                       split_hulls=s.get("split_hulls"), cache_hits=s.get("split_cache_hits"),
                       split_s=s.get("split_seconds"), max_split_deviation=s.get("max_split_deviation"),
                       targets=len(res.info["targets"]))
        _save(out, rec)
        print(f"[{k + 1}/{len(sources)}] {src.name}: {res.status} {seconds:.1f} s (cpu {cpu:.1f} s)"
              + (f", {rec.get('hulls')} hulls" if res.status != "rejected" else f" [{res.reason}] {res.message}"),
              flush=True)


def phase_cached(sources: list[Path], out: Path, cabinets: Path, cache: Path, warm_every: int = 1) -> dict:
    t = time.perf_counter()
    manifest = build_dataset(sources, cabinets, workers=1, progress=False, log=_quiet, cache_dir=cache)
    same = time.perf_counter() - t
    second = out / "cabinets-second"
    shutil.rmtree(second, ignore_errors=True)
    t = time.perf_counter()
    warm_sources = sources[::warm_every]
    m2 = build_dataset(warm_sources, second, workers=1, progress=False, log=_quiet, cache_dir=cache)
    warm = time.perf_counter() - t
    shutil.rmtree(second, ignore_errors=True)
    n = len(sources)
    result = {"sources": n, "valid": len(manifest.cabinets), "cached": manifest.info["cached"],
              "same_out_s": same, "second_out_s": warm, "second_out_built": m2.info["built"],
              "second_out_sources": len(warm_sources)}
    print(f"cached (same --out): {same:.1f} s for {n} ({manifest.info['cached']} cached); "
          f"second --out, cache warm: {warm:.1f} s for {len(warm_sources)} ({m2.info['built']} built)", flush=True)
    (out / "cached.json").write_text(json.dumps(result, indent=1))
    return result


def phase_checks(ids: list[str], out: Path, cabinets: Path) -> None:
    from opend_mj.assets.checks import check_cabinet, load_cabinet

    for k, cid in enumerate(ids):
        rec = _load(out, cid)
        if rec.get("status") == "rejected" or not (cabinets / cid / "cabinet.xml").is_file():
            continue
        t = time.perf_counter()
        try:
            r = check_cabinet(load_cabinet(cabinets / cid))
            rec["check"] = {"ok": r.ok, "failures": r.failures, "rest_contacts": len(r.rest_contacts),
                            "max_drift": max(r.drift.values(), default=0.0),
                            "min_reached": min((d.reached for d in r.drives), default=1.0),
                            "max_returned": max((d.returned for d in r.drives), default=0.0),
                            "drives": len(r.drives)}
        except Exception as exc:  # noqa: BLE001 - a crash is a failed check, not a lost benchmark
            rec["check"] = {"ok": False, "failures": [f"{type(exc).__name__}: {exc}"]}
        _save(out, rec)
        c = rec["check"]
        print(f"[{k + 1}/{len(ids)}] check {cid}: {'ok' if c['ok'] else 'FAIL ' + '; '.join(c['failures'])} "
              f"({time.perf_counter() - t:.1f} s)", flush=True)


def phase_fidelity(sources: list[Path], out: Path, cabinets: Path) -> None:
    from opend_mj.assets.fidelity import cabinet_fidelity

    for k, src in enumerate(sources):
        rec = _load(out, src.name)
        if rec.get("status") == "rejected" or not (cabinets / src.name / "cabinet.xml").is_file():
            continue
        t = time.perf_counter()
        try:
            rec["fidelity"] = cabinet_fidelity(src, cabinets / src.name, CompilerConfig())
        except Exception as exc:  # noqa: BLE001
            rec["fidelity"] = {"error": f"{type(exc).__name__}: {exc}"}
        _save(out, {"id": src.name, **rec["fidelity"]}, suffix=".fidelity.json")
        f = rec["fidelity"]
        if "error" in f:
            print(f"[{k + 1}/{len(sources)}] fidelity {src.name}: ERROR {f['error']}", flush=True)
        else:
            print(f"[{k + 1}/{len(sources)}] fidelity {src.name}: handle max {f['handle']['max'] * 1000:.1f} mm, "
                  f"rest max {f['rest']['max'] * 1000:.1f} mm, min bar gap "
                  f"{_mm(f.get('min_bar_gap_collision'))} (visual {_mm(f.get('min_bar_gap_visual'))}) "
                  f"({time.perf_counter() - t:.1f} s)", flush=True)


def _mm(x) -> str:
    return "-" if x is None else f"{x * 1000:.1f} mm"


def _pct(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else float("nan")


def summary(ids: list[str], out: Path, source: Path) -> str:
    recs = [_load(out, i) for i in ids]
    built = [r for r in recs if r.get("status") not in (None, "rejected")]
    rejected = [r for r in recs if r.get("status") == "rejected"]
    cold = [r["cold_s"] for r in built if "cold_s" in r]
    hulls = [r["hulls"] for r in built if "hulls" in r]
    cpu = [r["cold_cpu_s"] for r in built if "cold_cpu_s" in r]
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    lines = [f"# Real-cabinet asset benchmark: {source} ({len(ids)} sources, 1 worker, "
             f"{os.cpu_count()} cores on the machine, load average {load:.1f} at the end)", "",
             "Wall seconds depend on what else runs on the machine; CPU seconds (time.process_time of the "
             "compiling process) are the cost on one core.", ""]
    lines += [f"{len(built)} built, {len(rejected)} rejected"
              + "".join(f"\n- rejected {r['id']} [{r['reason']}]: {r['message']}" for r in rejected), ""]
    if cold:
        lines += ["| per cabinet                      | median | p90   | max   | total |",
                  "|----------------------------------|-------:|------:|------:|------:|",
                  f"| cold compile s (1 worker, empty cache) | {statistics.median(cold):.1f} | "
                  f"{_pct(cold, 90):.1f} | {max(cold):.1f} | {sum(cold):.0f} |"]
        if cpu:
            lines.append(f"| cold compile, CPU s of this process | {statistics.median(cpu):.1f} | "
                         f"{_pct(cpu, 90):.1f} | {max(cpu):.1f} | {sum(cpu):.0f} |")
        if hulls:
            lines.append(f"| collision geoms (hulls)          | {statistics.median(hulls):.0f} | "
                         f"{_pct(hulls, 90):.0f} | {max(hulls)} | {sum(hulls)} |")
        over = sorted(((r.get("cold_cpu_s", r["cold_s"]), r["id"]) for r in built
                       if r.get("cold_cpu_s", r["cold_s"]) > 20), reverse=True)
        lines.append(f"\ncabinets over 20 s cold (CPU s): {len(over)}"
                     + (" (" + ", ".join(f"{i} {s:.0f} s" for s, i in over[:10]) + ")" if over else ""))
    cp = out / "cached.json"
    if cp.is_file():
        c = json.loads(cp.read_text())
        n = max(c["sources"], 1)
        n2 = max(c.get("second_out_sources", n), 1)
        lines.append(f"cached, same output folder: {c['same_out_s']:.1f} s for {c['sources']} sources "
                     f"({c['same_out_s'] / n * 1000:.0f} ms each, wall); second output folder, decomposition "
                     f"cache warm: {c['second_out_s']:.1f} s for {n2} sources ({c['second_out_s'] / n2:.2f} s "
                     f"each, wall)")
    checked = [r for r in built if "check" in r]
    if checked:
        fails = [r for r in checked if not r["check"]["ok"]]
        lines += ["", f"physics checks (no contacts at rest, drift < 1 % in 5 s, every target driven >= 95 % "
                      f"open and back): {len(checked) - len(fails)} of {len(checked)} pass"]
        lines += [f"- FAIL {r['id']}: {'; '.join(r['check']['failures'])}" for r in fails]
    fid = [r for r in built if "fidelity" in r and "error" not in r["fidelity"]]
    errs = [r for r in built if "fidelity" in r and "error" in r["fidelity"]]
    if fid:
        lines += ["", "| fidelity (mm), over cabinets            | median | p90  | max  |",
                  "|------------------------------------------|-------:|-----:|-----:|"]
        for cls in ("handle", "rest"):
            for key, label in (("vis_to_col_max", "visual -> collision, max"),
                               ("vis_to_col_p99", "visual -> collision, p99"),
                               ("col_to_vis_max", "collision -> visual, max"),
                               ("col_to_vis_p99", "collision -> visual, p99")):
                v = [r["fidelity"][cls][key] * 1000 for r in fid if r["fidelity"][cls].get(key) is not None]
                if v:
                    lines.append(f"| {cls + ' ' + label:<40} | {statistics.median(v):.2f} | "
                                 f"{_pct(v, 90):.2f} | {max(v):.2f} |")
        lines += ["", "(visual -> collision: how much visual surface the collision geometry misses; collision -> "
                  "visual: how far the boundary of the collision geometry stands off the visual surface, which "
                  "counts the faces that filling a board adds where PartNet leaves it open, hulls bridging a "
                  "relief or a curve where the hull budget ran out, and the 4 mm thickening of flat plates. "
                  "The front rays measure what a finger or the camera meets: per ray, the larger of the "
                  "distances between the collision hit and the visual surface and between the visual hit and "
                  "the collision geometry.)"]
        lines += ["", "| front rays (+x, first hit, collision vs visual) | rays | median mm | p99 mm (median / max over cabinets) | within 1 mm | within 2 mm |",
                  "|---|---:|---:|---:|---:|---:|"]
        for cls, label in (("handle", "handles"), ("front", "door and drawer fronts"), ("carcass", "carcass (openings)")):
            rows = [r["fidelity"]["front_rays"][cls] for r in fid if r["fidelity"].get("front_rays", {}).get(cls, {}).get("rays")]
            if not rows:
                continue
            n = sum(x["rays"] for x in rows)
            w1 = sum(x["within_1mm"] * x["rays"] for x in rows) / n
            w2 = sum(x["within_2mm"] * x["rays"] for x in rows) / n
            p50 = statistics.median(x["p50"] for x in rows) * 1000
            p99 = [x["p99"] * 1000 for x in rows]
            lines.append(f"| {label} | {n} | {p50:.2f} | {statistics.median(p99):.2f} / {max(p99):.1f} | {w1:.1%} | {w2:.1%} |")
        within = [r for r in fid if r["fidelity"]["handle"]["max"] <= 0.001]
        lines.append(f"\nhandles within 1 mm (both directions, max): {len(within)} of {len(fid)} cabinets; "
                     f"rest within 2 mm: {sum(r['fidelity']['rest']['max'] <= 0.002 for r in fid)} of {len(fid)}")
        gaps = [(g["collision"], g["visual"], r["id"], g["link"]) for r in fid for g in r["fidelity"]["bar_gaps"]
                if g["visual"] is not None and g["visual"] >= 0.005]
        if gaps:
            worst = min(gaps)
            loss = max(gaps, key=lambda g: g[1] - (g[0] or 0))
            lines.append(f"bar-to-panel gaps (handles with a visual gap >= 5 mm: {len(gaps)}): smallest collision gap "
                         f"kept {_mm(worst[0])} (visual {_mm(worst[1])}, {worst[2]} {worst[3]}); largest loss "
                         f"{_mm(loss[1] - (loss[0] or 0))} ({loss[2]} {loss[3]}: visual {_mm(loss[1])}, collision "
                         f"{_mm(loss[0])}); gaps closed: {sum((g[0] or 0) < 0.001 for g in gaps)}")
        worst_h = sorted(fid, key=lambda r: -r["fidelity"]["handle"]["max"])[:5]
        lines.append("worst handles: " + ", ".join(f"{r['id']} {r['fidelity']['handle']['max'] * 1000:.1f} mm"
                                                    for r in worst_h))
        worst_r = sorted(fid, key=lambda r: -r["fidelity"]["rest"]["max"])[:5]
        lines.append("worst rest: " + ", ".join(f"{r['id']} {r['fidelity']['rest']['max'] * 1000:.1f} mm"
                                                 for r in worst_r))
    lines += [f"- fidelity error {r['id']}: {r['fidelity']['error']}" for r in errs]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--source", type=Path, required=True)
    parser.add_argument("--out", type=Path, default=ROOT / "build" / "bench-real")
    parser.add_argument("--cabinets", type=Path, default=None, help="Compiled dataset folder (default <out>/cabinets).")
    parser.add_argument("--ids", default=None)
    parser.add_argument("--every", type=int, default=1, help="Every N-th source only (a quick subset).")
    parser.add_argument("--phases", default=",".join(PHASES))
    parser.add_argument("--warm-every", type=int, default=1,
                        help="The warm-cache build into a second folder on every N-th source only.")
    args = parser.parse_args(argv)
    phases = [p for p in args.phases.split(",") if p]
    unknown = set(phases) - set(PHASES)
    if unknown:
        parser.error(f"unknown phases {sorted(unknown)}")
    sources = list_sources(args.source, args.ids.split(",") if args.ids else None)[::args.every]
    out = args.out
    cabinets = args.cabinets or out / "cabinets"
    cache = out / "cache"
    out.mkdir(parents=True, exist_ok=True)
    print(f"bench-assets-real: {len(sources)} sources from {args.source} -> {cabinets}; phases {phases}", flush=True)
    ids = [s.name for s in sources]
    if "build" in phases:
        phase_build(sources, out, cabinets, cache)
    if "cached" in phases:
        phase_cached(sources, out, cabinets, cache, args.warm_every)
    if "checks" in phases:
        phase_checks(ids, out, cabinets)
    if "fidelity" in phases:
        phase_fidelity(sources, out, cabinets)
    text = summary(ids, out, args.source)
    print("\n" + text)
    (out / "summary.md").write_text(text + "\n")
    recs = [_load(out, i) for i in ids]
    (out / "summary.json").write_text(json.dumps(recs, indent=1, default=float))
    ok = all(r.get("check", {}).get("ok", True) for r in recs if r.get("status") != "rejected")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
