"""gymnasium spaces of the environments over the dataset (`opend_mj.sim.envs.OpenDCore`).

One definition for the single environment (`sim.gym_env`) and the vector environment
(`sim.vector_env`): float observations are float32 boxes, rgb uint8, a text instruction a Text space.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np

_WIDE = 1.0e4
_CHARSET = "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789 ,.'-"


def _bounds(key: str) -> tuple[float, float]:
    """Bounds of a float observation: unit for quaternions and codes, else wide (never reached)."""
    if key.endswith("_quat"):
        return -1.0, 1.0
    if key in ("instruction", "open_ratio"):
        return 0.0, 1.0
    if key in ("depth", "time", "handle_size"):
        return 0.0, _WIDE
    return -_WIDE, _WIDE


def observation_space(core) -> gym.spaces.Dict:
    spaces = {}
    for key, (shape, kind) in core.observation_layout().items():
        if kind == "text":
            spaces[key] = gym.spaces.Text(max_length=128, charset=_CHARSET)
        elif kind == "uint8":
            spaces[key] = gym.spaces.Box(0, 255, shape, np.uint8)
        else:
            spaces[key] = gym.spaces.Box(*_bounds(key), shape, np.float32)
    return gym.spaces.Dict(spaces)


def action_space(core) -> gym.spaces.Box:
    low, high = core.action_bounds()
    return gym.spaces.Box(low.astype(np.float32), high.astype(np.float32), dtype=np.float32)
