"""The channel between the simulator and an agent process (`evaluation.agent_process`): the wire format.

One pipe each way, a message at a time, each after its u32 length. A message is a one-byte tag and
its body: plain data as JSON, arrays as raw bytes after a JSON header of their keys, dtypes and
shapes (numbers only: no object arrays), so that nothing is ever unpickled. An observation's layout
goes once; while it stays the same, a step's message is its array bytes alone. An action is float64
bytes after its shape. The simulator reads an agent's message by these fixed rules, at most
`MAX_AGENT_MESSAGE` bytes of it.
"""

from __future__ import annotations

import json
import math
import os
import struct
from dataclasses import asdict

import numpy as np

#: The largest message the simulator accepts from an agent (bytes): an action, an error, extra fields.
MAX_AGENT_MESSAGE = 1 << 20

# message tags (one byte at the start of every message)
RESET, OBS_FULL, OBS_SAME, INFO, QUIT = b"R", b"O", b"o", b"I", b"Q"
READY, ACTION, STOP, JSON, ERROR = b"K", b"A", b"N", b"J", b"E"
#: dtypes an observation array may have (no object arrays: raw bytes only)
_ARRAY_KINDS = "biuf"
_U32 = struct.Struct("<I")
_F8 = np.dtype("<f8")


class AgentFailure(Exception):
    """The agent could not act: it raised, ran out of memory, died or broke the protocol.

    ``error_kind`` and ``remote_traceback`` (the agent process's traceback text, or None) are what
    `runner.error_record` writes into the episode's record."""

    def __init__(self, reason: str, error_kind: str = "exception", remote_traceback: str | None = None):
        super().__init__(reason)
        self.error_kind = error_kind
        self.remote_traceback = remote_traceback


# --------------------------------------------------------------------------------------------------
# The wire format: tag + u32 header length + JSON header + padding, then raw array bytes (each
# padded to 8 bytes); on the pipe every message goes after its u32 length
# --------------------------------------------------------------------------------------------------
def _align(n: int) -> int:
    return n + (-n % 8)


def _header_bytes(tag: bytes, arrays: list, values: dict) -> bytes:
    header = json.dumps({"arrays": [[k, a.dtype.str, list(a.shape)] for k, a in arrays], "values": values}).encode()
    head = tag + _U32.pack(len(header)) + header
    return head + bytes(_align(len(head)) - len(head))


def _array_chunks(arrays: list) -> list[bytes]:
    chunks = []
    for _, a in arrays:
        data = a.tobytes()  # C order, also of a non-contiguous array
        chunks.append(data)
        if len(data) % 8:
            chunks.append(bytes(-len(data) % 8))
    return chunks


def _pack(tag: bytes, arrays: dict, values: dict) -> bytes:
    items = list(arrays.items())
    return b"".join([_header_bytes(tag, items, values), *_array_chunks(items)])


def _read_header(message: bytes) -> tuple[dict, int]:
    """(header, offset of the array bytes) of a full message."""
    (size,) = _U32.unpack_from(message, 1)
    return json.loads(message[5:5 + size]), _align(5 + size)


def _layout(header: dict) -> tuple[list, int]:
    """[(key, dtype, shape, offset)] of a header's arrays, and the bytes they take (padded)."""
    out, offset = [], 0
    for key, dtype, shape in header["arrays"]:
        dt = np.dtype(dtype)
        if dt.kind not in _ARRAY_KINDS:
            raise ValueError(f"array {key!r}: dtype {dtype!r} is not a plain number type")
        shape = tuple(int(x) for x in shape)
        out.append((key, dt, shape, offset))
        offset += _align(math.prod(shape) * dt.itemsize)
    return out, offset


def _arrays(layout, message: bytes, start: int, nbytes: int) -> dict:
    """The arrays of ``layout`` from ``message`` at ``start``: writable views of one fresh (aligned)
    copy of its array bytes, so an agent may keep or change them."""
    if len(message) - start != nbytes:
        raise ValueError(f"message of {len(message)} bytes, its layout says {start + nbytes}")
    raw = np.frombuffer(message, np.uint8, nbytes, start).copy() if nbytes else np.empty(0, np.uint8)
    return {key: np.ndarray(shape, dt, raw, offset) for key, dt, shape, offset in layout}


def _unpack(message: bytes) -> tuple[dict, dict]:
    """(arrays, plain values) of a full message."""
    header, start = _read_header(message)
    layout, nbytes = _layout(header)
    return _arrays(layout, message, start, nbytes), header["values"]


class ObservationEncoder:
    """Simulator side: observations -> messages. The layout (keys, dtypes, shapes) and the text
    values go once; while they stay the same, a step's message is its array bytes alone."""

    def __init__(self):
        self._signature = None

    def encode(self, obs: dict) -> bytes:
        arrays, values = [], {}
        for key, value in obs.items():
            if isinstance(value, np.ndarray) and value.dtype.kind in _ARRAY_KINDS:
                arrays.append((key, value))
            elif isinstance(value, (str, int, float, bool)) or value is None:
                values[key] = value
            else:  # anything else of the scene never crosses
                raise TypeError(f"observation {key!r} is a {type(value).__name__}, not an array or plain value")
        signature = (tuple((k, a.dtype, a.shape) for k, a in arrays), tuple(values.items()))
        chunks = _array_chunks(arrays)
        if signature == self._signature:
            return b"".join([OBS_SAME, *chunks])
        self._signature = signature
        return b"".join([_header_bytes(OBS_FULL, arrays, values), *chunks])


class ObservationDecoder:
    """Agent side: messages -> observation dicts (fresh, writable arrays every step)."""

    def __init__(self):
        self._layout, self._nbytes, self._values = None, 0, None

    def decode(self, message: bytes) -> dict:
        start = 1
        if message[:1] == OBS_FULL:
            header, start = _read_header(message)
            self._layout, self._nbytes = _layout(header)
            self._values = header["values"]
        return {**_arrays(self._layout, message, start, self._nbytes), **self._values}


def encode_action(action) -> bytes:
    """Agent side: an action (array-like of numbers, any shape) or None -> a message."""
    if action is None:
        return STOP
    a = np.ascontiguousarray(action, dtype="<f8")
    if a.ndim > 4:
        raise ValueError(f"action has {a.ndim} dimensions")
    return b"".join([ACTION, bytes([a.ndim]), struct.pack(f"<{a.ndim}I", *a.shape), a.tobytes()])


def decode_action(message: bytes) -> np.ndarray:
    """Simulator side: an action message -> a float64 array (its length checked against its shape)."""
    ndim = message[1] if len(message) > 1 else 0
    if len(message) < 2 + 4 * ndim or ndim > 4:
        raise AgentFailure("the agent sent a malformed action message", "protocol")
    shape = struct.unpack_from(f"<{ndim}I", message, 2)
    start = 2 + 4 * ndim
    count = math.prod(shape)
    if len(message) != start + 8 * count:
        raise AgentFailure("the agent sent a malformed action message", "protocol")
    return np.frombuffer(message, _F8, count, start).reshape(shape).copy()  # writable, the simulator's own


def encode_info(info) -> bytes:
    """`EpisodeInfo` -> a message of plain data (the hand's spec and the camera as dicts and arrays)."""
    view = info.camera_view
    arrays = {"action_low": np.asarray(info.action_low, float), "action_high": np.asarray(info.action_high, float),
              "camera_pos": np.asarray(view.pos, float), "camera_rot": np.asarray(view.rot, float)}
    values = {"instruction": info.instruction, "hand": info.hand, "hand_spec": asdict(info.hand_spec),
              "camera_intrinsics": asdict(view.intrinsics), "control_dt": float(info.control_dt),
              "time_limit": float(info.time_limit), "action_names": list(info.action_names), "seed": int(info.seed)}
    return _pack(RESET, arrays, values)


def decode_info(message: bytes):
    from opend_mj.policy.agents import EpisodeInfo
    from opend_mj.sim.camera import CameraIntrinsics, CameraView
    from opend_mj.sim.hands.spec import HandSpec

    arrays, v = _unpack(message)
    view = CameraView(CameraIntrinsics(**v["camera_intrinsics"]), pos=arrays["camera_pos"], rot=arrays["camera_rot"])
    return EpisodeInfo(instruction=v["instruction"], hand=v["hand"], hand_spec=HandSpec(**v["hand_spec"]),
                       camera_view=view, control_dt=v["control_dt"], time_limit=v["time_limit"],
                       action_names=tuple(v["action_names"]), action_low=arrays["action_low"],
                       action_high=arrays["action_high"], seed=v["seed"])


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (set, tuple)):
        return list(o)
    raise TypeError(f"{type(o).__name__} is not plain data")


def json_message(tag: bytes, value) -> bytes:
    return tag + json.dumps(value, default=_json_default).encode()


# --------------------------------------------------------------------------------------------------
# The pipes: one each way, a message at a time, each after its u32 length (os.read / os.write:
# half the cost per round trip of `multiprocessing.Connection`'s two reads per message)
# --------------------------------------------------------------------------------------------------
def write_message(fd: int, message: bytes) -> None:
    view = memoryview(_U32.pack(len(message)) + message)
    while view:
        view = view[os.write(fd, view):]


def read_message(fd: int, limit: int | None = None) -> bytes:
    """The next message on ``fd``; EOFError when the other end is closed, ValueError for one over
    ``limit`` bytes (nothing of it is kept)."""
    data = os.read(fd, 1 << 16)
    while 0 < len(data) < 4:
        data += os.read(fd, 4 - len(data))
    if not data:
        raise EOFError
    (size,) = _U32.unpack_from(data)
    if limit is not None and size > limit:
        raise ValueError(f"a message of {size} bytes (at most {limit})")
    if len(data) - 4 == size:
        return data[4:]
    buf = bytearray(data[4:])
    while len(buf) < size:
        more = os.read(fd, min(size - len(buf), 1 << 20))
        if not more:
            raise EOFError
        buf += more
    if len(buf) != size:
        raise ValueError("a message longer than its length")
    return bytes(buf)
