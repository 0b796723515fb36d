"""One section of BENCHMARKS.md, written in place by the benchmark scripts that own it."""

from __future__ import annotations

from pathlib import Path


def write_section(path: Path, title: str, text: str) -> None:
    """Put ``text`` (which starts with the heading line ``title``) into ``path`` in place of the
    section under that heading, up to the next ``## `` heading (or at the end where there is none)."""
    old = path.read_text() if path.exists() else "# Benchmarks\n"
    lines = old.rstrip("\n").split("\n")
    if title in lines:
        start = lines.index(title)
        end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("## ")), len(lines))
        lines[start:end] = text.rstrip("\n").split("\n") + ([""] if end < len(lines) else [])
    else:
        lines += [""] + text.rstrip("\n").split("\n")
    path.write_text("\n".join(lines) + "\n")
