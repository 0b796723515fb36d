"""The `opend` command line.

Thin by design: each command lives in `opend_mj.commands.<area>` and only parses arguments and calls
library functions that the tests call too. Commands are imported lazily so that `opend --help` and
light commands stay fast (mujoco, dm_control and torch are heavy imports).

Every command answers bad input in one line: exit status 2 for a usage error (click's), 1 for a
failure. An exception that no command turned into a message is shown as one line too (its type and
message); `opend --debug <command>` (or OPEND_DEBUG=1) shows its traceback instead.
"""

from __future__ import annotations

import importlib
import os

import click

from opend_mj import __version__

#: command name -> "module:attribute" of a click command.
COMMANDS: dict[str, str] = {
    "generate": "opend_mj.commands.assets:generate",
    "build-assets": "opend_mj.commands.dataset:build_assets",
    "hands": "opend_mj.commands.hands:hands",
    "render-hand": "opend_mj.commands.hands:render_hand",
    "run": "opend_mj.commands.evaluate:run",
    "score": "opend_mj.commands.evaluate:score",
    "robustness": "opend_mj.commands.evaluate:robustness",
    "report": "opend_mj.commands.evaluate:report",
    "reword": "opend_mj.commands.evaluate:reword",
    "evaluate-solver": "opend_mj.commands.evaluate:evaluate_solver",
    "search-grasp": "opend_mj.commands.evaluate:search_grasp",
    "render": "opend_mj.commands.render:render",
    "gallery": "opend_mj.commands.render:gallery",
    "make-data": "opend_mj.commands.learn:make_data",
    "train": "opend_mj.commands.learn:train",
    "view": "opend_mj.commands.teleop:view",
    "teleop": "opend_mj.commands.teleop:teleop",
    "replay": "opend_mj.commands.teleop:replay",
    "demos": "opend_mj.commands.demos:demos",
    "train-policy": "opend_mj.commands.demos:train_policy",
    "bundle-policy": "opend_mj.commands.demos:bundle_policy",
    "expert-check": "opend_mj.commands.demos:expert_check",
}


class LazyGroup(click.Group):
    """A click group whose subcommands are imported on first use."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(COMMANDS)

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        target = COMMANDS.get(name)
        if target is None:
            return None
        module_name, attr = target.split(":")
        try:
            module = importlib.import_module(module_name)
        except ImportError as exc:  # a broken install or module: say so, do not pretend the command is unknown
            raise click.ClickException(
                f"command {name!r} cannot be loaded: {type(exc).__name__}: {exc} (in {module_name})") from exc
        return getattr(module, attr)

    def invoke(self, ctx: click.Context):
        try:
            return super().invoke(ctx)
        except (click.exceptions.ClickException, click.exceptions.Exit, click.exceptions.Abort):
            raise
        except Exception as exc:  # noqa: BLE001 (anything a command did not catch: one line, or --debug)
            if ctx.params.get("debug") or os.environ.get("OPEND_DEBUG", "") not in ("", "0"):
                raise
            raise click.ClickException(one_line_error(exc) + " (opend --debug shows the traceback)") from None


def one_line_error(exc: BaseException) -> str:
    """``Type: message`` on one line (whitespace of a multi-line message collapsed)."""
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(version=__version__, package_name="opend-mj")
@click.option("--debug", is_flag=True, help="Show the traceback of an unexpected error (also: OPEND_DEBUG=1).")
def main(debug: bool) -> None:
    """opend-mj: language-driven door and drawer opening on MuJoCo.

    Outputs go where each command's options say; their default paths (cabinets/, results.jsonl,
    checkpoints/...) are relative to the current folder. Caches (the compiler's decompositions, the
    compiled control step) go to $XDG_CACHE_HOME/opend-mj, else ~/.cache/opend-mj ($OPEND_CACHE_DIR,
    where set, for the compiler's). The built-in hands
    and the shipped checkpoints are read from the installed package, which no command writes to.
    """


if __name__ == "__main__":
    main()
