"""Checkpoint files as plain data: writing them so, and reading them so that loading one runs no code.

Every checkpoint opend-mj writes (the handle solvers', their training state for ``--resume``, the
behaviour-cloning policies and their bundles) holds only tensors, Python numbers, strings, None, and
lists, tuples and dicts of these: configs are stored as dicts (``dataclasses.asdict``) and rebuilt
by the reader, numpy arrays as tensors. Every reader goes through :func:`read_checkpoint`, which
loads with ``torch.load(weights_only=True)``: torch's restricted unpickler builds exactly those types
and refuses any other global a pickle names before calling it, so a file from elsewhere whose
pickle would call a function (``os.system``, ``exec``, ...) is refused and nothing in it runs. The
refusal is a :class:`CheckpointError` (a ``ValueError``), one line naming the file and what it holds;
the command line turns it into exit status 1.
"""

from __future__ import annotations

import dataclasses
import zipfile
from collections import OrderedDict
from pathlib import Path, PurePath


class CheckpointError(ValueError):
    """A file that is not a checkpoint of plain data: refused unread (one line naming the file)."""


def read_checkpoint(path, what: str = "checkpoint"):
    """The contents of the checkpoint file ``path`` (tensors on the CPU), read with
    ``torch.load(weights_only=True)``. ``what`` names the kind of file in the error ("CLIPort
    checkpoint", ...). Raises :class:`CheckpointError` for a file whose pickle names any other
    global (nothing of it runs) or that torch cannot read (damaged, another format), and
    FileNotFoundError for a missing one."""
    import pickle
    import warnings

    import torch

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such {what} file")
    try:
        with warnings.catch_warnings():  # a bare pickle's protocol: the refusal below says what matters
            warnings.filterwarnings("ignore", message="Detected pickle protocol")
            return torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as exc:
        raise CheckpointError(f"{path}: refused as a {what}: {_refusal(path, exc)}; nothing in it ran "
                              "(checkpoints are read with torch.load(weights_only=True))") from None
    except Exception as exc:  # noqa: BLE001 (zip, torch and pickle errors of a damaged or foreign file alike)
        raise CheckpointError(f"{path}: not a readable {what} (a damaged file or another format: "
                              f"{_first_line(exc)})") from None


def _refusal(path: Path, exc: Exception) -> str:
    """What the refused file holds: the globals its pickle names (listed without unpickling them),
    else the reason torch's restricted unpickler gave."""
    import torch

    if zipfile.is_zipfile(path):
        try:
            names = torch.serialization.get_unsafe_globals_in_checkpoint(path)
        except Exception:  # noqa: BLE001 (a damaged archive: torch's own reason below)
            names = []
    else:  # torch.save's legacy format or a bare pickle: pickles one after another
        names = _pickle_globals(path.read_bytes())
    if names:
        return f"its pickle calls or builds {', '.join(sorted(set(names)))}, not tensors and plain data"
    lines = [ln.strip() for ln in str(exc).splitlines() if "nsupported" in ln]
    reason = lines[0] if lines else _first_line(exc)
    return reason if zipfile.is_zipfile(path) else f"not a file of torch.save ({reason})"


def _pickle_globals(data: bytes) -> list[str]:
    """The ``module.name`` globals that the pickles in ``data`` name, read opcode by opcode
    (``pickletools``: nothing is built or called); those read before a malformed opcode where the
    data stops being a pickle."""
    import io
    import pickletools

    stream, names = io.BytesIO(data), []
    try:
        while stream.tell() < len(data):
            pushed, memo = [], {}  # the values of the opcodes read (strings, else None), the memo's strings
            for op, arg, _ in pickletools.genops(stream):
                if op.name == "GLOBAL":  # protocols 0-3: "module name"
                    names.append(".".join(str(arg).split(" ", 1)))
                elif op.name == "STACK_GLOBAL" and len(pushed) >= 2:  # protocol 4+: module and name pushed
                    names.append(f"{pushed[-2]}.{pushed[-1]}")
                elif op.name == "MEMOIZE":
                    memo[len(memo)] = pushed[-1] if pushed else None
                elif op.name in ("PUT", "BINPUT", "LONG_BINPUT"):
                    memo[arg] = pushed[-1] if pushed else None
                elif op.name in ("GET", "BINGET", "LONG_BINGET"):
                    pushed.append(memo.get(arg))
                else:
                    pushed.append(arg if isinstance(arg, str) else None)
    except Exception:  # noqa: BLE001 (not, or no longer, a pickle)
        pass
    return names


def _first_line(exc: BaseException) -> str:
    """The first sentence of an exception's message (torch's go on for several), else its type."""
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    return lines[0].split(". ")[0].rstrip(".") if lines else type(exc).__name__


def plain_data(obj, where: str = "checkpoint"):
    """``obj`` with every value made one that ``torch.load(weights_only=True)`` reads: numpy arrays
    become tensors, numpy scalars Python numbers, dataclasses dicts (``asdict``), paths strings;
    tensors, numbers, strings, bytes, None, lists, tuples and dicts (an OrderedDict stays one, with
    a state dict's ``_metadata``) are kept. Anything else is a TypeError naming where it is (``where`` and the keys)."""
    import numpy as np
    import torch

    if obj is None or type(obj) in (bool, int, float, str, bytes) or isinstance(obj, torch.Tensor):
        return obj  # exact types: a subclass (np.float64 is a float) pickles as its own class
    if isinstance(obj, np.ndarray):
        return torch.from_numpy(np.array(obj))  # a copy the tensor owns
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, PurePath):
        return str(obj)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return plain_data(dataclasses.asdict(obj), where)
    if isinstance(obj, dict):
        items = [(plain_data(k, where), plain_data(v, f"{where}[{k!r}]")) for k, v in obj.items()]
        if not isinstance(obj, OrderedDict):
            return dict(items)
        out = OrderedDict(items)
        if hasattr(obj, "_metadata"):  # a state dict's module versions, which load_state_dict reads
            out._metadata = plain_data(obj._metadata, f"{where}._metadata")
        return out
    if isinstance(obj, (list, tuple)):
        out = [plain_data(v, f"{where}[{i}]") for i, v in enumerate(obj)]
        return out if isinstance(obj, list) else tuple(out)
    raise TypeError(f"{where}: a {type(obj).__module__}.{type(obj).__qualname__} is not plain data "
                    "(a checkpoint holds tensors, numbers, strings, lists, tuples and dicts)")


def write_checkpoint(obj: dict, path) -> None:
    """Write ``obj`` as plain data (:func:`plain_data`) with ``torch.save``: a file that
    :func:`read_checkpoint` reads."""
    import torch

    torch.save(plain_data(obj, str(path)), path)


__all__ = ["CheckpointError", "plain_data", "read_checkpoint", "write_checkpoint"]
