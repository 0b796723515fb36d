"""The dataset stage: compile many sources in parallel, filter, split, and write the manifest.

`cabinets/manifest.json` lists every built cabinet with its split and targets (joint, type,
instruction), every rejected source with its reason, and every target excluded by the feasibility
check with its reason, so that each later stage (task, training data, evaluation) reads one file.

The feasibility check (`opend_mj.sim.feasibility.RoomCheck`, passed in as ``check`` because the
room lives in a higher layer) pushes each target open with the cabinet standing in a room; its
report is stored in `cabinet.json["feasibility"]` and reused while its key matches.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from pathlib import Path

from tqdm import tqdm

from opend_mj.assets.compiler import CompileResult, compile_cabinet
from opend_mj.assets.config import CompilerConfig, DatasetConfig
from opend_mj.assets.layout import CABINET_JSON, Manifest
from opend_mj.language import LanguageConfig


def assign_split(ids: list[str], test_fraction: float, seed: int) -> dict[str, str]:
    """Deterministic split by cabinet: order ids by a seeded hash, the first fraction is test."""
    ranked = sorted(ids, key=lambda i: hashlib.sha256(f"{seed}:{i}".encode()).hexdigest())
    n_test = int(round(test_fraction * len(ids)))
    return {i: ("test" if k < n_test else "train") for k, i in enumerate(ranked)}


def format_split_table(table: dict[str, dict[str, int]]) -> str:
    lines = ["|          | train | test | total |", "|----------|------:|-----:|------:|"]
    for row in ("drawers", "doors", "targets", "cabinets"):
        r = table[row]
        lines.append(f"| {row:<8} | {r['train']:>5} | {r['test']:>4} | {r['total']:>5} |")
    return "\n".join(lines)


def _compile_job(args) -> CompileResult:
    source_dir, out_root, config, language, cache_dir, force, check = args
    try:
        result = compile_cabinet(source_dir, out_root, config, language, cache_dir, force)
    except Exception as exc:  # a bug must not lose the rest of the build: report it as a rejection
        return CompileResult(Path(source_dir).name, "rejected", "compiler_error",
                             f"{source_dir}: unexpected {type(exc).__name__}: {exc}")
    if check is None or result.status == "rejected":
        return result
    return _feasibility(result, Path(out_root) / result.id, check)


def _feasibility(result: CompileResult, cabinet_dir: Path, check) -> CompileResult:
    """Run `check` on a built cabinet (or reuse its stored report) and store it in cabinet.json."""
    stored = result.info.get("feasibility")
    if isinstance(stored, dict) and stored.get("key") == check.key:
        return result
    try:
        report = check(cabinet_dir)
    except Exception as exc:  # the cabinet does not load or step in a room
        return CompileResult(result.id, "rejected", "physics_error",
                             f"{cabinet_dir}: feasibility check failed ({type(exc).__name__}: {exc})")
    result.info["feasibility"] = report
    info_path = cabinet_dir / CABINET_JSON
    info_path.write_text(json.dumps(result.info, indent=1) + "\n")
    return result


def excluded_targets(info: dict) -> dict[str, dict]:
    """Targets of a cabinet.json that its feasibility report excludes: joint -> record."""
    report = info.get("feasibility") or {}
    return {t["joint"]: t for t in report.get("targets", []) if not t.get("feasible", True)}


def list_sources(source_root: Path, ids: list[str] | None = None) -> list[Path]:
    """Id folders of a PartNet-Mobility style root (every sub-folder; bad ones are rejected later)."""
    root = Path(source_root)
    if not root.is_dir():
        raise FileNotFoundError(f"{root}: source folder does not exist")
    folders = sorted((p for p in root.iterdir() if p.is_dir() and not p.name.startswith(".")),
                     key=lambda p: (len(p.name), p.name))
    if ids:
        wanted = set(ids)
        missing = wanted - {p.name for p in folders}
        if missing:
            raise FileNotFoundError(f"{root}: no source folder for ids {sorted(missing)}")
        folders = [p for p in folders if p.name in wanted]
    return folders


def build_dataset(
    source_dirs: list[Path],
    out_root: Path,
    config: CompilerConfig = CompilerConfig(),
    language: LanguageConfig = LanguageConfig(),
    dataset: DatasetConfig = DatasetConfig(),
    workers: int | None = None,
    force: bool = False,
    progress: bool = True,
    log=print,
    backend: str = "local",
    address: str | None = None,
    cache_dir: Path | None = None,
    check=None,
) -> Manifest:
    """Compile every source (in parallel), then split the valid ones and write the manifest.

    ``backend``: ``"local"`` (a spawn process pool of ``workers``, or this process for one worker) or
    ``"ray"`` (``address`` of a cluster sharing this file system, or a local Ray instance); see
    `opend_mj.backends`. Results come back to this process, which alone writes the manifest.

    ``check``: the feasibility check (`opend_mj.sim.feasibility.RoomCheck`), or None for none.
    Targets it finds infeasible leave the manifest for `excluded_targets` (with their reason); a
    cabinet left with no target is rejected (reason ``infeasible``).
    """
    from opend_mj.backends import make_executor

    out_root = Path(out_root)
    out_root.mkdir(parents=True, exist_ok=True)
    from opend_mj.assets.compiler import default_cache_dir

    cache_dir = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    workers = max(1, workers or os.cpu_count() or 1)
    jobs = [(Path(s), out_root, config, language, cache_dir, force, check) for s in source_dirs]
    results: list[CompileResult] = []
    start = time.perf_counter()
    bar = tqdm(total=len(jobs), desc="build-assets", unit="cab", disable=not progress, dynamic_ncols=True)

    def record(result: CompileResult) -> None:
        results.append(result)
        if result.status == "rejected":
            bar.write(f"rejected {result.id} [{result.reason}]: {result.message}") if progress else log(
                f"rejected {result.id} [{result.reason}]: {result.message}")
        bar.update(1)
        bar.set_postfix(built=sum(r.status != "rejected" for r in results), refresh=False)

    if backend == "local" and len(jobs) <= 1:
        workers = 1
    with make_executor(backend, workers, address) as executor:
        for job, result, error in executor.imap_unordered(_compile_job, jobs):
            if error is not None:  # a dead worker (e.g. CoACD crashed): a rejection, not a lost build
                last = [ln for ln in error.strip().splitlines() if ln.strip()][-1:]
                result = CompileResult(Path(job[0]).name, "rejected", "compiler_error",
                                       f"{job[0]}: worker failed: {last[0] if last else 'unknown error'}")
            record(result)
    bar.close()

    order = {Path(s).name: k for k, s in enumerate(source_dirs)}
    results.sort(key=lambda r: order.get(r.id, 0))
    excluded: list[dict] = []
    for r in results:
        if r.status == "rejected" or check is None:
            continue
        out = excluded_targets(r.info)
        excluded += [{"id": r.id, "joint": j, "type": t["kind"], "reason": t["reason"], "message": t["message"]}
                     for j, t in out.items()]
        if len(out) == len(r.info["targets"]):
            r.status, r.reason = "rejected", "infeasible"
            r.message = "; ".join(f"{t['reason']}: {t['message']}" for t in out.values())
    valid = [r for r in results if r.status != "rejected"]
    split = assign_split([r.id for r in valid], dataset.test_fraction, dataset.split_seed)
    manifest = Manifest(info={
        "compiler_config": config.digest(),
        "scale": config.scale,
        "sources": len(results),
        "built": sum(r.status == "built" for r in results),
        "cached": sum(r.status == "cached" for r in results),
        "seconds": round(time.perf_counter() - start, 2),
        "feasibility": None if check is None else {"key": check.key, "excluded_targets": len(excluded)},
    })
    for r in valid:
        out = excluded_targets(r.info) if check is not None else {}
        targets = [{k: t[k] for k in ("joint", "link", "type", "instruction", "vertical", "horizontal")}
                   | {"handle_orientation": t["handle"]["orientation"]} for t in r.info["targets"]
                   if t["joint"] not in out]
        manifest.cabinets.append({"id": r.id, "split": split[r.id], "path": r.id, "targets": targets,
                                  "hulls": r.info["stats"]["hulls"]})
    manifest.rejected = [{"id": r.id, "reason": r.reason, "message": r.message}
                         for r in results if r.status == "rejected"]
    manifest.excluded_targets = [e for e in excluded if e["id"] in {r.id for r in valid}]
    manifest.save(out_root)
    return manifest
