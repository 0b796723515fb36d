"""Reading an instruction as people say it back into Algorithm 1's labels, or refusing it.

A target is named by a vertical label (top / second top / middle / second bottom / bottom), a
horizontal label (left / second left / middle / second right / right) and a kind (door / drawer);
Algorithm 1 drops labels that are not needed. :func:`parse_instruction` reads the everyday ways of
saying the same: ordinals in words and figures counted from either side ("second from the left",
"2nd drawer from the top", "one below the top", "the bottom but one", "next-to-top"), rows and
columns ("middle row", "centre column", "first row" counts from the top, "first column" from the
left), synonyms ("uppermost", "lowest", "leftmost", "right-hand", "upper", "lower"), British and
American spelling, politeness, questions, commands and descriptions in any word order, plurals
("the left one of the two doors") and common nouns ("cabinet door", "cupboard", "drawer front").

What it cannot map onto one canonical template it refuses with :class:`InstructionNotUnderstood`,
naming what is missing (no kind) or ambiguous: an ordinal with no end to count from ("the second
drawer"), a position Algorithm 1 has no label for ("third from the top": in a column of five that
is the middle, in a column of four the second bottom), contradictions ("top bottom drawer"),
negation, several parts, closing, appearance ("the white drawer"), positions relative to another
part ("the drawer above the left door"), and any word outside its vocabulary (an unknown word may
carry position: "the drawer nearest the floor" must not be read as "drawer"). It never returns a
less specific template than the one said.

The text is normalised (lower case, contractions, figures, hyphens, synonyms), then phrase rules
turn what names a position or a kind into upper-case codes (the normalised text is lower case, so
codes never match a rule), and what is left must be known filler words.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import lru_cache

from opend_mj.language.algorithm1 import Description

VERTICAL = ("top", "second top", "middle", "second bottom", "bottom")
HORIZONTAL = ("left", "second left", "middle", "second right", "right")


class InstructionNotUnderstood(ValueError):
    """An instruction the parser cannot read as exactly one canonical target.

    ``missing``: what it does not say ("kind": door or drawer); ``ambiguous``: what it says that
    does not name one canonical target (each a short reason); ``unknown``: words outside the
    parser's vocabulary."""

    def __init__(self, text: str, missing: tuple[str, ...] = (), ambiguous: tuple[str, ...] = (),
                 unknown: tuple[str, ...] = ()):
        self.text, self.missing, self.ambiguous, self.unknown = text, tuple(missing), tuple(ambiguous), tuple(unknown)
        parts = []
        if "kind" in self.missing:
            parts.append("which kind of part: a door or a drawer?")
        parts.extend(self.ambiguous)
        if self.unknown:
            parts.append("words not understood: " + ", ".join(repr(w) for w in self.unknown))
        super().__init__(f"instruction not understood: {text!r}: " + "; ".join(parts))

    @property
    def reason(self) -> str:
        """The message without the instruction (for records and tables)."""
        return str(self).split(": ", 2)[-1]


# ------------------------------------------------------------------ normalisation
_CONTRACTIONS = ((r"can't|cannot", "can not"), (r"won't", "will not"), (r"n't\b", " not"), (r"'d\b", " would"),
                 (r"'ll\b", " will"), (r"'re\b", " are"), (r"'m\b", " am"), (r"'ve\b", " have"),
                 (r"\blet's\b", "let us"), (r"'s\b", " s"), (r"s'(?=\s|$)", "s"))
_FIGURES = ((r"\b1st\b", " first "), (r"\b2nd\b", " second "), (r"\b3rd\b", " third "),
            (r"\b\d+(?:st|nd|rd|th)\b", " nth "), (r"\d+", " number "))
#: Several words that mean one (applied to the space-joined, lower-case words, in order).
_PHRASES = (
    (r"\b(left|right) hand(ed)?\b", r"\1"), (r"\b(lefthand|righthand)\b", lambda m: m.group(1)[:-4]),
    (r"\b(top|bottom|left|right|upper|lower) ?most\b", r"\1"), (r"\ball the way\b", ""),
    (r"^(?:all right|alright)\b", ""), (r"\balright\b", ""), (r"\bat once\b", ""),
    (r"(?<!\bthe )(?<!\byour )(?<!\bmy )(?<!\bfar )(?<!\bto )(?<!\bfrom )\bright (now|away)\b", ""),
    (r"\bdrawer (front|face)s?\b", "drawer"), (r"\b(cupboard|cabinet|wardrobe) doors\b", "doors"),
    (r"\b(cupboard|cabinet|wardrobe) door\b", "door"), (r"\bnext to (the )?last\b", "penultimate"),
    (r"\bsecond (to )?last\b", "penultimate"), (r"\blast but one\b", "penultimate"),
    (r"\b(?:nearest|closest|next) (?:to )?the (?:floor|ground)\b", "bottom"),
    (r"\b(?:nearest|closest) (?:to )?the ceiling\b", "top"), (r"\bchest of drawers\b", "cabinet"),
    (r"\bat the middle on the middle\b", "middle middle"),
)
_SYNONYMS = {
    "centre": "middle", "center": "middle", "central": "middle", "centremost": "middle", "centermost": "middle",
    "centred": "middle", "centered": "middle", "mid": "middle", "middlemost": "middle",
    "highest": "top", "uppermost": "top", "topmost": "top", "upper": "top", "higher": "top", "upmost": "top",
    "lowest": "bottom", "lowermost": "bottom", "bottommost": "bottom", "lower": "bottom", "undermost": "bottom",
    "leftmost": "left", "rightmost": "right", "farthest": "far", "furthest": "far", "extreme": "far",
    "draw": "drawer", "draws": "drawers",
    "colour": "color", "colours": "color", "grey": "gray",
}
#: Containers: a cupboard, a wardrobe, a cabinet. "cupboard" names a door only when no drawer is named
#: ("the top drawer of the cupboard").
_CUPBOARD = "cupboard"


def normalise(text: str) -> str:
    """Lower case, contractions spelled out, figures as words, punctuation and hyphens as spaces,
    several-word phrases and synonyms in one form."""
    t = text.lower().replace("\u2019", "'").replace("\u2018", "'")
    # "next-to-top" (hyphenated: one word) is the second from the top; "next to the top one" is read later
    t = re.sub(r"\bnext-to-(top|bottom|left|right)\b", r"second \1", t)
    t = re.sub(r"\bnext-to-last\b", "penultimate", t)
    # a sentence-initial "Right," / "OK," (a discourse marker, set off by punctuation) names no side
    t = re.sub(r"^\s*(?:right|ok|okay|alright|all right|so|now|well)(?: then)?\s*[,.!:;]+", " ", t)
    # "centre-left": between the middle and the left, or the middle row's left? (refused below)
    t = re.sub(r"\b(?:centre|center|middle|mid)-(?:left|right)\b", " centreside ", t)
    for pattern, repl in _CONTRACTIONS + _FIGURES:
        t = re.sub(pattern, repl, t)
    t = " ".join(re.sub(r"[^a-z]+", " ", t).split())
    for pattern, repl in _PHRASES:
        t = " ".join(re.sub(pattern, repl, t).split())
    return " ".join(_SYNONYMS.get(w, w) for w in t.split())


# ------------------------------------------------------------------ phrase rules
_CODE = {("v", lab): "V" + lab.upper().replace(" ", "") for lab in VERTICAL}
_CODE.update({("h", lab): "H" + lab.upper().replace(" ", "") for lab in HORIZONTAL})
_AXIS = {"top": "v", "bottom": "v", "left": "h", "right": "h"}
_ORDINALS = ("first", "second", "third", "fourth", "fifth", "sixth", "seventh", "nth", "penultimate", "last")
_REF_NOUN = r"(?: (?:one|drawer|door|cupboard|row|level|tier|shelf|column|side|end|edge|position))?"
#: Not followed by another position word (a reference such as "below the top left drawer" is a cell of
#: a grid, refused), except an ordinal counted from a side ("one above the bottom, second from the right").
_NOT_POS = r"(?! (?:top|bottom|left|right|middle|second|first|third)\b(?! from\b))"
_SIDE = r"(top|bottom|left|right)"


def _side_code(side: str, ordinal: str) -> str:
    """The code of the ``ordinal``-th part from ``side``; refused where Algorithm 1 has no label."""
    if ordinal == "first":
        return _CODE[(_AXIS[side], side)]
    if ordinal == "second":
        return _CODE[(_AXIS[side], f"second {side}")]
    return _refusal(f"'{ordinal} from the {side}' has no label of its own (positions are named top, second "
                    "top, middle, second bottom, bottom and left, second left, middle, second right, right)")


#: Reasons for refusal that phrase rules give; the code XREF<i> in the text stands for reason i.
_REASONS: dict[str, int] = {}


def _refusal(reason: str) -> str:
    index = _REASONS.setdefault(reason, len(_REASONS))
    return f" XREF{index} "


def _ordinal_from(m: re.Match) -> str:
    ordinal, between, side = m.group("ord"), m.group("between") or "", m.group("side")
    return f" {_side_code(side, ordinal)} {between} "


def _ordinal_row(m: re.Match) -> str:
    ordinal, noun = m.group(1), m.group(2)
    side = ("left", "right") if noun in ("column", "columns", "stack") else ("top", "bottom")
    if ordinal == "last":
        return f" {_side_code(side[1], 'first')} {noun} "
    if ordinal == "penultimate":
        return f" {_side_code(side[1], 'second')} {noun} "
    return f" {_side_code(side[0], ordinal)} {noun} "


#: Words after which "right" is the side, and after which it is an intensifier.
_SIDE_BEFORE = frozenset("the your my far to on from of top bottom middle hand very extreme".split())
_INTENSIFIER_BEFORE = frozenset("drawer drawers door doors cupboard cupboards cabinet unit fronts front one ones is s "
                                "sits sitting located placed positioned situated that it which just found lies "
                                "lying".split())


def _right_before_position(m: re.Match) -> str:
    before = m.group("before")
    if before in _SIDE_BEFORE:
        return m.group(0)
    return f"{before} " if before in _INTENSIFIER_BEFORE else f"{before} RIGHTQ "


_ORD = "(?P<ord>" + "|".join(_ORDINALS[:-2]) + ")"
_BETWEEN = r"(?P<between>(?: (?!(?:top|bottom|left|right|middle|first|second|third|from|of)\b)[a-z]+){0,4}?)"
_RULES: tuple = (
    # ---- "right" before "at the top", "below", ...: a side after "the", "your", "from"...; an intensifier
    # after the part ("the drawer right at the top"); else unsure (RIGHTQ: dropped if another side is named)
    (r"\b(?P<before>[a-z]+) right (?=(?:at|in|on) (?:the )?(?:very )?(?:top|bottom)\b|(?:next|by|beside|below|under|"
     r"beneath|underneath|above|over|there)\b)", _right_before_position),
    # ---- refused outright
    (r"\bon top of\b", lambda m: _refusal("a position relative to another part ('on top of') is not understood")),
    (r"\b(its|cabinet s|door s|drawer s|unit s|their)( own)? (left|right)\b",
     lambda m: _refusal("left and right are the viewer's; the part's own side is ambiguous")),
    (r"\b(hinge|hinges|hinged)\b", lambda m: _refusal("a door's hinge side is not its position")),
    (r"\bcentreside\b", lambda m: _refusal("'centre-left' / 'centre-right': the middle, or beside it?")),
    (r"\b(?:a|an|any|some) (?:door|drawer|cupboard)\b",
     lambda m: _refusal("'a door' / 'a drawer' names any one of several")),
    (r"\bof (the |these |those )?(two|three|four|five|six)\b", " of the "),  # "the left one of the two doors"
    # ---- one from an end
    (r"\b" + _SIDE + r"((?: drawer| door| cupboard| one)?) but one\b",
     lambda m: f" {_side_code(m.group(1), 'second')} {m.group(2)} "),
    (r"\bnext to (?:the )?(?:very )?" + _SIDE + "(" + _REF_NOUN + r")\b" + _NOT_POS,
     lambda m: f" NEXTTO {_side_code(m.group(1), 'second')} {m.group(2)} "),
    (r"\b(?:(?:one|just|directly|immediately|right|the one) )?(?:below|under|beneath|underneath) (?:the )?(?:very )?"
     r"top(" + _REF_NOUN + r")\b" + _NOT_POS, lambda m: f" VSECONDTOP {m.group(1)} "),
    (r"\b(?:(?:one|just|directly|immediately|right|the one) )?(?:above|over) (?:the )?(?:very )?"
     r"bottom(" + _REF_NOUN + r")\b" + _NOT_POS, lambda m: f" VSECONDBOTTOM {m.group(1)} "),
    (r"\b(?:(?:one|just|directly|immediately) )?(?:to the )?right of (?:the )?(?:very |far )?left(" + _REF_NOUN
     + r")\b" + _NOT_POS, lambda m: f" HSECONDLEFT {m.group(1)} "),
    (r"\b(?:(?:one|just|directly|immediately) )?(?:to the )?left of (?:the )?(?:very |far )?right(" + _REF_NOUN
     + r")\b" + _NOT_POS, lambda m: f" HSECONDRIGHT {m.group(1)} "),
    (r"\bone (?:down|lower|below) from (?:the )?(?:very )?top\b", " VSECONDTOP "),
    (r"\bone (?:up|higher|above) from (?:the )?(?:very )?bottom\b", " VSECONDBOTTOM "),
    (r"\bone (?:in |over |across )?from (?:the )?(?:very |far )?(left|right)\b",
     lambda m: f" {_side_code(m.group(1), 'second')} "),
    # ---- ordinals counted from a side, the side before or after
    (r"\b" + _ORD + _BETWEEN + r" (?:counting |counted |starting |going |down |up |in |over )?from (?:the )?"
     r"(?:very |far )?(?P<side>top|bottom|left|right)(?: side| end| edge)?\b", _ordinal_from),
    (r"\b(?:counting |counted |starting |going |reading |looking )?from (?:the )?(?:very |far )?"
     r"(?P<side>top|bottom|left|right)(?: side| end| edge)?" + _BETWEEN + " " + _ORD + r"\b", _ordinal_from),
    (r"\bsecond((?: one| drawer| door| cupboard| shelf| row)?) down\b", r" VSECONDTOP \1 "),
    (r"\bsecond((?: one| drawer| door| cupboard| shelf| row)?) up\b", r" VSECONDBOTTOM \1 "),
    (r"\b(" + "|".join(_ORDINALS[:-2]) + r") " + _SIDE + r"\b", lambda m: f" {_side_code(m.group(2), m.group(1))} "),
    # ---- rows and columns
    (r"\b(" + "|".join(_ORDINALS) + r") (row|rows|level|tier|shelf|layer|column|columns|stack)\b", _ordinal_row),
    (r"\bmiddle (row|rows|level|tier|shelf|layer|line)\b", r" VMIDDLE \1 "),
    (r"\bmiddle (column|columns|stack)\b", r" HMIDDLE \1 "),
    (r"\bmiddle middle\b", " VMIDDLE HMIDDLE "),
    # ---- single words
    (r"\btop\b", " VTOP "), (r"\bbottom\b", " VBOTTOM "), (r"\bleft\b", " HLEFT "), (r"\bright\b", " HRIGHT "),
    (r"\bmiddle\b", " MID "),
)
_COMPILED = tuple((re.compile(p), r) for p, r in _RULES)

#: Words that carry no position and no kind (articles, politeness, verbs of opening, containers...).
FILLER = frozenset("""
a an the this that these those it its is s are be been being am was were will would could can shall should
might may must do does did done please pls plz kindly you your yours yourself me my mine i we us our let
go ahead and then now just quickly gently carefully slowly softly thanks thank cheers hey hi hello robot ok
okay so well mind like want need needs wanted try to for of on in at from by up down out one ones
located sitting sits sit placed positioned situated found find which who what where whose hand line stack cabinet
cabinets cupboard unit chest dresser sideboard wardrobe furniture piece front fronts face handle handles knob
knobs pull pulls pulling open opens opened opening slide sliding swing get grab tug yank access reach see
look position spot place part thing really quite as far very way with bit little time also too same again
into how about help able if possible kind enough favour favor task job take give make have love appreciate
drag lies lying sat inside u ur hmm um uh er erm yo
""".split())
#: Words that change which part is meant in ways the parser does not follow, with the reason given.
REFUSED_WORDS = {
    **{w: "closing or pushing is not opening" for w in ("close", "closed", "closing", "shut", "shutting", "push",
                                                         "pushing", "lock", "locked", "unlock")},
    **{w: "negation is not understood" for w in ("not", "never", "no", "except", "besides", "other", "than",
                                                 "instead", "rather", "but", "without", "nor", "neither")},
    **{w: "more than one part, or any of several, is named" for w in ("all", "both", "every", "each", "either",
                                                                     "any", "some", "whichever", "pair")},
    **{w: "a position relative to another part is not understood" for w in (
        "above", "below", "under", "beneath", "underneath", "over", "beside", "besides", "adjacent", "between",
        "near", "nearest", "nearer", "closest", "closer", "neighbouring", "neighboring", "neighbour", "neighbor",
        "behind", "opposite", "after", "before", "across", "previous", "following", "next")},
    **{w: "a part named by its look is not understood" for w in (
        "color", "white", "black", "red", "blue", "green", "yellow", "brown", "gray", "silver", "golden", "gold",
        "wooden", "wood", "glass", "metal", "big", "bigger", "biggest", "small", "smaller", "smallest", "large",
        "larger", "largest", "tiny", "tall", "taller", "tallest", "short", "shorter", "shortest", "wide", "wider",
        "widest", "narrow", "narrower", "narrowest", "deep", "deeper", "deepest", "shallow", "long", "longer",
        "round", "square", "thin", "thick", "ajar", "broken", "empty", "full")},
    **{w: "numbered parts are not understood (count from a side instead)" for w in (
        "number", "two", "three", "four", "five", "six", "seven", "eight", "nine", "ten", "zero", "numbered")},
}
_CODES = frozenset(_CODE.values())
#: Words that point at a place only with a label of their axis: "the corner drawer", "the drawer at the
#: end", "the drawer on this shelf" say no position; "the top left corner", "the left end", "the top shelf" do.
_NEEDS_AXES = {**{w: ("v", "h") for w in ("corner", "corners")},
               **{w: ("v",) for w in ("row", "rows", "level", "levels", "tier", "tiers", "shelf", "shelves", "layer")},
               **{w: ("h",) for w in ("column", "columns", "side", "sides", "end", "ends", "edge", "edges")}}
_NEEDS_HINT = {("v", "h"): "'top left', 'bottom right', ...", ("v",): "'top', 'middle', 'second from the bottom', ...",
               ("h",): "'left', 'middle', 'second from the right', ..."}


@dataclass(frozen=True)
class _Reading:
    vertical: tuple[str, ...]
    horizontal: tuple[str, ...]
    middles: int
    kinds: tuple[str, ...]
    plural_only: bool
    next_to: bool
    reasons: tuple[str, ...]
    unknown: tuple[str, ...]


#: A question about a part ("is the bottom drawer open?", "which drawer is at the top?") is not a
#: request to open it: yes/no questions about "the ..." / "there", and which/what/where questions
#: without a verb of opening.
_QUESTION = re.compile(r"^\s*(?:(?:is|are|was|were) (?:the|that|this|these|those|there)\b|(?:which|what|where)\b)")
_OPENING = re.compile(r"\b(?:open|pull|slide|swing|get|grab|yank|tug|access)\b")


def _question(text: str) -> bool:
    t = text.lower()
    if "?" not in t or not _QUESTION.match(t):
        return False
    return t.split()[0] in ("is", "are", "was", "were") or not _OPENING.search(t)


def _read(text: str) -> _Reading:
    t = f" {normalise(text)} "
    for pattern, repl in _COMPILED:
        t = pattern.sub(repl, t)
        t = f" {' '.join(t.split())} "
    tokens = t.split()
    vertical, horizontal, kinds, reasons, unknown = [], [], [], [], []
    middles, plural, singular, next_to, unsure_right, needs = 0, False, False, False, False, set()
    drawer_named = any(w in ("drawer", "drawers") for w in tokens)
    for i, w in enumerate(tokens):
        before = tokens[max(0, i - 2):i]
        if w.startswith("XREF"):
            reasons.append(next(k for k, i in _REASONS.items() if i == int(w[4:])))
        elif w in _CODES:
            (vertical if w[0] == "V" else horizontal).append(w)
        elif w == "MID":
            middles += 1
        elif w == "NEXTTO":
            next_to = True
        elif w == "RIGHTQ":
            unsure_right = True
        elif w in _NEEDS_AXES:
            needs.add(w)
        elif w in ("door", "drawer") or (w == _CUPBOARD and not drawer_named):
            kinds.append("drawer" if w == "drawer" else "door")
            singular = True
        elif w in ("doors", "drawers") or (w == _CUPBOARD + "s" and not drawer_named):
            kinds.append("drawer" if w == "drawers" else "door")
            plural = plural or not ({"of", "among", "amongst"} & set(before))
        elif w == "one":
            singular = True
        elif w in REFUSED_WORDS:
            reasons.append(f"{REFUSED_WORDS[w]} ({w!r})")
        elif w in _ORDINALS:
            reasons.append(f"{w!r}: counted from which side? (say 'from the top', 'from the left', ...)")
        elif w not in FILLER and w not in (_CUPBOARD, _CUPBOARD + "s"):
            unknown.append(w)
    for word in sorted(needs):
        axes = _NEEDS_AXES[word]
        said = {"v": bool(vertical), "h": bool(horizontal)}
        if middles:  # a bare middle stands for the missing axis
            said = {"v": True, "h": True} if (vertical or horizontal) else {"v": True, "h": middles > 1}
        if not all(said[a] for a in axes):
            reasons.append(f"which {word}? (name it: {_NEEDS_HINT[axes]})")
    if unsure_right and not horizontal:
        reasons.append("'right': the side, or 'just' (as in 'right at the top')?")
    return _Reading(tuple(vertical), tuple(horizontal), middles, tuple(kinds), plural and not singular, next_to,
                    tuple(dict.fromkeys(reasons)), tuple(dict.fromkeys(unknown)))


_LABEL = {code: label for (_, label), code in _CODE.items()}


def _label(codes: tuple[str, ...], labels: tuple[str, ...], axis: str) -> str:
    return _LABEL[codes[0]]


@lru_cache(maxsize=4096)
def parse_instruction(text: str) -> Description:
    """The labels an instruction names (Algorithm 1's vocabulary); raises
    :class:`InstructionNotUnderstood` where it cannot name exactly one canonical target."""
    if _question(str(text)):
        raise InstructionNotUnderstood(text, (), ("a question about a part, not a request to open it",))
    r = _read(str(text))
    missing: list[str] = []
    ambiguous = list(r.reasons)
    kinds = set(r.kinds)
    if not kinds:
        missing.append("kind")
    elif len(kinds) > 1:
        ambiguous.append("both a door and a drawer are named")
    if r.plural_only:
        ambiguous.append(f"more than one {next(iter(kinds), 'part')} is named: which one?")
    vertical, horizontal = set(r.vertical), set(r.horizontal)
    if len(vertical) > 1:
        ambiguous.append("more than one height is named (" + ", ".join(sorted(_LABEL[c] for c in vertical)) + ")")
    if len(horizontal) > 1:
        ambiguous.append("more than one side is named (" + ", ".join(sorted(_LABEL[c] for c in horizontal)) + ")")
    if r.next_to and vertical and horizontal:
        ambiguous.append("'next to' in a grid: beside or below?")
    v = _label(r.vertical, VERTICAL, "v") if len(vertical) == 1 else ""
    h = _label(r.horizontal, HORIZONTAL, "h") if len(horizontal) == 1 else ""
    if r.middles:
        if r.middles > 1 or (vertical and horizontal):
            ambiguous.append("'middle' of what: the row or the column?")
        elif vertical:
            h = "middle"
        else:
            v = "middle"
    if missing or ambiguous or r.unknown:
        raise InstructionNotUnderstood(text, tuple(missing), tuple(ambiguous), r.unknown)
    return Description(vertical=v, horizontal=h, kind=kinds.pop())
