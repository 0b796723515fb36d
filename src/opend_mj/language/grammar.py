"""Rewordings of Algorithm 1's instructions, generated from a small grammar.

An instruction is a frame (a command, a polite request, a question, a description) around a noun
phrase; the noun phrase places the target's labels before the noun ("second highest left drawer"),
after it ("drawer second from the top, on the left"), or both, in any order, with synonyms for each
label and for the noun ("cupboard", "cabinet door", "drawer front"). :func:`rewordings` draws from
the grammar deterministically for a seed (or lists all of it): for tests of the parser (every
rewording must read back to its template), for a user's instruction file (`opend reword`), and for
training text encoders on more than one wording. :data:`PARAPHRASES` are the three fixed rewordings
of ``opend run --paraphrase 1-3``.
"""

from __future__ import annotations

import itertools
import random
import re

from opend_mj.language.algorithm1 import Description

#: Paraphrase templates of ``--paraphrase k``: the same target named in other words.
PARAPHRASES = (
    "{instruction}",
    "open the {instruction}",
    "open the {kind}{at}",
    "pull open the {instruction}",
)


def paraphrase(description: Description, template: int) -> str:
    """Reword an instruction, e.g. 'top left drawer' -> 'open the drawer at the top on the left'."""
    where = []
    if description.vertical:
        where.append(f"at the {description.vertical}")
    if description.horizontal:
        where.append(f"on the {description.horizontal}")
    at = (" " + " ".join(where)) if where else ""
    return PARAPHRASES[template % len(PARAPHRASES)].format(
        instruction=description.instruction, kind=description.kind, at=at)


#: Each label as a word before the noun.
VERTICAL_BEFORE = {
    "top": ("top", "topmost", "uppermost", "highest", "top-most"),
    "second top": ("second top", "second highest", "second-from-top", "next-to-top", "2nd highest"),
    "middle": ("middle", "centre", "center", "central"),
    "second bottom": ("second bottom", "second lowest", "second-from-bottom", "next-to-bottom", "2nd lowest"),
    "bottom": ("bottom", "lowest", "bottommost", "lowermost", "bottom-most"),
}
HORIZONTAL_BEFORE = {
    "left": ("left", "leftmost", "left-hand", "far-left", "far left"),
    "second left": ("second left", "second-from-left", "2nd left", "second leftmost"),
    "middle": ("middle", "centre", "center", "central"),
    "second right": ("second right", "second-from-right", "2nd right", "second rightmost"),
    "right": ("right", "rightmost", "right-hand", "far-right", "far right"),
}
#: Each label as a phrase after the noun ("the drawer ... ").
VERTICAL_AFTER = {
    "top": ("at the top", "in the top row", "on the top level", "first from the top", "right at the top",
            "at the very top", "up top"),
    "second top": ("second from the top", "one below the top", "just under the top one", "in the second row",
                   "in the second row from the top", "second one down", "one down from the top",
                   "2nd from top", "the top but one"),
    "middle": ("in the middle row", "in the centre row", "on the middle level", "in the center row",
               "on the middle shelf"),
    "second bottom": ("second from the bottom", "one above the bottom", "just above the bottom one",
                      "in the second row from the bottom", "second one up", "one up from the bottom",
                      "2nd from bottom", "the bottom but one", "in the second-to-last row"),
    "bottom": ("at the bottom", "in the bottom row", "on the lowest level", "first from the bottom",
               "right at the bottom", "down at the bottom", "in the last row"),
}
HORIZONTAL_AFTER = {
    "left": ("on the left", "on the left-hand side", "at the far left", "in the left column",
             "first from the left", "on your left", "on the far left", "in the first column"),
    "second left": ("second from the left", "one in from the left", "just right of the leftmost one",
                    "in the second column from the left", "2nd from left", "in the second column"),
    "middle": ("in the middle column", "in the centre column", "in the center column"),
    "second right": ("second from the right", "one in from the right", "just left of the rightmost one",
                     "in the second column from the right", "2nd from right", "in the second-to-last column"),
    "right": ("on the right", "on the right-hand side", "at the far right", "in the right column",
              "first from the right", "on your right", "in the last column"),
}
NOUNS = {"door": ("door", "cabinet door", "cupboard door", "cupboard", "wardrobe door"),
         "drawer": ("drawer", "drawer front", "cabinet drawer", "drawer of the cabinet")}
PLURALS = {"door": ("doors", "cupboard doors"), "drawer": ("drawers", "drawer fronts")}
#: Frames around a noun phrase {np} (commands, requests, questions, descriptions).
FRAMES = (
    "{np}", "the {np}", "open the {np}", "open the {np}.", "Open the {np}!", "please open the {np}",
    "could you open the {np}?", "can you pull open the {np}, please?", "would you mind opening the {np}?",
    "I'd like the {np} opened", "I want you to open the {np}", "go ahead and open the {np}",
    "pull the {np} open", "the {np}: open it", "the {np} - open it please", "kindly open the {np}",
    "open up the {np}, thanks", "hey robot, open the {np}", "let's open the {np}", "grab the {np} and pull it open",
    "could you please slide out the {np}", "swing open the {np}", "get the {np} open for me",
)
#: Noun phrases: {vb}/{hb} labels before the noun, {va}/{ha} after it, {n} the noun, {ns} its plural.
SHAPES = (
    "{vb} {hb} {n}", "{n} {va} {ha}", "{n} {ha} {va}", "{vb} {n} {ha}", "{hb} {n} {va}", "{n} {va}, {ha}",
    "{n} that is {va} and {ha}", "{n} which sits {ha}, {va}", "one of the {ns} {va} {ha}",
    "{vb} {hb} one of the {ns}", "{n} located {va} {ha}",
)


def _options(d: Description) -> list[dict]:
    """Every way to say the labels of ``d`` (middle labels only where their axis is clear)."""
    vb = VERTICAL_BEFORE.get(d.vertical, ("",))
    hb = HORIZONTAL_BEFORE.get(d.horizontal, ("",))
    va = VERTICAL_AFTER.get(d.vertical, ("",))
    ha = HORIZONTAL_AFTER.get(d.horizontal, ("",))
    return [dict(vb=a, hb=b, va=c, ha=e) for a, b, c, e in itertools.product(vb, hb, va, ha)]


def _clear(shape: str, d: Description) -> bool:
    """Whether ``shape`` says ``d`` without ambiguity: a bare "middle" needs the other label said
    (or no other label), and a horizontal middle said alone before the noun reads as vertical."""
    if d.vertical == "middle" and d.horizontal == "middle":
        return "{vb} {hb}" in shape or ("{va}" in shape and "{ha}" in shape)
    if d.horizontal == "middle" and not d.vertical:
        return "{ha}" in shape or "{hb}" in shape
    return True


def _tidy(text: str) -> str:
    text = " ".join(text.replace(" ,", ",").split())
    return text.replace(", and", " and").replace(" ,", ",").strip(" ,")


def rewordings(description: Description, n: int | None = 50, seed: int = 0) -> list[str]:
    """``n`` distinct rewordings of ``description`` drawn from the grammar with ``seed`` (all of
    them, sorted, for ``n`` None). Labels that are empty are left out of every shape."""
    d = description
    shapes = [s for s in SHAPES if _clear(s, d)]
    for label, names in ((d.vertical, ("vb", "va")), (d.horizontal, ("hb", "ha"))):
        if not label:  # leave the label out, with the words that join it to the other one
            for name in names:
                shapes = [re.sub(r"(?:(?: and|,)? \{" + name + r"\}(?: and)?,?|\{" + name + r"\}(?: and|,)? ?)", " ", s)
                          for s in shapes]
    shapes = [_tidy(s) for s in shapes]
    dangling = ("that is", "which sits", "located", "of the {ns}")  # a shape left with no label to say
    shapes = list(dict.fromkeys(s for s in shapes if not s.endswith(dangling)))
    if n is None:
        out = {_tidy(f.format(np=_tidy(s.format(n=noun, ns=plural, **o))))
               for f in FRAMES for s in shapes for noun, plural in zip(NOUNS[d.kind], itertools.cycle(PLURALS[d.kind]))
               for o in _options(d)}
        return sorted(out)
    rng = random.Random(f"{seed}/{d.instruction}")
    options = _options(d)
    out: dict[str, None] = {}
    for _ in range(20 * n):
        if len(out) >= n:
            break
        shape = rng.choice(shapes)
        text = rng.choice(FRAMES).format(np=_tidy(shape.format(n=rng.choice(NOUNS[d.kind]),
                                                               ns=rng.choice(PLURALS[d.kind]),
                                                               **rng.choice(options))))
        out[_tidy(text)] = None
    return list(out)
