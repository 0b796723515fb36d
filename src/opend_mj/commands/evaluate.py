"""`opend run`, `opend score`, `opend search-grasp`."""

from __future__ import annotations

from pathlib import Path

import click

from opend_mj.language import TARGET_KINDS


def _check_hands(ctx, param, value):
    from opend_mj.sim.hands import list_hands

    known = list_hands()
    for name in value:
        if name not in known:
            raise click.BadParameter(f"unknown hand {name!r}; known: {', '.join(known)}", ctx, param)
    return value


def _check_solver(ctx, param, value):
    """A known solver name (or a tuple of them, for options given several times)."""
    from opend_mj.policy.solvers import list_solvers

    for name in (value,) if isinstance(value, str) else value:
        if name not in list_solvers():
            raise click.BadParameter(f"unknown handle solver {name!r}; known: {', '.join(list_solvers())}", ctx, param)
    return value


def _check_timestep(ctx, param, value):
    """A physics timestep such as 1/480 or 0.002, dividing the 60 Hz control step evenly (or None)."""
    if value is None:
        return None
    from fractions import Fraction

    from opend_mj.sim.task import TaskConfig

    try:
        seconds = float(Fraction(value.strip()))
        TaskConfig(physics_timestep=seconds)
    except (ValueError, ZeroDivisionError) as exc:
        raise click.BadParameter(f"{value!r}: {exc}", ctx, param) from None
    return seconds


def _check_cabinets(ctx, param, value):
    if not (Path(value) / "manifest.json").is_file():
        raise click.BadParameter(f"{value}: no manifest.json here; run `opend build-assets --out {value}` first",
                                 ctx, param)
    return value


@click.command("run")
@click.option("--hand", "hands", multiple=True, default=("allegro",), show_default=True, callback=_check_hands,
              help="Hand name (repeat for several).")
@click.option("--solver", default="oracle", show_default=True, callback=_check_solver)
@click.option("--split", type=click.Choice(["train", "test", "all"]), default="test", show_default=True)
@click.option("--workers", type=click.IntRange(min=1), default=1, show_default=True,
              help="Episodes at the same time (local: processes; ray: CPUs of a local Ray instance, min 2).")
@click.option("--backend", type=click.Choice(["local", "ray"]), default="local", show_default=True,
              help="local: this machine's process pool; ray: a Ray cluster (--address) or a local Ray instance.")
@click.option("--address", default=None, help="Ray cluster address (e.g. auto, ray://head:10001); with --backend ray.")
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), default=Path("results.jsonl"),
              show_default=True, help="Results file, one JSON line per episode (in the current folder by default).")
@click.option("--cabinets", "cabinets_dir", type=click.Path(exists=True, file_okay=False, path_type=Path),
              default=Path("cabinets"), show_default=True, callback=_check_cabinets)
@click.option("--limit", type=click.IntRange(min=1), default=None, help="First K targets of the split only.")
@click.option("--target", "targets", multiple=True, metavar="ID[:JOINT]",
              help="Only this cabinet (every target) or this target of it, e.g. 45780:joint_1 (repeatable).")
@click.option("--kind", type=click.Choice(TARGET_KINDS), default=None,
              help="Only targets of this kind (drawers or doors) [both].")
@click.option("--seed", "seeds", type=int, multiple=True, default=(0,), show_default=True,
              help="Episode seed: each cabinet's room, light and camera. Repeat to run every episode "
                   "in several draws of the scenes (one record per seed; `opend score` pools them).")
@click.option("--video", "video_dir", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Write an MP4 per episode here.")
@click.option("--light-scale", type=click.FloatRange(min=0), default=1.0, show_default=True)
@click.option("--pull", type=click.Choice(["straight", "arc"]), default="arc", show_default=True)
@click.option("--paraphrase", type=click.IntRange(0, 3), default=0, show_default=True,
              help="0: the Algorithm 1 instruction; 1-3: reworded ('open the drawer at the top on the left').")
@click.option("--instruction-file", "instruction_file", type=click.Path(exists=True, dir_okay=False, path_type=Path),
              default=None, help="Your own phrasings (JSON or CSV: per target, or per Algorithm 1 template, handed "
                                 "out in turn; see docs/language.md). Excludes --paraphrase.")
@click.option("--physics-timestep", "physics_timestep", default=None, callback=_check_timestep,
              help="Physics step in seconds, e.g. 1/120 (default 1/480). Coarser is faster and softer: "
                   "see BENCHMARKS.md for success and penetration at each.")
@click.option("--policy", default=None, metavar="bc|module:Class|file.py[:Class]",
              help="Evaluate this agent instead of the planner (docs/evaluation.md, Agent reference); "
                   "its name is the results' solver column. bc: the behaviour-cloning policy "
                   "(checkpoints/bc_<hand>.pt in the current folder, else the shipped one; docs/demonstrations.md).")
@click.option("--policy-arg", "policy_args", multiple=True, metavar="KEY=VALUE",
              help="Constructor argument of the --policy agent (repeatable; values parsed as JSON where they can be).")
@click.option("--agent-in-process", "agent_in_process", is_flag=True, default=False,
              help="Run the --policy agent in the simulator's process instead of a process of its own "
                   "(for debugging: it can then reach the simulator; every record and `opend score` say so).")
@click.option("--agent-memory", "agent_memory", default=None, metavar="SIZE",
              help="Address-space limit of the --policy agent's process, e.g. 4G, 512M; 0: none [half the "
                   "machine's memory]. An episode whose agent exceeds it is recorded as an error "
                   "(error_kind agent_memory) and the run goes on.")
@click.option("--perturb", "perturb", multiple=True, metavar="AXIS=LEVEL",
              help="Run under a perturbation (repeatable; axes camera_pose, camera_fov, light, texture, "
                   "distractors, physics, depth_noise, instruction; levels mild, strong; drawn per scene "
                   "from the seed; docs/robustness.md). Goes into every record.")
@click.option("--wait", is_flag=True, default=False,
              help="If another run is writing --out, wait for it to finish (default: exit with status 2).")
@click.option("--episode-timeout", "episode_timeout", type=click.FloatRange(min=0), default=None, metavar="S",
              help="Wall-clock limit of one episode in seconds (default 600; 0: none). An episode past it is "
                   "recorded as an error (error_kind timeout) and the run goes on.")
@click.pass_context
def run(ctx, hands, solver, split, workers, backend, address, out, cabinets_dir, limit, targets, kind, seeds, video_dir,
        light_scale,
        pull, paraphrase, instruction_file, physics_timestep, policy, policy_args, agent_in_process, agent_memory,
        perturb, wait, episode_timeout):
    """Run episodes (resumable: episodes already in --out are skipped).

    Exit status: 0 when the run finished (error episodes are recorded as lines with `error` and
    `error_reason`); 1 when every episode run this time was an error; 2 for bad arguments, or when
    another run is writing the same --out (one writer per results file; --wait waits instead).
    """
    import dataclasses

    from opend_mj.backends import BackendError
    from opend_mj.evaluation.deadline import DEFAULT_EPISODE_TIMEOUT
    from opend_mj.evaluation.jobs import make_jobs
    from opend_mj.evaluation.lock import ResultsLocked
    from opend_mj.evaluation.pool import run_jobs

    if address is not None and backend != "ray":
        raise click.UsageError("--address needs --backend ray")
    perturb = _check_perturb(perturb, paraphrase, instruction_file)
    policy_spec, parsed_args = None, ()
    actor = solver  # what acts, as the results' solver column names it: a handle solver or an agent
    isolation, memory = "process", None
    if policy is not None:
        from opend_mj.evaluation.agent_process import default_agent_memory, parse_memory

        if ctx.get_parameter_source("solver") is not click.core.ParameterSource.DEFAULT:
            raise click.UsageError("--policy and --solver exclude each other (an agent finds the handle itself)")
        try:
            memory = default_agent_memory() if agent_memory is None else parse_memory(agent_memory)
        except ValueError as exc:
            raise click.BadParameter(str(exc), ctx, param_hint="--agent-memory") from None
        isolation = "in-process" if agent_in_process else "process"
        policy_spec, parsed_args, actor = _agent_spec(ctx, policy, policy_args, isolation, memory)
    elif policy_args:
        raise click.UsageError("--policy-arg needs --policy")
    elif agent_in_process or agent_memory is not None:
        raise click.UsageError("--agent-in-process and --agent-memory need --policy")
    try:
        jobs = [job for seed in dict.fromkeys(seeds)
                for job in make_jobs(cabinets_dir, hands, actor, split=split, seed=seed, light_scale=light_scale,
                                     pull=pull, limit=limit, video_dir=video_dir, paraphrase=paraphrase,
                                     physics_timestep=physics_timestep, targets=targets or None, kind=kind,
                                     perturb=perturb)]
    except ValueError as exc:
        raise click.BadParameter(str(exc), ctx, param_hint="--target") from None
    if policy_spec is not None:
        from opend_mj.evaluation.agent_process import with_containment

        jobs = with_containment([dataclasses.replace(j, policy=policy_spec, policy_args=parsed_args) for j in jobs],
                                isolation, memory)
    if instruction_file is not None:
        jobs = _with_phrasings(jobs, instruction_file, paraphrase)
    _check_scenes(jobs)
    if not jobs:
        click.echo(f"no episodes: split {split!r} of {cabinets_dir} has no targets", err=True)
    try:
        counts = run_jobs(jobs, out, workers=workers, backend=backend, address=address, wait=wait,
                          on_wait=lambda message: click.echo(f"waiting: {message}", err=True),
                          episode_timeout=DEFAULT_EPISODE_TIMEOUT if episode_timeout is None else episode_timeout or None)
    except ResultsLocked as exc:
        click.echo(f"error: {exc}", err=True)
        raise SystemExit(2) from None
    except (ValueError, BackendError) as exc:  # a results file corrupt in its middle; no Ray cluster
        raise click.ClickException(str(exc)) from exc
    click.echo(f"{counts['ran']} episodes run, {counts['skipped']} already done, {counts['errors']} errors, "
               f"{counts['success']} successes -> {out}")
    if counts["ran"] and counts["errors"] == counts["ran"]:
        click.echo("error: every episode failed to run (see error_reason in the results file)", err=True)
        raise SystemExit(1)


def _agent_spec(ctx, policy: str, policy_args, isolation: str, memory: int | None) -> tuple[str, tuple, str]:
    """(spec, parsed arguments, name) of a --policy agent. Its name is read in an agent process of its
    own, as the run will hold it (in this process only with --agent-in-process): the process that
    writes the results never imports an agent that runs apart."""
    from opend_mj.evaluation.agent_process import AgentFailure, describe_agent
    from opend_mj.evaluation.agents import agent_name, load_agent, parse_policy_args, resolve_policy
    from opend_mj.policy.learned.checkpoint_io import CheckpointError

    try:
        parsed_args = parse_policy_args(policy_args)
        target, attr = resolve_policy(policy)
        spec = f"{target}:{attr}"
        if isolation == "in-process":
            return spec, parsed_args, agent_name(load_agent(spec, parsed_args))
        return spec, parsed_args, describe_agent(spec, parsed_args, memory)["name"]
    except AgentFailure as exc:  # raised in the agent's process: its reason says it
        if exc.error_kind == "checkpoint":  # a file refused unread: a failure (exit 1), not a usage error
            raise click.ClickException(str(exc)) from None
        raise click.BadParameter(f"{policy}: {exc}", ctx, param_hint="--policy") from None
    except CheckpointError as exc:  # the same, from an agent loaded here (--agent-in-process)
        raise click.ClickException(str(exc)) from None
    except Exception as exc:  # noqa: BLE001 (a bad spec, an agent whose constructor fails)
        raise click.BadParameter(f"{policy}: {exc}", ctx, param_hint="--policy") from None


class PerturbRefused(click.ClickException):
    """A perturbation refused before any episode runs (one line; exit status 2, as bad arguments)."""

    exit_code = 2


def _check_perturb(items, paraphrase: int = 0, instruction_file=None) -> str | None:
    """``--perturb`` values -> the canonical spec (None for none); refuses an unknown axis or level."""
    from opend_mj.sim.perturb import PerturbError, parse_perturb, perturb_items

    try:
        spec = parse_perturb(list(items))
    except PerturbError as exc:
        raise PerturbRefused(str(exc)) from None
    if "instruction" in perturb_items(spec) and (paraphrase or instruction_file is not None):
        raise PerturbRefused("--perturb instruction=... rewords the instruction itself; "
                             "it excludes --paraphrase and --instruction-file")
    return spec


def _check_scenes(jobs) -> None:
    """Refuse a run whose perturbation makes a scene invalid, before any episode runs."""
    from opend_mj.evaluation.jobs import check_perturbed_scenes
    from opend_mj.sim.perturb import PerturbError

    try:
        check_perturbed_scenes(jobs)
    except PerturbError as exc:
        raise PerturbRefused(str(exc)) from None


def _with_phrasings(jobs, instruction_file: Path, paraphrase: int):
    """``jobs`` with the file's phrasings; says how the parser reads them (per target)."""
    from opend_mj.evaluation.phrasings import (
        InstructionFileError,
        assign_phrasings,
        load_instruction_file,
        reading_summary,
    )

    if paraphrase:
        raise click.UsageError("--instruction-file and --paraphrase exclude each other")
    try:
        jobs = assign_phrasings(jobs, load_instruction_file(instruction_file))
    except InstructionFileError as exc:
        raise click.BadParameter(str(exc), param_hint="--instruction-file") from None
    seen = reading_summary(jobs)
    click.echo(f"{instruction_file}: {seen['targets']} targets reworded; the parser reads {seen['as_template']} "
               f"as their template, refuses {seen['refused']}, misreads {seen['misread']}", err=True)
    return jobs


@click.command("reword")
@click.option("--cabinets", "cabinets_dir", type=click.Path(exists=True, file_okay=False, path_type=Path),
              default=Path("cabinets"), show_default=True, callback=_check_cabinets)
@click.option("--split", type=click.Choice(["train", "test", "all"]), default="test", show_default=True)
@click.option("--seed", type=int, default=0, show_default=True, help="Which rewording each target gets.")
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), required=True,
              help="The instruction file to write (.json), for `opend run --instruction-file`.")
def reword(cabinets_dir, split, seed, out):
    """Write an instruction file with one rewording per target, drawn from the grammar."""
    import json

    from opend_mj.evaluation.phrasings import generated_instruction_file

    data = generated_instruction_file(cabinets_dir, split, seed)
    out.write_text(json.dumps(data, indent=1) + "\n")
    click.echo(f"{out}: {sum(len(v) for v in data['targets'].values())} targets")


@click.command("score")
@click.argument("results", nargs=-1, required=True, type=click.Path(exists=True, path_type=Path))
@click.option("--csv", "csv_path", type=click.Path(path_type=Path), default=None)
@click.option("--plot", "plot_path", type=click.Path(path_type=Path), default=None)
@click.option("--summary", "summary_path", type=click.Path(path_type=Path), default=None,
              help="also write per-hand aggregates (counts only, no cabinet ids) as JSON, e.g. "
                   "results/real/oracle_all.json for `opend report`")
@click.option("--manifest", "manifest_path", type=click.Path(exists=True, path_type=Path), default=None,
              help="with --summary: the build's manifest.json; the targets it excluded count as failures")
@click.option("--common", is_flag=True, default=False,
              help="score only the episodes every file holds (same cabinet, target, hand, seed and conditions; "
                   "any solver or agent): files with different episode sets are then compared on the same ones")
def score(results, csv_path, plot_path, summary_path, manifest_path, common):
    """The paper's tables from one or more results files (Markdown to stdout). Files that hold
    different episodes are named on stderr, one line per pair."""
    from opend_mj.evaluation.scoring import (
        episode_set_warnings,
        load_runs,
        merge_runs,
        plot_success,
        report_markdown,
        write_csv,
    )

    named = ", ".join(str(p) for p in results)
    try:
        runs = load_runs(results)
    except ValueError as exc:  # a corrupt line, or a line that is no episode record: named with its file
        raise click.ClickException(str(exc)) from None
    for line in episode_set_warnings(runs):
        click.echo(f"warning: {line}", err=True)
    records = merge_runs(runs, common=common)
    if common and not records:
        raise click.ClickException(f"{named}: no episode is in every file")
    try:
        table = report_markdown(records)
    except (ValueError, TypeError, KeyError, AttributeError) as exc:  # a field of the wrong type
        raise click.ClickException(f"{named}: a record the scorer cannot read ({type(exc).__name__}: {exc})") from None
    click.echo(table)
    if csv_path:
        write_csv(records, csv_path)
    if plot_path:
        plot_success(records, plot_path)
    if summary_path:
        from opend_mj.evaluation.report import write_summary

        try:
            write_summary(records, summary_path, label=" ".join(str(p) for p in results), manifest=manifest_path)
        except ValueError as exc:
            raise click.ClickException(str(exc)) from exc


@click.command("report")
@click.option("--results", "results_dir", type=click.Path(path_type=Path), default=Path("results"),
              show_default=True, help="results/*.jsonl (generated) and results/real/*.json (real aggregates)")
@click.option("--out", type=click.Path(path_type=Path), default=Path("docs/results.md"), show_default=True)
@click.option("--readme", type=click.Path(path_type=Path), default=Path("README.md"), show_default=True,
              help="README whose results table (between its markers) is rewritten")
@click.option("--no-readme", is_flag=True, help="write the results page only")
def report(results_dir, out, readme, no_readme):
    """Write docs/results.md and the README's results table from the results files."""
    from opend_mj.evaluation.report import write_report

    try:
        path = write_report(results_dir, out, None if no_readme else readme)
    except ValueError as exc:
        raise click.ClickException(str(exc)) from exc
    click.echo(f"wrote {path}" + ("" if no_readme else f" and the table in {readme}"))


@click.command("search-grasp")
@click.option("--hand", required=True)
@click.option("--cabinets", "cabinets_dir", type=click.Path(path_type=Path), default=Path("cabinets"),
              show_default=True)
@click.option("--n-cabinets", type=int, default=3, show_default=True)
@click.option("--scales", default="0.8,1.0,1.15", show_default=True)
@click.option("--depths", default="-0.01,0.0,0.008", show_default=True)
@click.option("--workers", type=int, default=1, show_default=True)
@click.option("--save/--no-save", default=True, show_default=True)
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Where to save the grasp tuning [the hand folder's grasp.json; a built-in hand of an "
                   "installed package is never written, so there --out is needed].")
def search_grasp(hand, cabinets_dir, n_cabinets, scales, depths, workers, save, out):
    """Search finger closing and grasp depth on the first training cabinets; save the hand's grasp.json."""
    from opend_mj.evaluation.grasp_search import search_grasp as _search
    from opend_mj.resources import in_package
    from opend_mj.sim.hands import get_hand

    try:
        out = out or get_hand(hand).grasp_file
    except KeyError as exc:
        raise click.BadParameter(exc.args[0], param_hint="'--hand'") from exc
    if save and in_package(out):
        raise click.UsageError(f"{out} lies inside the installed package, which is never written: "
                               "pass --out FILE (or --no-save)")
    profile = _search(hand, cabinets_dir, n_cabinets=n_cabinets,
                      scales=[float(x) for x in scales.split(",")],
                      depths=[float(x) for x in depths.split(",")], workers=workers)
    click.echo(f"chosen: close_scale={profile.close_scale} grasp_depth={profile.grasp_depth}")
    if save:
        click.echo(f"saved {profile.save(out)}")


@click.command("evaluate-solver")
@click.option("--solver", "solvers", multiple=True, default=("cliport",), show_default=True, callback=_check_solver,
              help="Handle solver (repeat for several).")
@click.option("--cabinets", "cabinets_dir", type=click.Path(exists=True, file_okay=False, path_type=Path),
              default=Path("cabinets"), show_default=True, callback=_check_cabinets)
@click.option("--split", type=click.Choice(["train", "test", "all"]), default="test", show_default=True)
@click.option("--seed", "seeds", type=int, multiple=True, default=(0,), show_default=True,
              help="Episode seed: each cabinet's room, light and camera. Repeat to pool several draws of "
                   "the same targets (the table adds each seed's rate).")
@click.option("--light-scale", type=click.FloatRange(min=0), default=1.0, show_default=True)
@click.option("--paraphrase", type=click.IntRange(0, 3), default=0, show_default=True)
@click.option("--perturb", "perturb", multiple=True, metavar="AXIS=LEVEL",
              help="Render the scenes under a perturbation, as `opend run --perturb` does (repeatable).")
@click.option("--limit", type=click.IntRange(min=1), default=None, help="First K targets of the split only.")
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Write one JSON line per target and solver here (one file per solver and seed when "
                   "there are several: <stem>_<solver>_s<seed>.jsonl).")
@click.option("--progress/--no-progress", default=True)
def evaluate_solver(solvers, cabinets_dir, split, seeds, light_scale, paraphrase, perturb, limit, out, progress):
    """Locate rate of handle solvers: render each target's scene once, grade the solver's box (no episodes)."""
    from opend_mj.evaluation.locate import evaluate_locate, format_summary, locate_jobs, summarise

    seeds = tuple(dict.fromkeys(seeds))
    perturb = _check_perturb(perturb, paraphrase)
    if perturb is not None:
        _check_scenes([job for seed in seeds for job in locate_jobs(cabinets_dir, split, seed, light_scale,
                                                                     paraphrase, limit, perturb=perturb)])
    records = []
    for solver in solvers:
        for seed in seeds:
            part = out
            if out is not None and (len(solvers) > 1 or len(seeds) > 1):
                tags = ([solver] if len(solvers) > 1 else []) + ([f"s{seed}"] if len(seeds) > 1 else [])
                part = out.with_name("_".join([out.stem, *tags]) + out.suffix)
            records += evaluate_locate(cabinets_dir, solver, split=split, seed=seed, light_scale=light_scale,
                                       paraphrase=paraphrase, limit=limit, progress=progress, out=part,
                                       perturb=perturb)
    click.echo(format_summary(summarise(records)))


@click.command("robustness")
@click.option("--solver", "solvers", multiple=True, callback=_check_solver,
              help="A handle solver for the planner (repeatable).")
@click.option("--policy", "policies", multiple=True, metavar="bc|module:Class|file.py[:Class]",
              help="An agent instead of the planner (repeatable; as `opend run --policy`).")
@click.option("--hand", "hands", multiple=True, default=("allegro",), show_default=True, callback=_check_hands)
@click.option("--split", type=click.Choice(["train", "test", "all"]), default="test", show_default=True)
@click.option("--cabinets", "cabinets_dir", type=click.Path(exists=True, file_okay=False, path_type=Path),
              default=Path("cabinets"), show_default=True, callback=_check_cabinets)
@click.option("--axis", "axes", multiple=True, metavar="AXIS",
              help="Only these perturbation axes (repeatable) [every axis, at both levels].")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--limit", type=click.IntRange(min=1), default=None, help="First K targets of the split only.")
@click.option("--workers", type=click.IntRange(min=1), default=1, show_default=True)
@click.option("--records", "records_dir", type=click.Path(file_okay=False, path_type=Path),
              default=Path("build/robustness"), show_default=True,
              help="Per-episode records, one resumable file per solver or agent: <dir>/<name>_<split>.jsonl.")
@click.option("--out", "out_prefix", type=click.Path(dir_okay=False, path_type=Path),
              default=Path("build/robustness/robustness"), show_default=True,
              help="The table: <out>.md, <out>.json (counts only) and the plot <out>.png.")
@click.option("--table-only", is_flag=True, default=False,
              help="Run nothing: tabulate the records already under --records.")
def robustness(solvers, policies, hands, split, cabinets_dir, axes, seed, limit, workers, records_dir, out_prefix,
               table_only):
    """Nominal and every perturbation axis at both levels, for each solver or agent: a table of success
    with 95 % intervals against nominal, and a plot (docs/robustness.md)."""
    from opend_mj.evaluation.pool import run_jobs
    from opend_mj.evaluation.robustness import records_path, robustness_jobs, write_outputs
    from opend_mj.evaluation.scoring import load_records
    from opend_mj.sim.perturb import AXES, PerturbError

    unknown = [a for a in axes if a not in AXES]
    if unknown:
        raise PerturbRefused(f"--axis {unknown[0]!r}: unknown perturbation axis; known: {', '.join(AXES)}")
    axes = tuple(axes) or AXES
    if not solvers and not policies:
        raise click.UsageError("give at least one --solver or --policy")
    entries = [(s, None, ()) for s in solvers]
    if policies:
        from opend_mj.evaluation.agent_process import default_agent_memory, with_containment

        memory = default_agent_memory()
    for policy in policies:
        spec, args, name = _agent_spec(click.get_current_context(), policy, (), "process", memory)
        entries.append((name, spec, args))
    paths = []
    plans = []
    for name, policy, args in entries:
        path = records_path(records_dir, name, split)
        paths.append(path)
        if table_only:
            continue
        try:  # every scene of every entry checked before any episode runs
            jobs = robustness_jobs(cabinets_dir, hands, name, split=split, seed=seed, limit=limit, axes=axes,
                                   policy=policy, policy_args=args)
            plans.append((path, with_containment(jobs, "process", memory) if policy else jobs))
        except PerturbError as exc:
            raise PerturbRefused(str(exc)) from None
    for path, jobs in plans:
        path.parent.mkdir(parents=True, exist_ok=True)
        counts = run_jobs(jobs, path, workers=workers)
        click.echo(f"{path}: {counts['ran']} episodes run, {counts['skipped']} already done, "
                   f"{counts['errors']} errors", err=True)
    from opend_mj.evaluation.jobs import make_jobs

    from opend_mj.sim.perturb import perturb_items

    # the table holds exactly this command's episodes (a records file may hold more: another --limit,
    # other hands, other axes)
    wanted = {(j.cabinet, j.joint, j.hand) for j in make_jobs(cabinets_dir, hands, "-", split=split, seed=seed,
                                                              limit=limit)}
    records = [r for r in load_records([p for p in paths if p.is_file()])
               if (r["cabinet"], r["joint"], r["hand"]) in wanted and int(r.get("seed", 0)) == seed
               and set(perturb_items(r.get("perturb"))) <= set(axes)]
    if not records:
        raise click.ClickException(f"no records under {records_dir} for {', '.join(n for n, _, _ in entries)}")
    words = ([f"--solver {x}" for x in solvers] + [f"--policy {x}" for x in policies]
             + [f"--hand {h}" for h in hands] + [f"--split {split}", f"--cabinets {cabinets_dir}"]
             + [f"--axis {a}" for a in axes if len(axes) < len(AXES)] + ([f"--limit {limit}"] if limit else [])
             + ([f"--seed {seed}"] if seed else []))
    write_outputs(records, out_prefix, title=f"Robustness ({split} split of {cabinets_dir})",
                  label=f"{Path(cabinets_dir).name}, split {split}, seed {seed}"
                        + (f", first {limit} targets" if limit else ""),
                  command="opend robustness " + " ".join(words))
    click.echo(out_prefix.with_suffix(".md").read_text())
    click.echo(f"wrote {out_prefix.with_suffix('.md')}, .json, .png", err=True)
