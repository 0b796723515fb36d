"""`opend demos` (the planner's episodes as demonstrations) and `opend train-policy` (behaviour cloning)."""

from __future__ import annotations

from pathlib import Path

import click

from opend_mj.commands.evaluate import _check_cabinets, _check_hands, _check_perturb, _check_scenes, _check_solver
from opend_mj.language import TARGET_KINDS


@click.command("demos")
@click.option("--hand", "hands", multiple=True, default=("allegro",), show_default=True, callback=_check_hands,
              help="Hand name (repeat for several).")
@click.option("--solver", default="oracle", show_default=True, callback=_check_solver,
              help="The planner's handle solver (its box is stored with the demos).")
@click.option("--split", type=click.Choice(["train", "test", "all"]), default="train", show_default=True)
@click.option("--cabinets", "cabinets_dir", type=click.Path(exists=True, file_okay=False, path_type=Path),
              default=Path("cabinets"), show_default=True, callback=_check_cabinets)
@click.option("--cabinet-id", "cabinet_ids", multiple=True, help="Only these cabinets (repeatable).")
@click.option("--seeds", type=click.IntRange(min=1), default=1, show_default=True,
              help="Episode seeds 0..N-1 per target (each seed: another room, light and camera).")
@click.option("--limit", type=click.IntRange(min=1), default=None, help="First K targets of the split only.")
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), default=Path("demos/planner.hdf5"),
              show_default=True, help="HDF5 file (robomimic / LIBERO layout); appended to, resumable.")
@click.option("--image-size", type=click.IntRange(min=0), default=0, show_default=True,
              help="Also store the front camera's RGB-D at every step at this size (0: none).")
@click.option("--keep-failures", is_flag=True, default=False,
              help="Keep failed episodes too (attrs success=false and failed_stage say why).")
@click.option("--noise-pos", type=click.FloatRange(min=0), default=0.0, show_default=True,
              help="DART: spread (m) of a smooth offset added to the root target sent; labels stay the planner's.")
@click.option("--noise-rot", type=click.FloatRange(min=0), default=0.0, show_default=True,
              help="DART: spread (rad) of the root target's rotation offset.")
@click.option("--noise-fingers", type=click.FloatRange(min=0), default=0.0, show_default=True,
              help="DART: spread of the finger targets' offsets (fraction of each actuator range).")
@click.option("--noise-tau", type=click.FloatRange(min=0, min_open=True), default=0.3, show_default=True,
              help="DART: correlation time (s) of the offsets.")
@click.option("--perturb", "perturb", multiple=True, metavar="AXIS=LEVEL",
              help="Record under a perturbation, as `opend run --perturb` runs (repeatable); e.g. "
                   "hand_start=strong: approaches from starts farther out, for training data.")
@click.option("--workers", type=click.IntRange(min=1), default=1, show_default=True,
              help="Worker processes (spawned).")
@click.option("--progress/--no-progress", default=True)
def demos(hands, solver, split, cabinets_dir, cabinet_ids, seeds, limit, out, image_size, keep_failures, noise_pos,
          noise_rot, noise_fingers, noise_tau, perturb, workers, progress):
    """Record the planner's episodes as demonstrations (agent observations and actions at 60 Hz)."""
    from opend_mj.apps.planner_demos import ActionNoise, RecordConfig, demo_jobs, log_path, record_demos

    if out.suffix.lower() not in (".hdf5", ".h5"):
        raise click.BadParameter(f"{out}: demonstrations are written as HDF5 (.hdf5 or .h5)", param_hint="--out")
    perturb = _check_perturb(perturb)  # refused (exit status 2) before any episode runs
    jobs = demo_jobs(cabinets_dir, hands, solver, split=split, seeds=range(seeds), limit=limit,
                     cabinet_ids=list(cabinet_ids) or None, perturb=perturb)
    if not jobs:
        raise click.ClickException(f"no episodes: split {split!r} of {cabinets_dir} has no targets")
    if perturb is not None:
        _check_scenes(jobs)
    noise = ActionNoise(pos=noise_pos, rot=noise_rot, fingers=noise_fingers, tau=noise_tau)
    config = RecordConfig(image_size=image_size, keep_failures=keep_failures, noise=noise)
    from opend_mj.apps.demos import DemoFileError

    try:
        counts = record_demos(jobs, out, workers=workers, config=config, progress=progress)
    except DemoFileError as exc:
        raise click.ClickException(str(exc)) from None
    click.echo(f"{counts['ran']} episodes recorded, {counts['skipped']} already tried, {counts['success']} "
               f"successes, {counts['kept']} kept, {counts['errors']} errors -> {out} (log {log_path(out)})")
    if counts["ran"] and counts["errors"] == counts["ran"]:
        click.echo(f"error: every episode failed to run (see the error fields in {log_path(out)})", err=True)
        raise SystemExit(1)


@click.command("train-policy")
@click.option("--demos", "demo_files", multiple=True, required=True,
              type=click.Path(exists=True, dir_okay=False, path_type=Path), help="Demonstrations file (repeatable).")
@click.option("--hand", default="allegro", show_default=True)
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Checkpoint [checkpoints/bc_<hand>.pt in the current folder, which --policy bc then loads before the shipped one]; a .json summary is written beside it.")
@click.option("--max-demos", type=click.IntRange(min=1), default=None,
              help="Train on the first N successful demos of the files only (data-scale studies).")
@click.option("--steps", type=click.IntRange(min=1), default=None, help="Optimiser steps [3000].")
@click.option("--batch-size", type=click.IntRange(min=1), default=None, help="[256]")
@click.option("--lr", type=float, default=None, help="[1e-3]")
@click.option("--chunk", type=click.IntRange(min=1), default=None, help="Actions per prediction [20].")
@click.option("--d-model", type=click.IntRange(min=8), default=None, help="Transformer width [64].")
@click.option("--grasp-token/--no-grasp-token", default=False, show_default=True,
              help="The grasp-style token: a head predicts the expert's grasp style at each step and the actions "
                   "are conditioned on it (needs demos that recorded grasp_style).")
@click.option("--watch", type=click.IntRange(min=0), default=12, show_default=True,
              help="Control steps between the depth images in which the policy watches the front it opens "
                   "(needs demos recorded with `front_watch`); 0: blind after the first image.")
@click.option("--kind", type=click.Choice(TARGET_KINDS), default=None,
              help="Train on the demos of this kind of target only (a member that a bundle routes that kind "
                   "to: `opend bundle-policy --route`) [both].")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--init", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Start from this checkpoint's weights (a warm start; its architecture wins) instead of "
                   "from scratch.")
@click.option("--warm-start/--no-warm-start", default=True, show_default=True,
              help="DAgger: each round after round 0 starts from the previous round's policy, and the final "
                   "policy from the best round's, instead of from scratch.")
@click.option("--threads", type=click.IntRange(min=1), default=1, show_default=True, help="torch CPU threads.")
@click.option("--device", default="cpu", show_default=True)
@click.option("--dagger", "dagger_rounds", type=click.IntRange(min=0), default=None,
              help="DAgger: after training on the demos, this many rounds of rollouts of the policy on the "
                   "training split, labelled by the planner as an expert, and training again (docs/demonstrations.md).")
@click.option("--cabinets", "cabinets_dir", type=click.Path(exists=True, file_okay=False, path_type=Path),
              default=Path("cabinets"), show_default=True, help="DAgger: the cabinets whose training split is rolled out.")
@click.option("--extra-cabinets", "extra_cabinets", multiple=True,
              type=click.Path(exists=True, file_okay=False, path_type=Path),
              help="DAgger: more cabinets whose every target is rolled out too, e.g. a `opend generate --family` "
                   "set (repeatable; validation stays on --cabinets).")
@click.option("--dagger-dir", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="DAgger: what can be made again: rollouts, validation episodes, working checkpoints "
                   "[build/dagger/<hand>].")
@click.option("--keep-rounds", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="DAgger: each round's policy (float16) and validation figures, kept so that a later run "
                   "continues after the latest kept round [checkpoints/bc_rounds/<hand>].")
@click.option("--beta0", type=click.FloatRange(0, 1), default=0.5, show_default=True,
              help="DAgger: the share of steps at which the expert's action is stepped in round 1.")
@click.option("--beta-decay", type=click.FloatRange(0, 1), default=0.5, show_default=True,
              help="DAgger: that share's factor from one round to the next.")
@click.option("--dagger-targets", type=click.IntRange(min=1), default=None,
              help="DAgger: roll out the first K training targets only [all].")
@click.option("--final-steps", type=click.IntRange(min=1), default=None,
              help="DAgger: optimiser steps of the final policy, trained on every training cabinet [--steps].")
@click.option("--final-members", type=click.IntRange(min=1), default=1, show_default=True,
              help="DAgger: the final policy is a seed ensemble of this many members, each trained as the final "
                   "policy with seeds --seed, --seed + 1, ... and bundled into --out (`opend bundle-policy`).")
@click.option("--round-steps", type=click.IntRange(min=1), default=None,
              help="DAgger: optimiser steps of the rounds after round 0 [--steps].")
@click.option("--revisit", type=click.IntRange(min=0), default=0, show_default=True,
              help="DAgger: roll out the training targets whose rollout failed this many times more per round, "
                   "at other episode seeds (more expert labels where the policy fails).")
@click.option("--hold-after-plan/--no-hold-after-plan", default=False, show_default=True,
              help="DAgger: rollouts go on after the expert's plan ended with the part open, to the policy's "
                   "stop, labelled with the plan's last action (the hand stays where the planner leaves it).")
@click.option("--val-targets", type=click.IntRange(min=1), default=None,
              help="DAgger: validate on the first K validation targets only [all].")
@click.option("--workers", type=click.IntRange(min=1), default=1, show_default=True,
              help="DAgger: worker processes for the rollouts and the validation episodes.")
@click.option("--progress/--no-progress", default=True)
def train_policy(demo_files, hand, out, max_demos, steps, batch_size, lr, chunk, d_model, grasp_token, watch, kind, seed,
                 init,
                 warm_start, threads, device, dagger_rounds, cabinets_dir, extra_cabinets, dagger_dir, keep_rounds,
                 beta0, beta_decay,
                 dagger_targets, final_steps, final_members, round_steps, revisit, hold_after_plan, val_targets,
                 workers, progress):
    """Train the behaviour-cloning policy (a transformer over action chunks) from demonstrations."""
    import dataclasses

    from opend_mj.apps.planner_demos import load_training_demos
    from opend_mj.policy.learned.bc_model import BCConfig
    from opend_mj.policy.learned.bc_train import train_bc

    changes = {k: v for k, v in dict(steps=steps, batch_size=batch_size, lr=lr, chunk=chunk, d_model=d_model,
                                     watch=watch).items() if v is not None}
    if grasp_token:
        from opend_mj.policy.learned.bc_model import GRASP_STYLES

        changes["modes"] = len(GRASP_STYLES)
    config = dataclasses.replace(BCConfig(seed=seed), **changes)
    out = out or Path("checkpoints") / f"bc_{hand}.pt"
    if dagger_rounds is not None:
        from opend_mj.apps.dagger import DaggerConfig

        dagger = DaggerConfig(rounds=dagger_rounds, beta0=beta0, beta_decay=beta_decay, seed=seed,
                              limit=dagger_targets, val_limit=val_targets, final_steps=final_steps,
                              warm_start=warm_start, init=init, round_steps=round_steps, revisit=revisit,
                              hold=hold_after_plan, extra_cabinets=tuple(str(d) for d in extra_cabinets),
                              final_members=final_members)
        _train_with_dagger(demo_files, hand, out, config, dagger, cabinets_dir, dagger_dir, keep_rounds, workers,
                           threads, progress)
        return
    try:
        demos_list = load_training_demos(list(demo_files), max_demos=max_demos, kind=kind, hand=hand)
        summary = train_bc(demos_list, hand, config, out=out, progress=progress, threads=threads, device=device,
                           kind=kind, init=init)
    except (ValueError, FileNotFoundError) as exc:
        raise click.ClickException(str(exc)) from exc
    last = summary["history"][-1] if summary["history"] else {}
    click.echo(f"{summary['demos']} demos ({summary['samples']} steps, {summary['cabinets']} cabinets), "
               f"{summary['parameters']} parameters, {summary['seconds']:.0f} s; last {last} -> {out}")


def _train_with_dagger(demo_files, hand, out, config, dagger, cabinets_dir, folder, keep, workers, threads,
                       progress) -> None:
    """`opend train-policy --dagger`: the DAgger rounds (each kept in ``keep``), then the final policy
    (every training cabinet, from the best round) written to ``out`` with float16 weights."""
    import json

    from opend_mj.apps.dagger import run_dagger, save_half
    from opend_mj.apps.demos import DemoFileError

    folder = folder or Path("build/dagger") / hand
    keep = keep or Path("checkpoints/bc_rounds") / hand
    try:
        summary = run_dagger(list(demo_files), hand, cabinets_dir, folder, config, dagger, workers=workers,
                             threads=threads, progress=progress, log=click.echo, keep=keep)
    except (ValueError, FileNotFoundError, DemoFileError) as exc:
        raise click.ClickException(str(exc)) from exc
    members = [Path(m["checkpoint"]) for m in summary["final"]["members"]]
    bundled = {}
    if len(members) == 1:
        save_half(members[0], out)
    else:  # float16 members bundled into one seed ensemble
        from opend_mj.policy.learned.bc_model import bundle_policies

        halves = [m.with_suffix(".half.pt") for m in members]
        for m, h in zip(members, halves):
            save_half(m, h)
        bundled = {"bundle": bundle_policies(halves, out)}
    trained = json.loads(members[0].with_suffix(".json").read_text())
    # member 0's training summary, the DAgger run's and (several members) the bundle's: the bundle's own
    # .json would name the float16 copies, which have no training summary beside them
    out.with_suffix(".json").write_text(json.dumps({**trained, "dagger": summary, **bundled}, indent=1) + "\n")
    click.echo("validation success per round: " + ", ".join(f"{r['round']}: {r['val_success']} %"
                                                           for r in summary["rounds"])
               + f"; final policy (from round {summary['chosen']}, every training cabinet"
               + (f", {len(members)} seeds" if len(members) > 1 else "") + f") -> {out}")


@click.command("bundle-policy")
@click.argument("checkpoints", nargs=-1, required=True, type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), required=True,
              help="The bundle (one file; `opend run --policy bc --policy-arg checkpoint=OUT` or checkpoints/bc_<hand>.pt).")
@click.option("--ensemble-decay", type=float, default=None,
              help="The temporal ensemble's weight decay that the bundle uses by default [each member's own].")
@click.option("--route", "routes", multiple=True, metavar="KIND=I,J",
              help="Members (0-based, over the CHECKPOINTS' members in order) that act on targets of KIND "
                   "(drawer or door; repeatable) [all members].")
def bundle_policy(checkpoints, out, ensemble_decay, routes):
    """Bundle behaviour-cloning checkpoints (e.g. trained with different --seed) into one seed ensemble."""
    from opend_mj.policy.learned.bc_model import bundle_policies

    try:
        routed = {}
        for text in routes:
            kind, sep, ids = text.partition("=")
            if not sep or not ids.strip():
                raise ValueError(f"--route {text!r}: write KIND=I,J (e.g. drawer=0,2)")
            try:
                routed[kind.strip()] = [int(i) for i in ids.split(",")]
            except ValueError:
                raise ValueError(f"--route {text!r}: member indices are whole numbers separated by commas") from None
        summary = bundle_policies(list(checkpoints), out, ensemble_decay=ensemble_decay, routes=routed)
    except (ValueError, KeyError) as exc:
        raise click.ClickException(str(exc)) from exc
    click.echo(f"{summary['members']} members (seeds {summary['seeds']}), ensemble_decay "
               f"{summary['ensemble_decay']:g}, stop {summary['stop_time']:.2f} s -> {out}")
    for kind, route in summary.get("routes", {}).items():
        click.echo(f"  {kind}: members {route['members']}, stop {route['stop_time']:.2f} s")


@click.command("expert-check")
@click.option("--hand", "hands", multiple=True, default=("allegro",), show_default=True, callback=_check_hands,
              help="Hand name (repeat for several).")
@click.option("--lead", default="planner", show_default=True,
              help="Who acts before the switch: 'planner' (the planner itself) or an agent of `opend run --policy` (bc).")
@click.option("--lead-arg", "lead_args", multiple=True, help="key=value for the lead agent's constructor (repeatable).")
@click.option("--switch", "switches", multiple=True, type=click.FloatRange(min=0), default=(2.0, 4.0, 6.0),
              show_default=True, help="Seconds of simulated time after which the expert takes over (repeatable).")
@click.option("--split", type=click.Choice(["train", "test", "all"]), default="test", show_default=True)
@click.option("--cabinets", "cabinets_dir", type=click.Path(exists=True, file_okay=False, path_type=Path),
              default=Path("cabinets"), show_default=True, callback=_check_cabinets)
@click.option("--limit", type=click.IntRange(min=1), default=None, help="First K targets of the split only.")
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="JSON lines, one per takeover; appended to, resumable [results/expert/<lead>_<hand>_<split>.jsonl].")
@click.option("--summary", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Also write the counts per lead, hand and switch as JSON here (they are always written beside "
                   "--out as .json: what `opend report` reads; for real cabinets keep only this).")
@click.option("--workers", type=click.IntRange(min=1), default=1, show_default=True)
@click.option("--progress/--no-progress", default=True)
def expert_check(hands, lead, lead_args, switches, split, cabinets_dir, limit, out, summary, workers, progress):
    """The planner as an interactive expert, taking over episodes mid-way from a lead: what it opens."""
    import json

    from opend_mj.evaluation.agents import parse_policy_args
    from opend_mj.evaluation.jobs import make_jobs
    import sys

    from opend_mj.evaluation.takeover import check_expert, summarise_takeovers, takeover_summary

    jobs = make_jobs(cabinets_dir, hands, "oracle", split=split, limit=limit)
    if not jobs:
        raise click.ClickException(f"no episodes: split {split!r} of {cabinets_dir} has no targets")
    if out is None:
        out = Path("results/expert") / f"{lead.replace(':', '_').replace('/', '_')}_{'_'.join(hands)}_{split}.jsonl"
    try:
        args = parse_policy_args(lead_args)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--lead-arg") from None
    counts = check_expert(jobs, out, lead=lead, lead_args=args, switches=switches, workers=workers, progress=progress)
    records = [json.loads(line) for line in out.read_text().splitlines() if line.strip()]
    keys = {(j.cabinet, j.joint, j.hand, j.seed) for j in jobs}
    records = [r for r in records if (r["cabinet"], r["joint"], r["hand"], r["seed"]) in keys]
    click.echo(f"{out}: ran {counts['ran']}, errors {counts['errors']}")
    command = "opend expert-check " + " ".join(sys.argv[2:])
    for path in dict.fromkeys([out.with_suffix(".json"), summary]):  # beside the records, and where asked
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps(takeover_summary(records, command=command), indent=1) + "\n")
    click.echo(f"summary -> {summary or out.with_suffix('.json')}")
    for (who, switch), (s, n) in sorted(summarise_takeovers(records).items(), key=lambda kv: str(kv[0])):
        at = "all switches" if switch == "all" else f"switch {switch:g} s"
        click.echo(f"  {who}, {at}: {s}/{n} = {100.0 * s / max(n, 1):.1f} % opened")
