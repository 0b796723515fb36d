"""Learned handle solvers (Faster R-CNN detector, CLIPort-style affordance model), data and training.

Importing this package keeps PyTorch from loading Triton (``sys.modules["triton"] = None``):
Triton's bundled LLVM crashes the process (segmentation fault) when it is loaded after Mesa's
llvmpipe, i.e. after any off-screen MuJoCo render on a CPU machine, which is exactly what
`opend run` does before it builds a solver. Nothing here uses ``torch.compile``. Set
``OPEND_ALLOW_TRITON=1`` to keep Triton importable.
"""

import os as _os
import sys as _sys

if "triton" not in _sys.modules and not _os.environ.get("OPEND_ALLOW_TRITON"):
    _sys.modules["triton"] = None  # type: ignore[assignment]


_LOADED: dict = {}


def checkpoint_tensors(checkpoint) -> dict:
    """A checkpoint's model tensors as float32 (a training checkpoint's ``model`` entry, or a bare
    state dict), for fine-tuning from it (read as plain data: `checkpoint_io.read_checkpoint`)."""
    from opend_mj.policy.learned.checkpoint_io import read_checkpoint

    src = read_checkpoint(checkpoint, "checkpoint to start from (--init)")
    return {k: v.float() for k, v in src.get("model", src).items()}


def load_checkpoint(checkpoint, default, what: str, train_command: str, build, device=None):
    """``(model in eval mode on device, config, checkpoint dict)``, cached per path and device.

    ``default``: the file name of the checkpoint to load when ``checkpoint`` is None, found by
    `opend_mj.resources.default_checkpoint` (``checkpoints/`` here, else the shipped one).
    ``build(ckpt) -> (model, config)`` makes the untrained model from the checkpoint's config; the
    weights are loaded here (as float32). A missing file is a clear error naming the file and the
    command that makes one; a file that is not plain data is refused unread
    (`checkpoint_io.read_checkpoint`).
    """
    from pathlib import Path

    import torch

    from opend_mj.policy.learned.checkpoint_io import read_checkpoint
    from opend_mj.resources import default_checkpoint

    path = Path(checkpoint) if checkpoint is not None else default_checkpoint(default)
    device = device or ("cuda" if torch.cuda.is_available() else "cpu")
    key = (str(path.resolve()), device, what)
    if key not in _LOADED:
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no {what} checkpoint; train one with `{train_command}` "
                                    "(or pass checkpoint=)")
        ckpt = read_checkpoint(path, f"{what} checkpoint")
        model, config = build(ckpt)
        model.load_state_dict({k: v.float() for k, v in ckpt["model"].items()})
        model.eval().to(device)
        _LOADED[key] = (model, config, ckpt)
    return _LOADED[key]
