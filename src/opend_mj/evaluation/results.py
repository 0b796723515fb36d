"""The results file: one JSON line per episode, resumable and safe against a killed run.

Written by the parent process only, one ``write()`` of a full line, then flush and ``os.fsync``. On
load, a torn last line (no newline, or not JSON) is dropped and truncated away, so after ``kill -9``
a rerun neither loses nor repeats an episode. When every job of a run is in the file, `sort_results`
rewrites it (atomically: temporary file, fsync, rename) in job order, so that the same command gives
the same file whatever the worker count or backend. Records of other runs keep their place, before
this run's.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from opend_mj.evaluation.episode import EpisodeJob, episode_key


def load_results(path: Path, repair: bool = True) -> list[dict]:
    """All complete records of a results file; a torn last line is dropped (and truncated away)."""
    path = Path(path)
    if not path.exists():
        return []
    data = path.read_bytes()
    records: list[dict] = []
    good_end = 0
    pos = 0
    number = 0  # of the line being read, from 1
    while pos < len(data):
        nl = data.find(b"\n", pos)
        if nl < 0:  # last line without newline: torn
            break
        line = data[pos:nl]
        pos = nl + 1
        number += 1
        if line.strip():
            try:
                record = json.loads(line)
            except (json.JSONDecodeError, UnicodeDecodeError):
                if pos >= len(data):  # a torn last line that happens to end in a newline
                    break
                raise ValueError(f"{path}: corrupt line {number} in the middle of the file at byte {pos}") from None
            _check_record(record, path, number)
            records.append(record)
        good_end = pos
    if repair and good_end < len(data):
        with open(path, "r+b") as f:
            f.truncate(good_end)
            f.flush()
            os.fsync(f.fileno())
    return records


def _check_record(record, path: Path, line: int) -> None:
    """A parsed line must be an episode record: a JSON object with the fields of its key."""
    from opend_mj.evaluation.episode import EPISODE_FIELDS, _REQUIRED

    if not isinstance(record, dict):
        raise ValueError(f"{path}: line {line} is not an episode record (a JSON {type(record).__name__})")
    missing = [f.name for f in EPISODE_FIELDS if f.in_key and f.default is _REQUIRED and f.name not in record]
    if missing:
        raise ValueError(f"{path}: line {line} is not an episode record (no {', '.join(missing)})")
    for f in EPISODE_FIELDS:
        if f.in_key and f.name in record:
            try:
                f.normalise(record[f.name])
            except (TypeError, ValueError):
                raise ValueError(f"{path}: line {line}: {f.name} {record[f.name]!r} is not valid") from None


class ResultsWriter:
    """Appends one record per line: one write of the full line, flush, fsync (parent process only)."""

    def __init__(self, path: Path):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)

    def write(self, record: dict) -> None:
        line = (json.dumps(record, default=_json_default) + "\n").encode()
        n = os.write(self._fd, line)
        if n != len(line):
            raise OSError(f"short write to {self.path}")
        os.fsync(self._fd)

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o)}")


def sort_results(path: Path, jobs: list[EpisodeJob], attempts: int = 5) -> bool:
    """Rewrite ``path`` with this run's records in job order (others first, in their order).

    Atomic (a temporary file, fsync, rename), so a ``kill -9`` leaves either the old or the new file.
    Never drops a line: the new file holds exactly the lines read, and if the file changed while it
    was being sorted (a writer that does not take the run's lock appended to it), it is read again,
    up to ``attempts`` times, then left as it is. Returns whether the file was rewritten (not when
    it is already in order, or jobs are missing).
    """
    path = Path(path)
    for _ in range(attempts):
        before = _stamp(path)
        records = load_results(path)
        if not records:
            return False
        index = {j.key(): i for i, j in enumerate(jobs)}
        if not set(index) <= {episode_key(r) for r in records}:
            return False  # an incomplete run: leave the file as it is
        data = path.read_bytes()
        lines = [ln for ln in data.split(b"\n") if ln.strip()]
        if len(lines) != len(records):
            return False
        order = sorted(range(len(records)), key=lambda i: (1, index[k], i) if (k := episode_key(records[i])) in index
                       else (0, 0, i))
        if order == list(range(len(records))):
            return False
        new = b"".join(lines[i] + b"\n" for i in order)
        tmp = path.with_name(f".{path.name}.sorting")
        with open(tmp, "wb") as f:
            f.write(new)
            f.flush()
            os.fsync(f.fileno())
        if _stamp(path) != before or path.read_bytes() != data:
            tmp.unlink(missing_ok=True)  # someone wrote meanwhile: sort again from what is there now
            continue
        os.replace(tmp, path)
        try:
            dir_fd = os.open(path.parent, os.O_RDONLY)
            try:
                os.fsync(dir_fd)
            finally:
                os.close(dir_fd)
        except OSError:
            pass
        return True
    return False


def _stamp(path: Path) -> tuple:
    st = os.stat(path)
    return (st.st_ino, st.st_size, st.st_mtime_ns)
