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
