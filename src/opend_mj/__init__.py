"""opend-mj: the OpenD door and drawer opening benchmark on MuJoCo."""

from pathlib import Path

__version__ = "0.1.0"

#: Repository root when installed in development mode (src layout); used for default paths.
PROJECT_ROOT = Path(__file__).resolve().parents[2]
