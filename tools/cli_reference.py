"""Write docs/cli.md, the full command reference, from the `opend` click commands themselves.

    python tools/cli_reference.py            # rewrite docs/cli.md
    python tools/cli_reference.py --check    # exit 1 when docs/cli.md differs from what it would write

Each command's section is its own `--help` text, formatted at a fixed width so that the page does
not depend on the terminal; tests/test_docs.py checks that the page is current.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import click

ROOT = Path(__file__).resolve().parents[1]
#: The help text's width in characters (fixed: the page must not depend on the terminal).
WIDTH = 100

HEADER = """# Command reference

Every `opend` command with its options, as `opend COMMAND --help` prints them. Written by
`python tools/cli_reference.py` from the commands themselves; do not edit by hand
(`tests/test_docs.py` fails when this page and the commands disagree). The README lists the
commands used most; the Makefile's targets (`make quickstart`, `make results`, `make eval-real`,
`make test`, `make bench`) are described in the Makefile's comments.
"""


def command_help(name: str, command: click.Command, parent: click.Context) -> str:
    """``opend NAME --help`` as text, at :data:`WIDTH` columns."""
    ctx = click.Context(command, info_name=name, parent=parent, terminal_width=WIDTH, max_content_width=WIDTH)
    return command.get_help(ctx)


def reference() -> str:
    """The whole page: the group's help, then one section per command in the order of ``COMMANDS``."""
    from opend_mj.cli import COMMANDS, main

    root = click.Context(main, info_name="opend", terminal_width=WIDTH, max_content_width=WIDTH,
                         **main.context_settings)
    out = [HEADER, "```", main.get_help(root), "```", ""]
    for name in COMMANDS:
        command = main.get_command(root, name)
        summary = command.get_short_help_str(limit=WIDTH)
        out += [f"## `opend {name}`", "", summary, "", "```", command_help(name, command, root), "```", ""]
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "cli.md")
    ap.add_argument("--check", action="store_true", help="compare with --out instead of writing it")
    args = ap.parse_args(argv)
    text = reference()
    if args.check:
        current = args.out.read_text() if args.out.is_file() else ""
        if current != text:
            print(f"{args.out}: out of date; run python tools/cli_reference.py", file=sys.stderr)
            return 1
        return 0
    args.out.write_text(text)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
