"""The learned solvers read instructions through the language parser: a rewording reaches CLIPort's
text encoder and Faster R-CNN's Algorithm 1 matching as its canonical template (so it picks the same
handle), and a refused instruction raises instead of picking one."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from opend_mj.language import InstructionNotUnderstood
from opend_mj.policy.learned.detector import consistent_choice, match_instruction

CHECKPOINTS = Path(__file__).resolve().parents[2] / "checkpoints"
REWORDED = [("top left door", "could you open the upper-left cupboard?"),
            ("bottom right door", "the door at the bottom on the right-hand side - open it"),
            ("top right door", "in the top row, the door on the far right"),
            ("bottom left door", "open the lower left-hand door please")]


def _box(u, v, w=4, h=20):
    return [u - w / 2, v - h / 2, u + w / 2, v + h / 2]


GRID = [_box(80, 60), _box(180, 60), _box(80, 160), _box(180, 160)]


@pytest.mark.parametrize("template, words", REWORDED)
def test_matching_reads_rewordings_as_their_template(template, words):
    assert match_instruction(GRID, words) == match_instruction(GRID, template)
    p = [0.9, 0.6, 0.45, 0.9]
    assert consistent_choice(GRID, p, words) == consistent_choice(GRID, p, template)


def test_matching_refuses_what_the_parser_refuses():
    with pytest.raises(InstructionNotUnderstood):
        match_instruction(GRID, "the third door from the left")


def test_cliport_text_features_come_from_the_canonical_template(monkeypatch):
    """The shipped CLIPort checkpoint: the text encoder sees the template, whatever the wording."""
    import opend_mj.policy.learned.affordance as affordance

    solver = affordance.CLIPortSolver(checkpoint=CHECKPOINTS / "cliport.pt", proposals=False)
    seen = []

    def fake_predict(model, config, text, rgb, depth, instruction):
        seen.append(instruction)
        text.encode([instruction])  # the cached table holds Algorithm 1's instructions
        prob = np.zeros((256, 256), np.float32)
        prob[60:64, 70:90] = 1.0
        return prob

    monkeypatch.setattr(affordance, "predict", fake_predict)
    rgb, depth = np.zeros((256, 256, 3), np.uint8), np.ones((256, 256), np.float32)
    boxes = [solver.solve(rgb, depth, words, None).as_tuple() for _, words in REWORDED]
    assert seen == [template for template, _ in REWORDED]
    assert boxes == [solver.solve(rgb, depth, template, None).as_tuple() for template, _ in REWORDED]
    with pytest.raises(InstructionNotUnderstood):
        solver.solve(rgb, depth, "open the second door", None)


def test_fasterrcnn_matches_rewordings_as_their_template(monkeypatch):
    """The shipped Faster R-CNN checkpoint with fixed detections (a 2 x 2 grid of door handles):
    each rewording selects the box its template selects."""
    import opend_mj.policy.learned.detector as detector

    solver = detector.FasterRCNNSolver(checkpoint=CHECKPOINTS / "fasterrcnn.pt", proposals=False)
    boxes = np.array(GRID, float)
    found = detector.Detections(boxes, np.full(4, 0.95), np.tile([0.1, 0.9], (4, 1)))
    import opend_mj.policy.learned.detector.solver as detector_solver  # where the solver looks it up

    monkeypatch.setattr(detector_solver, "detect_handles", lambda *a, **k: (found, found))
    rgb, depth = np.zeros((256, 256, 3), np.uint8), np.ones((256, 256), np.float32)
    for template, words in REWORDED:
        got = solver.solve(rgb, depth, words, None).as_tuple()
        assert got == solver.solve(rgb, depth, template, None).as_tuple()
    assert [solver.solve(rgb, depth, w, None).as_tuple()[:2] for _, w in REWORDED] == [
        (78.0, 50.0), (178.0, 150.0), (178.0, 50.0), (78.0, 150.0)]
    with pytest.raises(InstructionNotUnderstood):
        solver.solve(rgb, depth, "open the door next to the top left one", None)


def test_training_instructions_can_be_grammar_rewordings():
    """`opend train --solver cliport --reword P`: with chance P a training target's instruction is a
    grammar rewording that reads back to its template; its embedding stays out of the saved table."""
    import random

    from opend_mj.language import canonical_instruction
    from opend_mj.policy.learned.text import CachedEncoder
    from opend_mj.policy.learned.train_cliport import _encode_for_training, training_instruction

    rng = random.Random(0)
    assert {training_instruction("top left drawer", rng, 0.0) for _ in range(20)} == {"top left drawer"}
    worded = [training_instruction("top left drawer", rng, 1.0) for _ in range(30)]
    assert len(set(worded)) > 10 and {canonical_instruction(t) for t in worded} == {"top left drawer"}
    text = CachedEncoder("bow")
    text.encode(["top left drawer"])
    vectors = _encode_for_training(text, ["top left drawer"] + worded[:3])
    assert vectors.shape == (4, text.dim) and set(text.table) == {"top left drawer"}
