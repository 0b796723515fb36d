"""`opend run`, `opend score`, `opend search-grasp`."""

from __future__ import annotations

from pathlib import Path

import click


@click.command("run")
@click.option("--hand", "hands", multiple=True, default=("allegro",), show_default=True,
              help="Hand name (repeat for several).")
@click.option("--solver", default="oracle", show_default=True)
@click.option("--split", type=click.Choice(["train", "test", "all"]), default="test", show_default=True)
@click.option("--workers", type=int, default=1, show_default=True)
@click.option("--out", type=click.Path(path_type=Path), default=Path("results.jsonl"), show_default=True)
@click.option("--cabinets", "cabinets_dir", type=click.Path(path_type=Path), default=Path("cabinets"),
              show_default=True)
@click.option("--limit", type=int, default=None, help="First K targets of the split only.")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--video", "video_dir", type=click.Path(path_type=Path), default=None,
              help="Write an MP4 per episode here.")
@click.option("--light-scale", type=float, default=1.0, show_default=True)
@click.option("--pull", type=click.Choice(["straight", "arc"]), default="arc", show_default=True)
def run(hands, solver, split, workers, out, cabinets_dir, limit, seed, video_dir, light_scale, pull):
    """Run episodes (resumable: episodes already in --out are skipped)."""
    from opend_mj.evaluation import make_jobs, run_jobs

    jobs = make_jobs(cabinets_dir, hands, solver, split=split, seed=seed, light_scale=light_scale, pull=pull,
                     limit=limit, video_dir=video_dir)
    counts = run_jobs(jobs, out, workers=workers)
    click.echo(f"{counts['ran']} episodes run, {counts['skipped']} already done, {counts['errors']} errors, "
               f"{counts['success']} successes -> {out}")


@click.command("score")
@click.argument("results", nargs=-1, required=True, type=click.Path(exists=True, path_type=Path))
@click.option("--csv", "csv_path", type=click.Path(path_type=Path), default=None)
@click.option("--plot", "plot_path", type=click.Path(path_type=Path), default=None)
def score(results, csv_path, plot_path):
    """The paper's tables from one or more results files (Markdown to stdout)."""
    from opend_mj.scoring import load_records, plot_success, report_markdown, write_csv

    records = load_records(results)
    click.echo(report_markdown(records))
    if csv_path:
        write_csv(records, csv_path)
    if plot_path:
        plot_success(records, plot_path)


@click.command("search-grasp")
@click.option("--hand", required=True)
@click.option("--cabinets", "cabinets_dir", type=click.Path(path_type=Path), default=Path("cabinets"),
              show_default=True)
@click.option("--n-cabinets", type=int, default=3, show_default=True)
@click.option("--scales", default="0.8,1.0,1.15", show_default=True)
@click.option("--depths", default="-0.01,0.0,0.008", show_default=True)
@click.option("--workers", type=int, default=1, show_default=True)
@click.option("--save/--no-save", default=True, show_default=True)
def search_grasp(hand, cabinets_dir, n_cabinets, scales, depths, workers, save):
    """Search finger closing and grasp depth on the first training cabinets; save hands/<hand>/grasp.json."""
    from opend_mj.planner import search_grasp as _search

    profile = _search(hand, cabinets_dir, n_cabinets=n_cabinets,
                      scales=[float(x) for x in scales.split(",")],
                      depths=[float(x) for x in depths.split(",")], workers=workers)
    click.echo(f"chosen: close_scale={profile.close_scale} grasp_depth={profile.grasp_depth}")
    if save:
        click.echo(f"saved {profile.save()}")
