"""Instructions from handle positions: the OpenD paper's Algorithm 1.

Targets of one type (door or drawer) are compared by the centres of their handles, seen from the
front (cabinet frame: +y is the viewer's left, +z is up). Vertical levels are labelled top / second
top / middle / second bottom / bottom; within one level, positions are labelled left / second left /
middle / second right / right. Words that are not needed are dropped ("top drawer", "left door",
"drawer"). Centres closer than a tolerance count as one level. A cabinet whose targets cannot all be
told apart (more than five levels, or two targets that read the same) is invalid.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class LanguageConfig:
    """Algorithm 1 of the OpenD paper: spatial labels from handle centres."""

    #: Handle centres closer than this (m) along an axis count as one level.
    level_tolerance: float = 0.04
    vertical_labels: dict[int, tuple[str, ...]] = field(
        default_factory=lambda: {
            1: ("",),
            2: ("top", "bottom"),
            3: ("top", "middle", "bottom"),
            4: ("top", "second top", "second bottom", "bottom"),
            5: ("top", "second top", "middle", "second bottom", "bottom"),
        }
    )
    horizontal_labels: dict[int, tuple[str, ...]] = field(
        default_factory=lambda: {
            1: ("",),
            2: ("left", "right"),
            3: ("left", "middle", "right"),
            4: ("left", "second left", "second right", "right"),
            5: ("left", "second left", "middle", "second right", "right"),
        }
    )


class LanguageInvalid(ValueError):
    """The targets of a cabinet cannot all be described uniquely."""


@dataclass(frozen=True)
class TargetLayout:
    """What the language generator sees of one target."""

    key: str  # e.g. the joint name
    kind: str  # "door" or "drawer"
    y: float  # handle centre, cabinet frame (+y = viewer's left)
    z: float  # handle centre height


@dataclass(frozen=True)
class Description:
    vertical: str
    horizontal: str
    kind: str

    @property
    def instruction(self) -> str:
        return " ".join(w for w in (self.vertical, self.horizontal, self.kind) if w)


def levels(values: list[float], tolerance: float, descending: bool = True) -> list[int]:
    """Level index of each value: values sorted (highest first) and split where a gap exceeds tolerance."""
    order = sorted(range(len(values)), key=lambda i: -values[i] if descending else values[i])
    out = [0] * len(values)
    level = 0
    for previous, current in zip(order, order[1:]):
        if abs(values[current] - values[previous]) > tolerance:
            level += 1
        out[current] = level
    return out


def describe(targets: list[TargetLayout], config: LanguageConfig = LanguageConfig()) -> dict[str, Description]:
    """Describe every target; raise LanguageInvalid if they cannot all be told apart."""
    if not targets:
        raise LanguageInvalid("no targets to describe")
    out: dict[str, Description] = {}
    for kind in sorted({t.kind for t in targets}):
        group = [t for t in targets if t.kind == kind]
        rows = levels([t.z for t in group], config.level_tolerance, descending=True)
        n_rows = max(rows) + 1
        if n_rows not in config.vertical_labels:
            raise LanguageInvalid(f"{n_rows} vertical levels of {kind}s (at most {max(config.vertical_labels)})")
        for row in range(n_rows):
            members = [t for t, r in zip(group, rows) if r == row]
            cols = levels([t.y for t in members], config.level_tolerance, descending=True)
            n_cols = max(cols) + 1
            if n_cols not in config.horizontal_labels:
                raise LanguageInvalid(
                    f"{n_cols} {kind}s side by side in one level (at most {max(config.horizontal_labels)})")
            for target, col in zip(members, cols):
                out[target.key] = Description(
                    vertical=config.vertical_labels[n_rows][row],
                    horizontal=config.horizontal_labels[n_cols][col],
                    kind=kind,
                )
    seen: dict[str, str] = {}
    for key in sorted(out):
        text = out[key].instruction
        if text in seen:
            raise LanguageInvalid(f"targets {seen[text]} and {key} both read '{text}'")
        seen[text] = key
    return out
