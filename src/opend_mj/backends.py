"""Where independent jobs run: in this process, in a local process pool (default), or on a Ray cluster.

One small interface for every parallel stage (episodes in `opend run`, cabinets in
`opend build-assets`): an executor maps a picklable top-level function over items and yields
``(item, result, error)`` triples in *completion* order, with at most ``max_in_flight`` items
submitted ahead, so that results stream back to the parent (which alone writes files) and a long
job list is never materialised as futures all at once. ``error`` is ``None`` on success, else the
text of the exception (a worker that died, a task that raised): callers turn it into a record, so
that one bad job never stops the others.

    with make_executor("local", workers=4) as ex:
        for item, result, error in ex.imap_unordered(fn, items):
            ...

Backends:

- ``"local"`` (default): ``workers == 1`` runs in this process; otherwise a ``spawn`` process pool
  (an OpenGL/EGL context does not survive ``fork``).
- ``"ray"``: one ``ray.remote`` task per item with ``num_cpus=1``. ``address=None`` starts a local
  Ray instance with ``num_cpus=max(2, workers)``, no dashboard and quiet logging; an address
  (``"auto"``, ``"ray://host:10001"``, ``"host:6379"``) joins a running cluster, whose machines must
  have ``opend_mj`` installed and the cabinet folders at the same paths (a shared file system).
  Workers get ``MUJOCO_GL=egl`` through the job's ``runtime_env``.
"""

from __future__ import annotations

import functools
import multiprocessing
import os
import traceback
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Any

BACKENDS = ("local", "ray")

#: Environment every worker needs (headless rendering).
WORKER_ENV = {"MUJOCO_GL": "egl"}


def worker_init(nice: int = 5) -> None:
    """Pool worker initialiser: headless GL, and a lower priority than the parent."""
    for k, v in WORKER_ENV.items():
        os.environ.setdefault(k, v)
    if nice:
        try:
            os.nice(nice)
        except OSError:
            pass


class BackendError(RuntimeError):
    """A backend that cannot start (Ray missing, or no cluster at the address)."""


class Executor:
    """Base class: ``imap_unordered(fn, items)`` yields ``(item, result, error)`` in completion order."""

    name = "base"

    def __init__(self, workers: int = 1):
        self.workers = max(1, int(workers))

    @property
    def slots(self) -> int:
        """How many items run at the same time."""
        return self.workers

    def imap_unordered(self, fn: Callable[[Any], Any], items: Iterable[Any],
                       max_in_flight: int | None = None) -> Iterator[tuple[Any, Any, str | None]]:
        raise NotImplementedError

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class SerialExecutor(Executor):
    """Runs each item in this process, one after the other (``--workers 1``; easiest to debug)."""

    name = "serial"

    def imap_unordered(self, fn, items, max_in_flight=None):
        for item in items:
            try:
                result, error = fn(item), None
            except Exception:  # noqa: BLE001 (reported, not raised: the other items go on)
                result, error = None, traceback.format_exc()
            yield item, result, error


class ProcessPoolBackend(Executor):
    """A ``spawn`` process pool on this machine.

    A worker that dies (``kill -9``, a segfault, the OOM killer) breaks a ``ProcessPoolExecutor``:
    every job in flight fails. Here the pool is rebuilt and the jobs that were in flight are rerun
    one at a time; the one that kills its worker again alone is reported as an error, the others
    give their results. The caller's parent process is never lost.
    """

    name = "local"

    def __init__(self, workers: int = 2, initializer: Callable[[], None] | None = worker_init):
        super().__init__(workers)
        self._initializer = initializer
        self._pool = self._new_pool()
        self.restarts = 0

    def _new_pool(self) -> ProcessPoolExecutor:
        ctx = multiprocessing.get_context("spawn")
        return ProcessPoolExecutor(max_workers=self.workers, mp_context=ctx, initializer=self._initializer)

    def _restart(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)
        self._pool = self._new_pool()
        self.restarts += 1

    def imap_unordered(self, fn, items, max_in_flight=None):
        from concurrent.futures.process import BrokenProcessPool

        limit = max(1, max_in_flight or 2 * self.workers)
        it = iter(items)
        pending: dict = {}  # future -> (item, alone)
        suspects: list = []  # in flight when a worker died: rerun one at a time

        def submit(item, alone: bool) -> None:
            try:
                fut = self._pool.submit(fn, item)
            except BrokenProcessPool:
                self._restart()
                fut = self._pool.submit(fn, item)
            pending[fut] = (item, alone)

        def fill() -> None:
            if suspects:
                if not pending:
                    submit(suspects.pop(0), True)
                return
            while len(pending) < limit:
                item = next(it, _END)
                if item is _END:
                    return
                submit(item, False)

        def settle(fut):
            """(item, result, error) of a finished future, or None when it is a suspect to rerun."""
            item, alone = pending.pop(fut)
            try:
                return item, fut.result(), None
            except BrokenProcessPool:
                if alone:
                    return item, None, ("BrokenProcessPool: the worker process running this job died "
                                        "(killed, out of memory or crashed), twice")
                suspects.append(item)
                return None
            except Exception:  # noqa: BLE001 (the job raised)
                return item, None, traceback.format_exc()

        fill()
        while pending:
            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
            broken = False
            for fut in finished:
                broken |= isinstance(fut.exception(), BrokenProcessPool)
                out = settle(fut)
                if out is not None:
                    yield out
            if broken:  # every other job in flight fails too: collect them, then a fresh pool
                rest, _ = wait(list(pending), timeout=60)
                for fut in rest:
                    out = settle(fut)
                    if out is not None:
                        yield out
                for fut in list(pending):  # did not settle in time: rerun them
                    suspects.append(pending.pop(fut)[0])
                self._restart()
            fill()

    def close(self) -> None:
        self._pool.shutdown(wait=True, cancel_futures=True)


class RayBackend(Executor):
    """One Ray task per item (``num_cpus=1``), on a local Ray instance or a cluster."""

    name = "ray"

    def __init__(self, workers: int = 2, address: str | None = None, num_cpus: int | None = None,
                 max_retries: int = 1):
        super().__init__(workers)
        try:
            import ray
        except ImportError as exc:  # pragma: no cover (ray is a dependency)
            raise BackendError(f"the ray backend needs `pip install 'ray>=2.9'` ({exc})") from exc
        import logging

        import opend_mj  # noqa: F401 (the package must import in the driver before workers start)

        self._ray = ray
        for k, v in WORKER_ENV.items():
            os.environ.setdefault(k, v)  # local workers inherit the driver's environment too
        os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
        os.environ.setdefault("RAY_DEDUP_LOGS", "1")
        self._owns = not ray.is_initialized()
        if self._owns:
            kwargs: dict = dict(include_dashboard=False, logging_level=logging.ERROR, log_to_driver=False,
                                configure_logging=True, runtime_env={"env_vars": dict(WORKER_ENV)})
            if address is None:
                kwargs["num_cpus"] = num_cpus or max(2, self.workers)
            try:
                ray.init(address=address, **kwargs)
            except Exception as exc:  # noqa: BLE001 (ConnectionError, RuntimeError, ... depending on the version)
                where = f"the Ray cluster at {address!r}" if address else "a local Ray instance"
                raise BackendError(f"could not start {where}: {type(exc).__name__}: {exc}") from exc
        self.address = address
        self.max_retries = max_retries
        self._remote_cache: dict = {}

    @property
    def slots(self) -> int:
        try:
            return max(1, int(self._ray.available_resources().get("CPU", 0)) or
                       int(self._ray.cluster_resources().get("CPU", 1)))
        except Exception:  # noqa: BLE001
            return self.workers

    def _remote(self, fn):
        """A Ray task calling ``fn`` (a function, or a ``functools.partial`` of one, which Ray cannot
        make remote itself)."""
        if isinstance(fn, functools.partial):
            base = self._remote(_call_partial)
            return _Bound(base, (fn.func, fn.args, fn.keywords))
        if fn not in self._remote_cache:
            self._remote_cache[fn] = self._ray.remote(num_cpus=1, max_retries=self.max_retries)(fn)
        return self._remote_cache[fn]

    def imap_unordered(self, fn, items, max_in_flight=None):
        ray = self._ray
        remote = self._remote(fn)
        limit = max(1, max_in_flight or 2 * self.slots)
        it = iter(items)
        pending: dict = {}

        def fill() -> None:
            while len(pending) < limit:
                item = next(it, _END)
                if item is _END:
                    return
                pending[remote.remote(item)] = item

        fill()
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            for ref in ready:
                item = pending.pop(ref)
                try:
                    result, error = ray.get(ref), None
                except Exception:  # noqa: BLE001 (RayTaskError, WorkerCrashedError, ...)
                    result, error = None, traceback.format_exc()
                yield item, result, error
            fill()
        # anything still pending (the consumer stopped early) is cancelled
        for ref in pending:
            try:
                ray.cancel(ref, force=True)
            except Exception:  # noqa: BLE001
                pass

    def close(self) -> None:
        if self._owns and self._ray.is_initialized():
            self._ray.shutdown()


_END = object()


def _call_partial(bound, item):
    """``functools.partial(func, *args, **keywords)(item)`` as a plain function (for Ray)."""
    func, args, keywords = bound
    return func(*args, item, **keywords)


class _Bound:
    """``remote.remote(item)`` of a Ray task that takes a bound partial first."""

    def __init__(self, remote, bound):
        self._remote, self._bound = remote, bound

    def remote(self, item):
        return self._remote.remote(self._bound, item)


def make_executor(backend: str = "local", workers: int = 1, address: str | None = None,
                  initializer: Callable[[], None] | None = worker_init) -> Executor:
    """The executor for a backend name: ``"local"`` (serial when ``workers == 1``) or ``"ray"``."""
    if backend == "local":
        if address is not None:
            raise ValueError("--address is only for --backend ray")
        if workers <= 1:
            return SerialExecutor(1)
        return ProcessPoolBackend(workers, initializer=initializer)
    if backend == "ray":
        return RayBackend(workers, address=address)
    raise ValueError(f"unknown backend {backend!r}; known: {', '.join(BACKENDS)}")


__all__ = ["BACKENDS", "BackendError", "Executor", "ProcessPoolBackend", "RayBackend", "SerialExecutor", "make_executor",
           "worker_init"]
