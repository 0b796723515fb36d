"""Agents in a process of their own (`opend run --policy`): the simulator stays out of the agent's reach.

The simulator (an `opend run` worker) starts one agent process per agent spec with the ``spawn``
method: a fresh interpreter that inherits none of the simulator's objects. What crosses is one
`multiprocessing` pipe, and on it only:

- simulator -> agent: the episode information (`EpisodeInfo` as plain data: JSON and raw array
  bytes) and each observation (numpy arrays as raw bytes, the instruction as text);
- agent -> simulator: an action (float64 bytes), a stop, an error (JSON), or the agent's extra record
  fields (JSON). Nothing from the agent is unpickled: its messages are raw bytes with a one-byte tag,
  read by fixed rules (`evaluation.agent_channel`), at most `MAX_AGENT_MESSAGE` bytes each.

Before the agent's code is imported, the agent process drops every Linux capability (bounding,
effective, permitted, inheritable and ambient sets; so that even when run by root it lacks
CAP_SYS_PTRACE, which would let it read any process's memory), sets no-new-privileges, asks to be
killed when its simulator dies, and sets its address-space limit (``RLIMIT_AS``, ``--agent-memory``).
The processes that hold the simulator and the results make themselves non-dumpable
(`make_undumpable`): a process of the same user without CAP_SYS_PTRACE can then open neither their
``/proc/<pid>/mem`` nor ``maps``, nor ptrace them.

Not contained (see docs/evaluation.md): the agent runs as the same user, so it can read and write
the files that user can, and signal the user's processes.
"""

from __future__ import annotations

import ctypes
import hashlib
import importlib.machinery
import json
import os
import resource
import sys
import traceback
from functools import lru_cache
from pathlib import Path

import numpy as np

from opend_mj.evaluation.agent_channel import (
    ACTION,
    ERROR,
    INFO,
    JSON,
    MAX_AGENT_MESSAGE,
    OBS_FULL,
    OBS_SAME,
    QUIT,
    READY,
    RESET,
    STOP,
    AgentFailure,
    ObservationDecoder,
    ObservationEncoder,
    decode_action,
    decode_info,
    encode_action,
    encode_info,
    json_message,
    read_message,
    write_message,
)

#: The agent runs in its own process (the default) / in the simulator's process (`--agent-in-process`).
ISOLATION_PROCESS = "process"
ISOLATION_IN_PROCESS = "in-process"
ISOLATIONS = (ISOLATION_PROCESS, ISOLATION_IN_PROCESS)

#: Fields every record of an agent's episode carries to say how it was run.
CONTAINMENT_FIELDS = ("agent_isolation", "agent_memory", "agent_sha256", "opend_version")

#: Share of the machine's physical memory an agent process may map by default (`--agent-memory`).
DEFAULT_MEMORY_SHARE = 0.5

#: Seconds a closing agent process is given to exit before it is killed.
CLOSE_GRACE = 2.0


# --------------------------------------------------------------------------------------------------
# Where an agent comes from, and what a record says about how it ran
# --------------------------------------------------------------------------------------------------
def source_path(target: str) -> Path | None:
    """The file that defines an agent's module (``target``: a file path or a dotted module name),
    found without importing anything (no package ``__init__`` runs); None if not on the path."""
    if target.endswith(".py"):
        return Path(target)
    search = None
    spec = None
    parts = target.split(".")
    for i in range(len(parts)):
        spec = importlib.machinery.PathFinder.find_spec(".".join(parts[: i + 1]), search)
        if spec is None:
            return None
        search = spec.submodule_search_locations
    origin = getattr(spec, "origin", None)
    return Path(origin) if origin and os.path.isfile(origin) else None


@lru_cache(maxsize=64)
def source_sha256(target: str) -> str | None:
    """sha256 (hex) of the agent's source file: the ``.py`` file of a file spec or of a module spec's
    module (the file that defines the class; not what it imports, nor its checkpoints)."""
    path = source_path(target)
    if path is None:
        return None
    try:
        return hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError:
        return None


def containment_fields(job) -> dict:
    """How ``job``'s agent was run, for its record (`CONTAINMENT_FIELDS`); {} for a planner episode."""
    if not getattr(job, "policy", None):
        return {}
    from opend_mj import __version__

    target = job.policy.rpartition(":")[0] or job.policy
    return {"agent_isolation": job.agent_isolation, "agent_memory": job.agent_memory,
            "agent_sha256": job.agent_sha256 or source_sha256(target), "opend_version": __version__}


def default_agent_memory() -> int:
    """Bytes of address space an agent process may map by default: `DEFAULT_MEMORY_SHARE` of RAM."""
    try:
        total = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError):
        total = 8 << 30
    return int(total * DEFAULT_MEMORY_SHARE)


def parse_memory(text: str) -> int | None:
    """``--agent-memory`` -> bytes: ``4G``, ``512M``, ``1.5GiB``, a number of bytes; ``0`` or
    ``none``: no limit (None). Raises ValueError."""
    value = str(text).strip().lower().removesuffix("ib").removesuffix("b")
    if value in ("0", "none", "off", ""):
        return None
    scale = {"k": 1 << 10, "m": 1 << 20, "g": 1 << 30, "t": 1 << 40}.get(value[-1:], 1)
    number = value[:-1] if scale != 1 else value
    try:
        size = int(float(number) * scale)
    except ValueError:
        raise ValueError(f"{text!r} is no memory size (e.g. 4G, 512M, 0 for no limit)") from None
    if size < (64 << 20):
        raise ValueError(f"{text!r}: an agent process needs at least 64M (0 for no limit)")
    return size


def memory_text(size: int | None) -> str:
    return "no limit" if not size else f"{size / (1 << 30):.3g} GiB"


# --------------------------------------------------------------------------------------------------
# Process hardening (Linux; elsewhere these do nothing)
# --------------------------------------------------------------------------------------------------
_PR_SET_PDEATHSIG, _PR_SET_DUMPABLE, _PR_CAPBSET_DROP = 1, 4, 24
_PR_SET_NO_NEW_PRIVS, _PR_CAP_AMBIENT, _PR_CAP_AMBIENT_CLEAR_ALL = 38, 47, 4
_CAP_VERSION_3 = 0x20080522


def _libc():
    if not sys.platform.startswith("linux"):
        return None
    try:
        return ctypes.CDLL(None, use_errno=True)
    except OSError:
        return None


def make_undumpable() -> bool:
    """``prctl(PR_SET_DUMPABLE, 0)`` on this process: a same-user process without CAP_SYS_PTRACE
    can no longer read or write its memory (``/proc/<pid>/mem``), its maps, or ptrace it; no core
    dumps. Returns whether it took effect."""
    libc = _libc()
    return bool(libc) and libc.prctl(_PR_SET_DUMPABLE, 0, 0, 0, 0) == 0


def _drop_privileges() -> None:
    """In the agent process: every capability dropped for good (bounding set first, while
    CAP_SETPCAP is still held), no new privileges on exec, killed when the simulator dies."""
    libc = _libc()
    if libc is None:
        return
    libc.prctl(_PR_SET_PDEATHSIG, 9, 0, 0, 0)  # SIGKILL
    try:
        last = int(Path("/proc/sys/kernel/cap_last_cap").read_text())
    except (OSError, ValueError):
        last = 63
    for cap in range(last + 1):
        libc.prctl(_PR_CAPBSET_DROP, cap, 0, 0, 0)  # EPERM without CAP_SETPCAP: nothing to drop then
    libc.prctl(_PR_CAP_AMBIENT, _PR_CAP_AMBIENT_CLEAR_ALL, 0, 0, 0)
    header = (ctypes.c_uint32 * 2)(_CAP_VERSION_3, 0)
    data = (ctypes.c_uint32 * 6)()  # effective, permitted, inheritable x 2 words: all zero
    libc.capset(header, data)
    libc.prctl(_PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0)


# --------------------------------------------------------------------------------------------------
# The agent process
# --------------------------------------------------------------------------------------------------
def _is_memory_error(exc: BaseException) -> bool:
    text = str(exc).lower()
    return isinstance(exc, MemoryError) or (isinstance(exc, RuntimeError)
                                            and ("can't allocate memory" in text or "out of memory" in text))


def _error_message(exc: BaseException, memory: int | None) -> bytes:
    from opend_mj.policy.learned.checkpoint_io import CheckpointError

    if isinstance(exc, CheckpointError):  # a file refused unread: the run stops (exit 1), naming it
        return json_message(ERROR, {"kind": "checkpoint", "reason": str(exc), "traceback": None})
    if _is_memory_error(exc):
        exc.__traceback__ = None  # frees what the agent allocated before the reply is written
        reason = (f"the agent ran out of its memory limit of {memory_text(memory)} (--agent-memory): "
                  f"{type(exc).__name__}: {exc}".rstrip(": "))
        return json_message(ERROR, {"kind": "agent_memory", "reason": reason, "traceback": reason})
    tb = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
    reason = f"{type(exc).__name__}: {exc}".splitlines()[0] if str(exc) else type(exc).__name__
    return json_message(ERROR, {"kind": "exception", "reason": reason, "traceback": tb})


def agent_main(inbox, outbox, spec: str, args: tuple, memory: int | None) -> None:
    """The agent process: load the agent, then answer the simulator's messages (on ``inbox``, a
    `multiprocessing` connection read as a raw pipe; replies on ``outbox``) until told to quit."""
    rfd, wfd = inbox.fileno(), outbox.fileno()
    _drop_privileges()
    if memory:
        resource.setrlimit(resource.RLIMIT_AS, (memory, memory))
    try:
        from opend_mj.evaluation.agent_loader import load_agent
        from opend_mj.policy.agents import agent_control, agent_image_every, agent_images, agent_name

        agent = load_agent(spec, args)
        write_message(wfd, json_message(READY, {"name": agent_name(agent), "control": agent_control(agent),
                                           "images": agent_images(agent)}))
    except BaseException as exc:  # noqa: BLE001 (told to the simulator, which records it)
        write_message(wfd, _error_message(exc, memory))
        return
    decoder = ObservationDecoder()
    while True:
        try:
            message = read_message(rfd)
        except (EOFError, OSError, ValueError):
            return  # the simulator is gone
        tag = message[:1]
        try:
            if tag in (OBS_FULL, OBS_SAME):
                reply = encode_action(agent.act(decoder.decode(message)))
            elif tag == RESET:
                agent.reset(decode_info(message))
                reply = json_message(JSON, {"image_every": agent_image_every(agent)})
            elif tag == INFO:
                info = agent.episode_info() if callable(getattr(agent, "episode_info", None)) else {}
                reply = json_message(JSON, dict(info or {}))
            elif tag == QUIT:
                close = getattr(agent, "close", None)
                if callable(close):
                    close()
                return
            else:
                reply = json_message(ERROR, {"kind": "protocol", "reason": f"unknown message {tag!r}",
                                               "traceback": None})
        except BaseException as exc:  # noqa: BLE001 (an agent's error is its episode's, not the process's end)
            reply = _error_message(exc, memory)
        write_message(wfd, reply)


# --------------------------------------------------------------------------------------------------
# The simulator's side
# --------------------------------------------------------------------------------------------------
class AgentProcess:
    """An agent in its own process, behind the agent interface (``name``, ``control``, ``images``,
    ``reset``, ``act``, ``episode_info``, ``close``), for the simulator to call as if it were the agent.

    ``memory``: the agent process's address-space limit in bytes (None: no limit). Any failure
    raises `AgentFailure`; after one the process is in an unknown state: `close` it."""

    def __init__(self, spec: str, args: tuple = (), memory: int | None = None):
        import multiprocessing

        make_undumpable()
        self.spec, self.args, self.memory = spec, tuple(args), memory
        ctx = multiprocessing.get_context("spawn")
        self._inbox, agent_outbox = ctx.Pipe(duplex=False)
        agent_inbox, self._outbox = ctx.Pipe(duplex=False)
        self._process = ctx.Process(target=agent_main, args=(agent_inbox, agent_outbox, spec, self.args, memory),
                                    name="opend-agent", daemon=False)
        self._process.start()
        agent_inbox.close()
        agent_outbox.close()
        self._rfd, self._wfd = self._inbox.fileno(), self._outbox.fileno()
        # closed before the pool joins its children at exit (an agent process is not a daemon, so
        # that it may start processes of its own)
        from multiprocessing.util import Finalize

        self._state = {"graceful": True}
        self._finalizer = Finalize(self, AgentProcess._shut,
                                   args=(self._inbox, self._outbox, self._process, self._state), exitpriority=100)
        self._encoder = ObservationEncoder()
        try:
            ready = self._reply((READY,))
        except BaseException:
            self.close(graceful=False)
            raise
        self.name, self.control, self.images = ready["name"], ready["control"], ready["images"]
        self.image_every = 1  # until the agent's reset says otherwise

    @property
    def pid(self) -> int | None:
        return self._process.pid

    def alive(self) -> bool:
        return self._process.is_alive() and not self._outbox.closed

    def _receive(self) -> bytes:
        try:
            return read_message(self._rfd, MAX_AGENT_MESSAGE)
        except (EOFError, ConnectionError):
            raise AgentFailure(self._death(), "agent_died") from None
        except ValueError as exc:  # over MAX_AGENT_MESSAGE
            raise AgentFailure(f"the agent sent a message the simulator refuses ({exc})", "protocol") from None

    def _death(self) -> str:
        import signal

        self._process.join(CLOSE_GRACE)
        code = self._process.exitcode
        if code is None:
            return "the agent process closed its channel"
        if code < 0:
            try:
                how = f"killed by {signal.Signals(-code).name}"
            except ValueError:
                how = f"killed by signal {-code}"
        else:
            how = f"exit status {code}"
        limit = f"; its memory limit is {memory_text(self.memory)}" if self.memory and code < 0 else ""
        return f"the agent process died ({how}{limit})"

    def _reply(self, expected: tuple[bytes, ...]):
        message = self._receive()
        tag = message[:1]
        if tag == ERROR:
            try:
                err = json.loads(message[1:])
                kind, reason, tb = str(err["kind"]), str(err["reason"]), err.get("traceback")
            except (ValueError, KeyError, TypeError):
                raise AgentFailure("the agent sent a malformed error message", "protocol") from None
            raise AgentFailure(reason, kind if kind in ("exception", "agent_memory", "protocol", "checkpoint") else "exception",
                               tb if isinstance(tb, str) else None)
        if tag not in expected:
            raise AgentFailure(f"the agent answered {tag!r} where {b'/'.join(expected)!r} was expected", "protocol")
        if tag == ACTION:
            return decode_action(message)
        if tag == STOP:
            return None
        try:
            value = json.loads(message[1:])
        except ValueError:
            raise AgentFailure("the agent sent malformed JSON", "protocol") from None
        if not isinstance(value, dict):
            raise AgentFailure("the agent sent JSON that is not an object", "protocol")
        return value

    def _send(self, message: bytes) -> None:
        try:
            write_message(self._wfd, message)
        except (BrokenPipeError, ConnectionError, EOFError):
            raise AgentFailure(self._death(), "agent_died") from None

    def reset(self, info) -> None:
        self._encoder = ObservationEncoder()
        self._send(encode_info(info))
        every = self._reply((JSON,)).get("image_every", 1)
        if isinstance(every, bool) or not isinstance(every, int) or every < 1:
            raise AgentFailure(f"the agent sent image_every {every!r} (an integer >= 1)", "protocol")
        #: control steps between the agent's images (`policy.agents.agent_image_every`), read at reset
        self.image_every = every

    def act(self, obs: dict) -> np.ndarray | None:
        self._send(self._encoder.encode(obs))
        return self._reply((ACTION, STOP))

    def episode_info(self) -> dict:
        self._send(INFO)
        return self._reply((JSON,))

    def close(self, graceful: bool = True) -> None:
        """End the agent process: told to quit and given `CLOSE_GRACE` s (``graceful``), then killed."""
        self._state["graceful"] = self._state["graceful"] and graceful
        self._finalizer()

    @staticmethod
    def _shut(inbox, outbox, process, state) -> None:
        try:
            if state["graceful"] and process.is_alive() and not outbox.closed:
                try:
                    write_message(outbox.fileno(), QUIT)
                except OSError:
                    pass
                process.join(CLOSE_GRACE)
        finally:  # even when interrupted (the episode's wall-clock limit fires again every second)
            if process.is_alive():
                process.kill()  # SIGKILL: an agent cannot catch it; a live agent would hang the worker's exit
            inbox.close()
            outbox.close()
        process.join(CLOSE_GRACE)


_PROCESSES: dict[tuple, AgentProcess] = {}


def contained_agent(spec: str, args: tuple, memory: int | None) -> AgentProcess:
    """The agent process of (spec, args, memory) in this simulator process, started on first use
    and again after a failure (`discard`)."""
    key = (spec, tuple(args), memory)
    proc = _PROCESSES.get(key)
    if proc is None or not proc.alive():
        if proc is not None:
            proc.close(graceful=False)
        _PROCESSES.pop(key, None)
        proc = AgentProcess(spec, args, memory)
        _PROCESSES[key] = proc
    return proc


def discard(proc: AgentProcess) -> None:
    """End an agent process whose state is unknown (it failed, or its episode ran out of time)."""
    for key, value in list(_PROCESSES.items()):
        if value is proc:
            del _PROCESSES[key]
    proc.close(graceful=False)


def describe_agent(spec: str, args: tuple = (), memory: int | None = None) -> dict:
    """``{"name", "control", "images"}`` of an agent, read in an agent process of its own (so that the
    process asking, e.g. the one that writes the results, never imports the agent). Raises
    `AgentFailure` with the agent's reason if it cannot be loaded."""
    proc = AgentProcess(spec, args, memory)
    try:
        return {"name": proc.name, "control": proc.control, "images": proc.images}
    finally:
        proc.close()


def with_containment(jobs, isolation: str = ISOLATION_PROCESS, memory: int | None = None) -> list:
    """``jobs`` with their agent's containment set (jobs without an agent unchanged): the isolation,
    the agent process's memory limit (bytes; None: none) and the sha256 of the agent's source,
    read here once (the process that writes the records)."""
    import dataclasses

    if isolation not in ISOLATIONS:
        raise ValueError(f"agent isolation must be one of {ISOLATIONS}, not {isolation!r}")
    return [dataclasses.replace(j, agent_isolation=isolation, agent_memory=memory,
                                agent_sha256=source_sha256(j.policy.rpartition(":")[0] or j.policy))
            if j.policy else j for j in jobs]
