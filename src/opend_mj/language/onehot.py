"""The instruction's one-hot code: 14 numbers for the labels of an Algorithm 1 instruction, what the
environments observe (``instruction="onehot"``) and the learned policies read."""

from __future__ import annotations

import numpy as np

from opend_mj.language.parser import parse_instruction

#: Labels of each part of the code (Algorithm 1's words; "" = the word is not needed).
ONEHOT_VERTICAL = ("", "top", "second top", "middle", "second bottom", "bottom")
ONEHOT_HORIZONTAL = ("", "left", "second left", "middle", "second right", "right")
ONEHOT_KIND = ("drawer", "door")
#: Length of the code: vertical (6), horizontal (6), door/drawer (2).
INSTRUCTION_DIM = len(ONEHOT_VERTICAL) + len(ONEHOT_HORIZONTAL) + len(ONEHOT_KIND)


def instruction_onehot(text: str) -> np.ndarray:
    """A 14-number code of an instruction (any phrasing the parser reads): vertical (6), horizontal
    (6), door/drawer (2), float32. A label outside Algorithm 1's words counts as "" (not needed)."""
    d = parse_instruction(text)
    code = np.zeros(INSTRUCTION_DIM, dtype=np.float32)
    code[ONEHOT_VERTICAL.index(d.vertical) if d.vertical in ONEHOT_VERTICAL else 0] = 1.0
    code[len(ONEHOT_VERTICAL) + (ONEHOT_HORIZONTAL.index(d.horizontal) if d.horizontal in ONEHOT_HORIZONTAL
                                 else 0)] = 1.0
    code[len(ONEHOT_VERTICAL) + len(ONEHOT_HORIZONTAL) + ONEHOT_KIND.index(d.kind)] = 1.0
    return code
