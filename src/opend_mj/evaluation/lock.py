"""One run owns a results file: an advisory lock beside it, held for the whole run.

``.<name>.lock`` next to ``results.jsonl`` is locked with ``flock`` (released by the kernel when the
process ends, even on ``kill -9``, so a stale lock file never blocks anyone) and holds the owner's
pid, host and command line for the message a second run prints. The lock is on a separate file
because the final reorder replaces the results file by rename. The lock file is left in place.
"""

from __future__ import annotations

import fcntl
import json
import os
import socket
import sys
import time
from pathlib import Path


class ResultsLocked(RuntimeError):
    """Another process holds the results file's lock."""


def lock_path(results: Path) -> Path:
    results = Path(results)
    return results.with_name(f".{results.name}.lock")


class ResultsLock:
    """``with ResultsLock(path, wait=False):`` owns ``path`` or raises `ResultsLocked`.

    ``wait``: block until the owner finishes instead (``on_wait(message)`` is called once first).
    """

    def __init__(self, results: Path, wait: bool = False, on_wait=None):
        self.results = Path(results)
        self.path = lock_path(self.results)
        self.wait = wait
        self.on_wait = on_wait
        self._fd: int | None = None

    def owner(self) -> dict:
        try:
            return json.loads(self.path.read_text() or "{}")
        except (OSError, json.JSONDecodeError):
            return {}

    def describe_owner(self) -> str:
        o = self.owner()
        if not o:
            return "another process"
        started = time.strftime("%H:%M:%S", time.localtime(o.get("started", 0)))
        return f"pid {o.get('pid')} on {o.get('host')}, started {started}: {o.get('command', '')}".rstrip(": ")

    def acquire(self) -> "ResultsLock":
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            message = (f"{self.results} is being written by another run ({self.describe_owner()}); "
                       f"a results file has one writer at a time: wait for it, pass --wait, or use another --out")
            if not self.wait:
                os.close(fd)
                raise ResultsLocked(message) from None
            if self.on_wait is not None:
                self.on_wait(message)
            fcntl.flock(fd, fcntl.LOCK_EX)
        owner = {"pid": os.getpid(), "host": socket.gethostname(), "started": time.time(),
                 "command": " ".join(os.path.basename(a) if i == 0 else a for i, a in enumerate(sys.argv))}
        os.ftruncate(fd, 0)
        os.pwrite(fd, (json.dumps(owner) + "\n").encode(), 0)
        self._fd = fd
        return self

    def release(self) -> None:
        fd, self._fd = self._fd, None
        if fd is not None:
            try:
                os.ftruncate(fd, 0)
                fcntl.flock(fd, fcntl.LOCK_UN)
            finally:
                os.close(fd)

    def __enter__(self):
        return self.acquire()

    def __exit__(self, *exc):
        self.release()
