"""A minimal agent for `opend run --policy`: random normalised delta actions, seeded per episode.

    opend run --policy examples/random_agent.py --hand allegro --split test --out results/random.jsonl
    opend score results/random.jsonl results/oracle_test.jsonl

It reads nothing but the step count; a real agent reads ``obs`` (instruction, RGB-D on the first
step, camera, the hand's own state: see `opend_mj.policy.agents`) and returns an action each step.
"""

from __future__ import annotations

import numpy as np


class Agent:
    name = "random"
    control = "delta"  # 6 + n_fingers numbers in [-1, 1] (root translation, root rotation, finger targets)
    images = "first"  # RGB-D only in the first observation (the paper's setting)

    def __init__(self, scale: float = 1.0, seconds: float | None = None):
        self.scale = float(scale)
        self.seconds = seconds  # stop after this much simulated time (None: use the whole time limit)

    def reset(self, episode) -> None:
        self.rng = np.random.default_rng(episode.seed)
        self.dim = len(episode.action_names)
        self.max_steps = None if self.seconds is None else int(round(self.seconds / episode.control_dt))
        self.steps = 0

    def act(self, obs: dict):
        if self.max_steps is not None and self.steps >= self.max_steps:
            return None  # done: the episode is scored on the state as it is
        self.steps += 1
        return self.scale * self.rng.uniform(-1.0, 1.0, self.dim)
