"""`opend view`, `opend teleop` and `opend replay`: the interactive viewer, teleoperation (the
paper's human study) and deterministic replay of recorded demonstrations."""

from __future__ import annotations

from pathlib import Path

import click

from opend_mj.commands.options import (
    cabinets_option,
    episode_from_options,
    scene_options,
)


def _key_help() -> str:
    from opend_mj.apps.teleop import KEY_HELP  # light: numpy + hands helpers

    return "\n".join(f"  {k:<13} {v}" for k, v in KEY_HELP)


def _display():
    from opend_mj.apps.viewer import require_display

    try:
        require_display()
    except RuntimeError as exc:
        raise click.ClickException(str(exc)) from exc


@click.command("view")
@cabinets_option
@click.option("--cabinet", "cabinet_id", required=True, help="Cabinet id (a folder under --cabinets).")
@scene_options
def view(cabinets, cabinet_id, target, hand, room, seed):
    """MuJoCo's interactive viewer on a task scene; the instruction is shown on screen and printed."""
    _display()
    from opend_mj.apps import viewer
    from opend_mj.apps.teleop import teleop_config
    from opend_mj.sim.task import make_environment

    env = make_environment(episode_from_options(cabinets, cabinet_id, target, hand, seed, room), teleop_config())
    try:
        viewer.view(env)
    finally:
        env.close()


_TELEOP_HELP = """Drive the hand with the keyboard (or a gamepad) in MuJoCo's viewer.

\b
One episode on --cabinet/--target, or with --study N a human study: N tasks drawn (seeded) from
the --split of the manifest, each appended to --out in the `opend run` JSON-lines format
(solver "human"), so `opend score` puts people beside the solvers. --record FILE saves every
finished episode as a demonstration (.hdf5/.h5 with h5py, else .npz; see opend_mj.apps.demos).

\b
Keys (click into the viewer window first):
{keys}
\b
Gamepad (pygame, optional): left stick x/y, right stick z/yaw, triggers pitch; A grip,
B profile, START end, BACK reset, shoulders step size.
"""


@click.command("teleop", help=_TELEOP_HELP.format(keys=_key_help()))
@cabinets_option
@click.option("--cabinet", "cabinet_id", default=None, help="Cabinet id (one episode; not with --study).")
@scene_options
@click.option("--study", type=click.IntRange(min=1), default=None, help="Run a human study of N tasks.")
@click.option("--split", type=click.Choice(["train", "test", "all"]), default="test", show_default=True)
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), default=Path("results/human.jsonl"),
              show_default=True, help="Results file (JSON lines), appended to.")
@click.option("--record", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Append each finished episode to this demonstration file.")
@click.option("--no-gamepad", is_flag=True, help="Do not look for a gamepad.")
def teleop(cabinets, cabinet_id, target, hand, room, seed, study, split, out, record, no_gamepad):
    if (study is None) == (cabinet_id is None):
        raise click.UsageError("give either --cabinet (one episode) or --study N")
    _display()
    from opend_mj.apps import viewer
    from opend_mj.apps.demos import DemoRecorder, write_demos
    from opend_mj.apps.teleop import (
        TeleopController,
        episode_record,
        run_study,
        sample_study,
        teleop_config,
        write_record,
    )
    from opend_mj.sim.task import make_environment

    config = teleop_config()
    if record is not None and record.exists():
        from opend_mj.apps.demos import DemoFileError, read_demos

        try:
            read_demos(record)  # refused before the session, not after it: a damaged or older-format file
        except DemoFileError as exc:
            raise click.ClickException(str(exc)) from None
    recorders = []

    def make_recorder():
        r = DemoRecorder()
        recorders.append(r)
        return r

    def save_demos():
        demos = [d for r in recorders for d in r.demos]
        if record is not None and demos:
            write_demos(record, demos, config)
            click.echo(f"{len(demos)} demonstration(s) appended to {record}")

    aborted = []

    def play(ctl):
        finished = viewer.teleop(ctl, gamepad=not no_gamepad)
        if not finished:
            aborted.append(ctl)
            raise click.Abort()
        o = ctl.outcome()
        click.echo(f"{'success' if o.success else 'failure'}: open ratio {o.open_ratio:.1%}")

    if study is not None:
        try:
            tasks = sample_study(cabinets, study, seed=seed, split=split)
        except (FileNotFoundError, ValueError) as exc:
            raise click.UsageError(str(exc)) from exc
        try:
            run_study(tasks, hand, play, out, task_config=config, room=room,
                      recorder_factory=make_recorder if record else None)
        finally:
            save_demos()
        click.echo(f"results appended to {out}")
        return

    episode = episode_from_options(cabinets, cabinet_id, target, hand, seed, room)
    env = make_environment(episode, config)
    try:
        recorder = make_recorder() if record else None
        ctl = TeleopController(env, recorder=recorder)
        play(ctl)
        if recorder is not None:
            recorder.finish(ctl)
        split_name = "unknown"
        try:
            from opend_mj.assets.layout import load_manifest

            split_name = next((c["split"] for c in load_manifest(cabinets).cabinets if c["id"] == cabinet_id),
                              "unknown")
        except FileNotFoundError:
            pass
        write_record(out, episode_record(ctl, cabinet=cabinet_id, split=split_name))
        click.echo(f"result appended to {out}")
    finally:
        env.close()
        save_demos()


@click.command("replay")
@click.argument("file", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--demo", "index", type=click.IntRange(min=0), default=None,
              help="Demo index (default: every demo in the file).")
@click.option("--cabinet-dir", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Use this compiled cabinet folder instead of the recorded path.")
@click.option("--tolerance", type=float, default=1e-9, show_default=True,
              help="Largest accepted |replayed - recorded| final open ratio.")
def replay(file, index, cabinet_dir, tolerance):
    """Replay recorded demonstrations deterministically; report the final open ratio of each.

    Exits with status 1 if a replay ends more than --tolerance away from the recorded open ratio."""
    import json

    from opend_mj.apps.demos import DemoFileError, read_demos, replay_demo

    try:
        attrs, demos = read_demos(file)
    except (DemoFileError, FileNotFoundError) as exc:
        raise click.ClickException(str(exc)) from None
    indices = range(len(demos)) if index is None else [index]
    if index is not None and index >= len(demos):
        raise click.UsageError(f"{file} has {len(demos)} demo(s); no demo {index}")
    args = json.loads(attrs["env_args"])
    bad = 0
    for i in indices:
        d = demos[i]
        r = replay_demo(d, args, cabinet_dir=cabinet_dir)
        ok = r.error <= tolerance
        bad += not ok
        click.echo(f"demo_{i}: {d.attrs['cabinet']} {d.attrs['target_joint']} \"{d.attrs['instruction']}\" "
                   f"{d.attrs['hand']} steps {d.num_samples}: open ratio {r.open_ratio:.9f} "
                   f"(recorded {r.recorded_open_ratio:.9f}, diff {r.error:.2e}) "
                   f"{'success' if r.success else 'failure'} {'OK' if ok else 'MISMATCH'}")
    if bad:
        raise SystemExit(1)
