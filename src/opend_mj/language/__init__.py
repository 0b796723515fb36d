"""Language: the OpenD paper's Algorithm 1 (instructions from handle positions, :mod:`.algorithm1`),
reading instructions as people say them back into its labels or refusing them (:mod:`.parser`), and
rewordings generated from a grammar (:mod:`.grammar`), and the instruction's one-hot code that the
environments and learned policies read (:mod:`.onehot`).

Every part of the pipeline that reads an instruction (the planner's door / drawer and hinge side,
both learned solvers, the environments' one-hot code, the score tables) reads it through
:func:`canonical_instruction` / :func:`describe_instruction`, so all of them understand the same
phrasings and refuse the same ones (:class:`InstructionNotUnderstood`).
"""

from __future__ import annotations

from opend_mj.language.algorithm1 import (
    Description,
    LanguageConfig,
    LanguageInvalid,
    TargetLayout,
    describe,
    levels,
)
from opend_mj.language.grammar import PARAPHRASES, paraphrase, rewordings
from opend_mj.language.onehot import INSTRUCTION_DIM, instruction_onehot
from opend_mj.language.parser import InstructionNotUnderstood, normalise, parse_instruction

#: The kinds of target an instruction names (`target_kind`): what a run, a training set or an
#: ensemble's route can be restricted to.
TARGET_KINDS = ("drawer", "door")

__all__ = [
    "TARGET_KINDS", "Description", "LanguageConfig", "LanguageInvalid", "TargetLayout", "describe", "levels", "PARAPHRASES",
    "paraphrase", "rewordings", "InstructionNotUnderstood", "normalise", "parse_instruction",
    "describe_instruction", "canonical_instruction", "target_kind", "hinge_side", "all_templates",
    "INSTRUCTION_DIM", "instruction_onehot",
]


def describe_instruction(instruction: str) -> Description:
    """The labels an instruction names (Algorithm 1's form or any phrasing the parser reads);
    raises :class:`InstructionNotUnderstood` (a ValueError) where it names no one canonical target."""
    return parse_instruction(instruction)


def canonical_instruction(instruction: str) -> str:
    """The Algorithm 1 form of an instruction ("could you open the drawer second from the top on the
    left?" -> "second top left drawer"), so that a model trained on Algorithm 1's wording reads any
    wording the parser understands; raises :class:`InstructionNotUnderstood` otherwise (never a
    less specific template)."""
    return parse_instruction(instruction).instruction


def target_kind(instruction: str) -> str:
    """door or drawer (one of `TARGET_KINDS`), as the instruction names it; raises
    :class:`InstructionNotUnderstood`."""
    return parse_instruction(instruction).kind


def hinge_side(instruction: str) -> str | None:
    """'left' / 'right' where the instruction names a door's side plainly (double doors always do),
    else None: no side, or a side counted from an end ("second left") or beside a middle level.
    Raises :class:`InstructionNotUnderstood` for an instruction the parser refuses."""
    d = parse_instruction(instruction)
    if d.horizontal in ("left", "right") and "second" not in d.vertical and d.vertical != "middle":
        return d.horizontal
    return None


def all_templates(config: LanguageConfig = LanguageConfig()) -> list[str]:
    """Every instruction Algorithm 1 can produce (vertical x horizontal x kind), sorted."""
    vertical = sorted({w for labels in config.vertical_labels.values() for w in labels})
    horizontal = sorted({w for labels in config.horizontal_labels.values() for w in labels})
    return sorted({Description(v, h, k).instruction for v in vertical for h in horizontal for k in ("door", "drawer")})
