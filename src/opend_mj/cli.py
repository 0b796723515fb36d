"""The `opend` command line: parses arguments and calls library functions (which tests also call)."""

from __future__ import annotations

import click


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="opend-mj")
def main() -> None:
    """opend-mj: language-driven door and drawer opening on MuJoCo."""


if __name__ == "__main__":
    main()
