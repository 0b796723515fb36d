"""The pool: run a list of episodes in worker processes (or on Ray), resumably, into one results file.

Reliability: an episode never stops the run. A cabinet whose files are missing or corrupt (checked
cheaply in the parent: ``cabinet.json`` parses, ``cabinet.xml`` is well-formed XML; deeper faults
surface in the worker as ``CabinetError``) gives error records with ``error_reason`` naming the file;
an episode past its wall-clock limit (``episode_timeout``) gives an error record of kind ``timeout``.
Agents (``EpisodeJob.policy``) run in agent processes of their own, started by the worker that
holds the simulator (`evaluation.agent_process`); an agent process that dies costs its episode only.
Agent runs use worker processes even with one worker, so that a worker that dies (or an agent run
``--agent-in-process`` that calls ``os._exit``) costs its episode only: the episodes of its group
are run again one by one. This process, which writes the records, makes itself non-dumpable for an
agent run (`agent_process.make_undumpable`). Error records count as done on resume (delete their
lines to retry them).
"""

from __future__ import annotations

import functools
from pathlib import Path

from opend_mj.evaluation.agent_process import ISOLATION_IN_PROCESS, make_undumpable
from opend_mj.evaluation.agents import run_group
from opend_mj.evaluation.deadline import DEFAULT_EPISODE_TIMEOUT
from opend_mj.evaluation.episode import EpisodeJob, episode_key
from opend_mj.evaluation.jobs import group_jobs
from opend_mj.evaluation.lock import ResultsLock
from opend_mj.evaluation.results import ResultsWriter, load_results, sort_results
from opend_mj.evaluation.runner import error_reason, error_record


def _worker_init() -> None:
    from opend_mj.backends import worker_init

    worker_init()


def check_cabinet_files(cabinet_dir: str | Path) -> None:
    """Cheap checks of a compiled cabinet folder in the parent; raises ``CabinetError`` naming the file."""
    import xml.etree.ElementTree as ET

    from opend_mj.assets.layout import CABINET_XML
    from opend_mj.sim.cabinet import CabinetError, load_cabinet_info

    load_cabinet_info(Path(cabinet_dir))
    xml_path = Path(cabinet_dir) / CABINET_XML
    try:
        ET.parse(xml_path)
    except FileNotFoundError as exc:
        raise CabinetError(f"{xml_path}: missing") from exc
    except (ET.ParseError, OSError) as exc:
        raise CabinetError(f"{xml_path}: corrupt MJCF ({exc})") from exc


def run_jobs(jobs: list[EpisodeJob], out: Path, workers: int = 1, progress: bool = True,
             backend: str = "local", address: str | None = None, executor=None, sort: bool = True,
             wait: bool = False, on_wait=None, episode_timeout: float | None = DEFAULT_EPISODE_TIMEOUT) -> dict:
    """Run the jobs not yet in ``out`` (resumable) and append their records. Returns counts.

    ``backend``: ``"local"`` (this process when ``workers == 1``, else a spawn pool of ``workers``)
    or ``"ray"`` (``address`` of a cluster, or a local Ray instance); or pass an ``executor`` from
    `opend_mj.backends`. Only this process writes ``out``. With ``sort``, the file ends in job order.

    The run owns ``out`` while it runs (`evaluation.lock`): if another run holds it, this raises
    `ResultsLocked`, or with ``wait`` waits for it (and then skips the episodes it wrote).

    ``episode_timeout``: each episode's wall-clock limit in seconds (None: none); it does not change
    the record of an episode that ends in time.
    """
    with ResultsLock(out, wait=wait, on_wait=on_wait):
        return _run_jobs(jobs, out, workers, progress, backend, address, executor, sort, episode_timeout)


def _run_jobs(jobs, out, workers, progress, backend, address, executor, sort, episode_timeout) -> dict:
    from tqdm import tqdm

    from opend_mj.backends import make_executor

    out = Path(out)
    done = {episode_key(r) for r in load_results(out)}
    seen = set()
    todo = []
    for j in jobs:
        k = j.key()
        if k in done or k in seen:
            continue
        seen.add(k)
        todo.append(j)
    counts = {"total": len(jobs), "skipped": len(jobs) - len(todo), "ran": 0, "errors": 0, "success": 0}
    if not todo:
        if sort:
            sort_results(out, jobs)
        return counts
    bar = tqdm(total=len(todo), desc="episodes", unit="ep", disable=not progress, dynamic_ncols=True)

    # cabinets whose files are broken: their episodes become error records without running
    broken: dict[str, BaseException] = {}
    for cab_dir in dict.fromkeys(j.cabinet_dir for j in todo):
        try:
            check_cabinet_files(cab_dir)
        except Exception as exc:  # noqa: BLE001 (CabinetError, or anything odd about the folder)
            broken[cab_dir] = exc
    runnable = [j for j in todo if j.cabinet_dir not in broken]

    with ResultsWriter(out) as writer:
        def record(rec: dict) -> None:
            writer.write(rec)
            counts["ran"] += 1
            counts["errors"] += int("error" in rec)
            counts["success"] += int(bool(rec.get("success")))
            bar.update(1)
            bar.set_postfix(success=f"{counts['success']}/{counts['ran']}")

        for j in todo:
            if j.cabinet_dir in broken:
                exc = broken[j.cabinet_dir]
                record({**error_record(j, exc), "wall_seconds": 0.0})
                if progress:
                    bar.write(f"skipped {j.cabinet}/{j.joint}: {error_reason(exc)}")
        if runnable:
            if any(j.policy and j.agent_isolation != ISOLATION_IN_PROCESS for j in runnable):
                make_undumpable()  # no agent process reads or writes the records in this one's memory
            if executor is not None:
                ex = executor
            elif backend == "local" and workers <= 1 and any(j.policy for j in runnable):
                from opend_mj.backends import ProcessPoolBackend

                ex = ProcessPoolBackend(1, initializer=_worker_init)  # an agent never runs in this process
            else:
                ex = make_executor(backend, workers, address, initializer=_worker_init)
            fn = functools.partial(run_group, episode_timeout=episode_timeout)
            try:
                alone = []  # episodes of groups whose worker failed: each is run again on its own
                for group, recs, err in ex.imap_unordered(fn, group_jobs(runnable)):
                    if err is not None and len(group) > 1:
                        alone += [(j,) for j in group]
                        continue
                    if err is not None:
                        recs = [{**error_record(j, err), "wall_seconds": None} for j in group]
                    for rec in recs:
                        record(rec)
                for group, recs, err in ex.imap_unordered(fn, alone):
                    if err is not None:
                        recs = [{**error_record(j, err), "wall_seconds": None} for j in group]
                    for rec in recs:
                        record(rec)
            finally:
                if executor is None:
                    ex.close()
    bar.close()
    if sort:
        sort_results(out, jobs)
    return counts
