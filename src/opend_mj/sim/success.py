"""The success checker: the instructed target's open ratio against the threshold (the paper's: open
ratio > 20 %), its joint as a share of its range (ManiSkill3's criterion reads it), and which other
targets moved. Pure numpy over the cabinet's joint values."""

from __future__ import annotations

from dataclasses import dataclass, field

from opend_mj.sim.cabinet import Cabinet, Target


@dataclass
class Outcome:
    """What the success checker reports about the current state."""

    success: bool
    open_ratio: float
    range_ratio: float
    joint_value: float
    others_moved: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        return {"success": self.success, "open_ratio": self.open_ratio, "range_ratio": self.range_ratio,
                "joint_value": self.joint_value, "others_moved": self.others_moved}


class SuccessChecker:
    """The instructed target's open ratio against a threshold; which other targets moved."""

    def __init__(self, cabinet: Cabinet, target: Target, threshold: float, moved_threshold: float):
        self.cabinet = cabinet
        self.target = target
        self.threshold = threshold
        self.moved_threshold = moved_threshold

    def check_values(self, values: dict[str, float]) -> Outcome:
        q = values[self.target.joint]
        ratio = self.target.open_ratio(q)
        others = [t.joint for t in self.cabinet.targets
                  if t.joint != self.target.joint and t.range_ratio(values[t.joint]) > self.moved_threshold]
        return Outcome(success=ratio > self.threshold, open_ratio=ratio, range_ratio=self.target.range_ratio(q),
                       joint_value=q, others_moved=others)

    def check(self, physics) -> Outcome:
        return self.check_values(self.cabinet.joint_values(physics))
