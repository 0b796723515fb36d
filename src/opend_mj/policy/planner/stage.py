"""What every planner stage is given: the :class:`StageContext` (the configuration, the hand, the
episode's state and the stage log), shared by the stages of one :class:`~opend_mj.policy.planner.Planner`.

A stage is an object with one job (approach, grasp choice, pull, kind check, recovery); it reads
its own section of the configuration (``config.approach``, ``config.pulling``, ...), keeps nothing
of an episode in itself, and calls the other stages it needs through the references it was built
with. The episode's state (:class:`~opend_mj.policy.planner.records.EpisodeState`) is one explicit
object, replaced at the start of each episode.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from opend_mj.policy.planner.config import PlannerConfig
from opend_mj.policy.planner.records import EpisodeState, PlanResult
from opend_mj.sim.hands import HandPlannerConfig, HandSpec


@dataclass
class StageContext:
    """``config``: the planner's configuration; ``spec``: the hand's description; ``hand``: the
    planner's numbers for this hand (``planner.json``); ``episode``: the state of the episode being
    run; ``on_stage``: called with (stage name, info) as each stage starts (probes, demonstrations)."""

    config: PlannerConfig
    spec: HandSpec
    hand: HandPlannerConfig
    episode: EpisodeState = field(default_factory=EpisodeState)
    on_stage: Callable[[str, dict], None] | None = None

    def enter(self, result: PlanResult, name: str, **info) -> None:
        """A stage starts: the result's ``stage_reached`` and an event (arrays left out)."""
        result.stage_reached = name
        result.events.append({"stage": name, **{k: v for k, v in info.items() if not isinstance(v, np.ndarray)}})
        if self.on_stage is not None:
            self.on_stage(name, info)

    def time_left(self, robot) -> float:
        """Simulated seconds left of the episode's budget (``config.max_time``)."""
        return self.config.max_time - robot.time


class Stage:
    """A planner stage over a :class:`StageContext`: ``config``, ``spec``, ``hand`` and ``episode``
    read through to it (so that a new episode's state, or a changed configuration, is seen by every
    stage at once)."""

    def __init__(self, ctx: StageContext):
        self.ctx = ctx

    @property
    def config(self) -> PlannerConfig:
        return self.ctx.config

    @property
    def spec(self) -> HandSpec:
        return self.ctx.spec

    @property
    def hand(self) -> HandPlannerConfig:
        return self.ctx.hand

    @property
    def episode(self) -> EpisodeState:
        return self.ctx.episode
