"""opend-mj: the OpenD door and drawer opening benchmark on MuJoCo."""

import os

# Off-screen rendering by default (EGL works without a GPU through Mesa). It must be chosen before
# mujoco or dm_control is first imported; set MUJOCO_GL=glfw yourself for an on-screen viewer.
os.environ.setdefault("MUJOCO_GL", "egl")

__version__ = "0.7.0"
