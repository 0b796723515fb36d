"""A scripted reach-grasp-pull episode in the environments' delta action space.

It reads the privileged observations (``handle_pos``, ``grasp_site_pos``), so it is no agent of the
benchmark: it is the fixed episode with which the environment step is checked against its
reference (the tests of the lean and compiled steps, ``tools/compare_steps.py``). Steps 0-139 move
the grasp site toward the handle's box centre with the fingers open (full speed beyond 12.5 mm),
140-159 close the fingers while creeping on, then pull back along -x with the fingers closed; the
wrist turns a little all the time, so that every step plans a rotation.
"""

from __future__ import annotations

import numpy as np

#: the distance (m) from the handle beyond which the hand moves at full speed
FULL_SPEED_DISTANCE = 0.0125


def reach_grasp_pull(obs: dict, t: int, shape, rng: np.random.Generator | None = None) -> np.ndarray:
    """The delta action for control step ``t``; with ``rng``, every tenth step is instead a random
    action beyond [-1, 1] (uniform in [-1.5, 1.5]: the environment clips it)."""
    if rng is not None and t % 10 == 9:
        return rng.uniform(-1.5, 1.5, shape)
    a = np.zeros(shape, np.float32)
    d = obs["handle_pos"] - obs["grasp_site_pos"]
    if t < 140:
        a[:3], a[6:] = np.clip(d / FULL_SPEED_DISTANCE, -1, 1), -1
    elif t < 160:
        a[:3], a[6:] = np.clip(d / FULL_SPEED_DISTANCE, -1, 1) * 0.3, 1
    else:
        a[0], a[6:] = -0.4, 1
    a[3:6] = np.sin(t * 0.1 + np.arange(3)) * 0.3
    return a
