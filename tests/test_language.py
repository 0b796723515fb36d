"""Instructions from handle layouts (OpenD Algorithm 1): hand-made layouts with known answers."""

from __future__ import annotations

import pytest

from opend_mj.language import PARAPHRASES, Description, LanguageConfig, LanguageInvalid, TargetLayout, describe, paraphrase


def stack(n: int, kind: str = "drawer", y: float = 0.0, z0: float = 0.1, dz: float = 0.15) -> list[TargetLayout]:
    """n targets one above the other; key k0 is the lowest."""
    return [TargetLayout(f"{kind[:2]}{i}", kind, y, z0 + i * dz) for i in range(n)]


def words(layouts: list[TargetLayout], config: LanguageConfig = LanguageConfig()) -> dict[str, str]:
    return {k: d.instruction for k, d in describe(layouts, config).items()}


def test_single_drawer():
    assert words([TargetLayout("j", "drawer", 0.1, 0.5)]) == {"j": "drawer"}


def test_single_door():
    assert words([TargetLayout("j", "door", -0.2, 0.9)]) == {"j": "door"}


def test_two_stacked_drawers():
    assert words(stack(2)) == {"dr0": "bottom drawer", "dr1": "top drawer"}


def test_three_stacked_drawers():
    assert words(stack(3)) == {"dr0": "bottom drawer", "dr1": "middle drawer", "dr2": "top drawer"}


def test_four_stacked_drawers():
    assert words(stack(4)) == {"dr0": "bottom drawer", "dr1": "second bottom drawer",
                               "dr2": "second top drawer", "dr3": "top drawer"}


def test_five_stacked_drawers():
    assert words(stack(5)) == {"dr0": "bottom drawer", "dr1": "second bottom drawer", "dr2": "middle drawer",
                               "dr3": "second top drawer", "dr4": "top drawer"}


def test_order_of_input_does_not_matter():
    layout = stack(4)
    assert words(layout[::-1]) == words(layout)
    assert words([layout[2], layout[0], layout[3], layout[1]]) == words(layout)


def test_double_doors_left_is_plus_y():
    doors = [TargetLayout("a", "door", 0.25, 0.6), TargetLayout("b", "door", -0.25, 0.6)]
    assert words(doors) == {"a": "left door", "b": "right door"}


def test_three_side_by_side():
    row = [TargetLayout(k, "drawer", y, 0.5) for k, y in (("r", -0.4), ("m", 0.0), ("l", 0.4))]
    assert words(row) == {"l": "left drawer", "m": "middle drawer", "r": "right drawer"}


def test_two_by_two_grid():
    grid = [TargetLayout(f"{v}{h}", "drawer", y, z)
            for v, z in (("t", 0.8), ("b", 0.3)) for h, y in (("l", 0.3), ("r", -0.3))]
    assert words(grid) == {"tl": "top left drawer", "tr": "top right drawer",
                           "bl": "bottom left drawer", "br": "bottom right drawer"}


def test_description_fields():
    d = describe([TargetLayout("a", "door", 0.3, 0.6), TargetLayout("b", "door", -0.3, 0.6)])["a"]
    assert d == Description(vertical="", horizontal="left", kind="door")


def test_mixed_types_are_labelled_per_type():
    """A drawer over a double door: the drawer alone is 'drawer', the doors are left/right."""
    layout = [TargetLayout("drawer", "drawer", 0.0, 0.85),
              TargetLayout("ldoor", "door", 0.2, 0.4), TargetLayout("rdoor", "door", -0.2, 0.4)]
    assert words(layout) == {"drawer": "drawer", "ldoor": "left door", "rdoor": "right door"}


def test_mixed_column_of_drawers_beside_a_door():
    layout = stack(3, "drawer", y=-0.3) + [TargetLayout("door", "door", 0.3, 0.5)]
    assert words(layout) == {"dr0": "bottom drawer", "dr1": "middle drawer", "dr2": "top drawer",
                             "door": "door"}


def test_close_centres_count_as_one_level():
    """Handles 2 cm apart in height are one level (tolerance 4 cm); 10 cm apart are two."""
    near = [TargetLayout("a", "door", 0.3, 0.60), TargetLayout("b", "door", -0.3, 0.62)]
    assert words(near) == {"a": "left door", "b": "right door"}
    far = [TargetLayout("a", "door", 0.3, 0.60), TargetLayout("b", "door", -0.3, 0.70)]
    assert words(far) == {"a": "bottom door", "b": "top door"}


def test_tolerance_comes_from_config():
    near = [TargetLayout("a", "door", 0.3, 0.60), TargetLayout("b", "door", -0.3, 0.62)]
    tight = LanguageConfig(level_tolerance=0.01)
    assert words(near, tight) == {"a": "bottom door", "b": "top door"}


def test_tolerance_also_applies_side_by_side():
    """Two drawers in one level whose centres are 2 cm apart cannot be told apart."""
    with pytest.raises(LanguageInvalid):
        describe([TargetLayout("a", "drawer", 0.01, 0.5), TargetLayout("b", "drawer", -0.01, 0.5)])


def test_six_stacked_drawers_are_invalid():
    with pytest.raises(LanguageInvalid, match="6 vertical levels"):
        describe(stack(6))


def test_six_drawers_in_a_row_are_invalid():
    row = [TargetLayout(f"d{i}", "drawer", -0.5 + 0.2 * i, 0.5) for i in range(6)]
    with pytest.raises(LanguageInvalid, match="6 drawers side by side"):
        describe(row)


def test_two_handles_at_the_same_place_are_invalid():
    with pytest.raises(LanguageInvalid):
        describe([TargetLayout("a", "drawer", 0.0, 0.5), TargetLayout("b", "drawer", 0.0, 0.5)])


def test_no_targets_is_invalid():
    with pytest.raises(LanguageInvalid):
        describe([])


def test_six_levels_of_drawers_are_fine_when_split_by_type():
    """Limits are per type: 4 drawers and 2 doors are 4 + 1 levels, not 6."""
    layout = stack(4, "drawer") + [TargetLayout("l", "door", 0.3, 1.2), TargetLayout("r", "door", -0.3, 1.2)]
    out = words(layout)
    assert out["l"] == "left door" and out["r"] == "right door"
    assert len(set(out.values())) == 6


@pytest.mark.parametrize(
    "description, expected",
    [
        (Description("top", "left", "drawer"), ["top left drawer", "open the top left drawer",
                                                 "open the drawer at the top on the left",
                                                 "pull open the top left drawer"]),
        (Description("", "", "door"), ["door", "open the door", "open the door", "pull open the door"]),
        (Description("second bottom", "", "drawer"), [
            "second bottom drawer", "open the second bottom drawer", "open the drawer at the second bottom",
            "pull open the second bottom drawer"]),
        (Description("", "right", "door"), ["right door", "open the right door", "open the door on the right",
                                             "pull open the right door"]),
    ],
)
def test_paraphrase(description, expected):
    assert [paraphrase(description, k) for k in range(4)] == expected
    assert paraphrase(description, 4) == expected[0], "templates wrap around"


@pytest.mark.parametrize("template", range(4))
@pytest.mark.parametrize("labels", [("top", "left", "drawer"), ("second bottom", "", "drawer"),
                                    ("", "right", "door"), ("", "", "door"), ("bottom", "second right", "door")])
def test_paraphrases_read_back_to_the_same_target(template, labels):
    """Every paraphrase names the same target: reading it back gives the same labels."""
    from opend_mj.language import Description, describe_instruction, paraphrase

    d = Description(*labels)
    text = paraphrase(d, template)
    assert describe_instruction(text) == d, text


def test_paraphrased_episodes_are_their_own_episodes():
    from opend_mj.evaluation.episode import EpisodeJob, record_fields

    job = EpisodeJob(cabinet="c", cabinet_dir="x", joint="joint_0", split="test", hand="allegro", solver="oracle")
    reworded = EpisodeJob(**{**job.__dict__, "paraphrase": 2})
    assert job.key() != reworded.key()
    assert "paraphrase" not in record_fields(job) and record_fields(reworded)["paraphrase"] == 2


def test_describe_instruction_reads_labels():
    from dataclasses import astuple

    from opend_mj.language import describe_instruction

    def parse_instruction(text):
        return astuple(describe_instruction(text))

    assert parse_instruction("second top left drawer") == ("second top", "left", "drawer")
    assert parse_instruction("bottom door") == ("bottom", "", "door")
    assert parse_instruction("right door") == ("", "right", "door")
    assert parse_instruction("middle drawer") == ("middle", "", "drawer")
    assert parse_instruction("top middle door") == ("top", "middle", "door")
    assert parse_instruction("open the drawer at the top on the second right") == ("top", "second right", "drawer")


@pytest.mark.parametrize("template", range(len(PARAPHRASES)))
def test_canonical_instruction_undoes_every_paraphrase(template):
    from opend_mj.language import canonical_instruction

    for labels in [("top", "left", "drawer"), ("second bottom", "", "door"), ("", "second right", "door"),
                   ("middle", "middle", "drawer"), ("", "", "drawer")]:
        d = Description(*labels)
        assert canonical_instruction(paraphrase(d, template)) == d.instruction


def test_instruction_onehot_codes_the_labels_of_any_phrasing():
    import numpy as np

    from opend_mj.language import INSTRUCTION_DIM, instruction_onehot

    code = instruction_onehot("second top left drawer")
    assert code.dtype == np.float32 and code.shape == (INSTRUCTION_DIM,) == (14,)
    assert np.flatnonzero(code).tolist() == [2, 7, 12]  # "second top", "left", drawer
    assert np.flatnonzero(instruction_onehot("door")).tolist() == [0, 6, 13]  # no word needed: ""
    assert np.array_equal(instruction_onehot("open the drawer second from the top on the left"), code)
