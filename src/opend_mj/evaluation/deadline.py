"""A wall-clock limit on one episode (`opend run --episode-timeout`): an agent that hangs ends its
episode, not the run.

`episode_deadline(seconds)` arms a ``SIGALRM`` timer around one episode: when it fires, `EpisodeTimeout`
is raised wherever the episode's Python code is (a ``while True`` loop, a ``time.sleep``, a lock that
is never released), and again every second until the episode gives up (an agent whose own ``except``
swallows the first one). It derives from ``BaseException`` so that an agent's ``except Exception`` does
not catch it. In a worker process (not in the process that writes the results), a watchdog thread
also ends the whole worker `HARD_EXIT_GRACE` seconds later, for code that the signal cannot reach;
the pool then records that episode as an error and runs the others again (`evaluation.pool`).

The timer needs the main thread of its process (signals are delivered there): elsewhere it is off.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import sys
import threading
from contextlib import contextmanager

#: Default wall-clock limit of one episode (s): some 40 times a planner episode on a busy core.
DEFAULT_EPISODE_TIMEOUT = 600.0

#: Seconds after the limit at which a worker process whose episode still runs is ended.
HARD_EXIT_GRACE = 30.0

#: Exit status of a worker process ended by the watchdog.
HARD_EXIT_STATUS = 124


class EpisodeTimeout(BaseException):  # noqa: N818 (a limit, not an error of the code)
    """The episode ran past its wall-clock limit."""


def _in_worker_process() -> bool:
    return multiprocessing.parent_process() is not None


@contextmanager
def episode_deadline(seconds: float | None, hard_exit: bool | None = None):
    """Raise `EpisodeTimeout` in the body after ``seconds`` of wall-clock time (None or 0: no limit).

    ``hard_exit``: end this process `HARD_EXIT_GRACE` s after the limit if the body is still running
    (default: only in a worker process of a pool)."""
    if not seconds or seconds <= 0 or threading.current_thread() is not threading.main_thread() \
            or not hasattr(signal, "setitimer"):
        yield
        return
    message = f"the episode ran past its wall-clock limit of {seconds:g} s (--episode-timeout)"

    def on_alarm(signum, frame):
        raise EpisodeTimeout(message)

    previous = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, float(seconds), 1.0)
    done = threading.Event()
    if hard_exit if hard_exit is not None else _in_worker_process():
        def watch():
            if not done.wait(float(seconds) + HARD_EXIT_GRACE):
                sys.stderr.write(f"opend: {message}; the episode did not stop, ending worker {os.getpid()}\n")
                sys.stderr.flush()
                os._exit(HARD_EXIT_STATUS)

        threading.Thread(target=watch, name="episode-watchdog", daemon=True).start()
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, previous)
        done.set()
