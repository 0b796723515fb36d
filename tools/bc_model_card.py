"""Write a shipped behaviour-cloning policy's model card, checkpoints/bc_<hand>.md, from its files.

    python tools/bc_model_card.py --hand shadow          # every hand: --hand repeated, or none

Everything on the card is read from what `make train-bc HAND=<hand>` and the real-cabinet run left:
the checkpoint's summary (``checkpoints/bc_<hand>.json``: model, data, the DAgger rounds, the final
policy), the kept rounds (``checkpoints/bc_rounds/<hand>/round_<i>.json``: validation figures and
wall seconds per stage), the generated test-split record (``results/bc/<hand>_shipped_test.jsonl``)
and the real-cabinet counts (``results/real/bc_<hand>_all.json``), so the card and the figures
cannot drift apart.
"""

from __future__ import annotations

import argparse
import json
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _rate(k: int, n: int) -> str:
    return f"{100.0 * k / max(1, n):.1f} % ({k}/{n})"


def _test_cells(path: Path) -> dict | None:
    """`report.summarize`'s cells (overall, drawer, door) of the shipped policy's generated test record."""
    from opend_mj.evaluation.report import summarize
    from opend_mj.evaluation.scoring import load_records

    if not path.is_file():
        return None
    hands = next(iter(summarize(load_records([path])).values()))
    return next(iter(hands.values()))


def _cells_text(cell: dict) -> str:
    """Success overall (bold), per kind, and at >= 75 % of the joint range, of `report.summarize`'s cells."""
    o, dr, do = cell["overall"], cell.get("drawer", {}), cell.get("door", {})
    return (f"**{_rate(o['open20'], o['episodes'])}**, drawers {dr.get('open20')}/{dr.get('episodes')}, doors "
            f"{do.get('open20')}/{do.get('episodes')}; {o['range75']}/{o['episodes']} at >= 75 % of the joint range")


def _seconds(rounds: list[dict], stage: str) -> str:
    values = [r["seconds"][stage] for r in rounds if r.get("seconds", {}).get(stage, 0) > 1.0]
    if not values:
        return "-"
    lo, hi = min(values), max(values)
    return f"{lo:.0f} s" if round(lo) == round(hi) else f"{lo:.0f}-{hi:.0f} s"


def make_defaults(root: Path = ROOT) -> dict[str, str]:
    """The Makefile's ``NAME ?= VALUE`` defaults (what a bare `make train-bc` uses)."""
    out = {}
    for line in (root / "Makefile").read_text().splitlines():
        name, sep, value = line.partition("?=")
        if sep and name.strip().isidentifier():
            out[name.strip()] = value.strip()
    return out


def make_variants(root: Path = ROOT) -> dict[str, str]:
    """The Makefile's ``VARIANT_<name> = SETTINGS`` lines: the settings of each DAgger run variant."""
    out = {}
    for line in (root / "Makefile").read_text().splitlines():
        name, sep, value = line.partition("=")
        if sep and name.strip().startswith("VARIANT_") and not name.endswith(("?", ":", "+")):
            out[name.strip()[len("VARIANT_"):]] = value.strip()
    return out


def ensemble_row(hand: str, bundle: dict, root: Path = ROOT) -> str:
    """The card's text on a shipped bundle of several DAgger runs' final policies: each member's run,
    its make settings and its rounds' validation figures."""
    from opend_mj.apps.dagger import kept_rounds

    variants = make_variants(root)
    parts = []
    for i, source in enumerate(bundle["sources"]):
        folder = Path(source).parent
        variant = folder.name[len(hand) + 1:] if folder.name.startswith(f"{hand}-") else ""
        rounds = kept_rounds(root / folder)
        how = "this card's run" if not variant else f"`VARIANT={variant} {variants.get(variant, '')}`".replace(" `", "`")
        parts.append(f"{i}: `{source}` ({how}; validation " + " / ".join(f"{r['val_success']}" for r in rounds) + " %)")
    return (f"{bundle['members']} final policies of DAgger runs on other data, their action chunks averaged every "
            f"step (`opend bundle-policy`; `ENSEMBLE_{hand}` in the Makefile): " + "; ".join(parts))


def recipe_command(hand: str, rounds: list[dict], extra: list, root: Path = ROOT, members: int = 1) -> str:
    """The `make train-bc` command that makes a policy of ``rounds`` (kept round figures), extra
    training cabinets ``extra`` and ``members`` final members: the Makefile's defaults, overridden
    where the policy was made otherwise."""
    defaults = make_defaults(root)
    later = rounds[1:] or [{}]
    made = {"REVISIT": str(later[0].get("revisit", 0)), "HOLD": "1" if later[0].get("hold") else "0"}
    args = [f"{k}={v}" for k, v in made.items() if defaults.get(k, v) != v]
    if members > 1:  # the Makefile has no variable of its own for it: passed through BC_ARGS
        args.append(f'BC_ARGS="--final-members {members}"')
    if bool(extra) != (defaults.get("LONG_DOORS", "0") != "0"):
        args.append("LONG_DOORS=0" if not extra else "LONG_DOORS=N")
    return " ".join([f"make train-bc HAND={hand}", *args])


def model_card(hand: str, root: Path = ROOT) -> str:
    """The card's markdown for ``hand``."""
    summary = json.loads((root / "checkpoints" / f"bc_{hand}.json").read_text())
    ckpt = root / "checkpoints" / f"bc_{hand}.pt"
    config, dagger = summary["config"], summary.get("dagger") or {}
    from opend_mj.apps.dagger import kept_rounds

    kept = kept_rounds(root / "checkpoints" / "bc_rounds" / hand)
    final = dagger.get("final", {})
    # the rounds of the run that made this policy; rounds kept since (a longer run not shipped) apart
    made = int(final.get("rounds", dagger.get("config", {}).get("rounds", len(kept))))
    rounds, later = [r for r in kept if r["round"] <= made], [r for r in kept if r["round"] > made]
    watch = int(config.get("watch") or 0)
    from opend_mj.evaluation.report import hand_title

    members = final.get("members") or [{}]
    # a bundle of several DAgger runs' final policies (`ENSEMBLE_<hand>`); one run's seed members
    # (`--final-members`) are told on the final policy's row instead
    bundle = summary.get("bundle") if len(members) == 1 else None
    title = f"# Model card: `bc_{hand}.pt` (behaviour cloning with DAgger, {hand_title(hand)}" + (
        f", an ensemble of {bundle['members']} runs" if bundle else "") + (
        ", watching the front)" if watch else ")")
    rows = [
        ("model", f"ACT-style transformer over action chunks ({config['d_model']} wide, {config['chunk']}-action "
                  f"chunks{', grasp-style token' if config.get('modes') else ''}), {summary['parameters']:,} "
                  f"parameters, float16 weights, {ckpt.stat().st_size / 1e6:.2f} MB"),
        ("inputs", "the handle the shipped Faster R-CNN finds in the first RGB-D image (back-projected with depth), "
                   "the instruction's one-hot code, the hand's own state and touch"
                   + (f", and the instructed front watched in a new depth image every {watch} control steps "
                      f"(`--watch {watch}`)" if watch else "") + "; never ground truth"),
    ]
    extra = dagger.get("config", {}).get("extra_cabinets") or []
    if rounds and final:
        more = (f" and on every target of the extra training cabinets in {', '.join(f'`{d}`' for d in extra)} "
                "(long doors: `opend generate --family long_door`, `make train-bc LONG_DOORS=N`), which every "
                "DAgger round also rolls out" if extra else "")
        rows.append(("demonstrations", f"generated cabinets only, train split (`opend demos --hand {hand} --split "
                                       f"train --seeds 2 --solver oracle`){more}: {final.get('demos')} successful, "
                                       f"{rounds[0]['demos']} of them on the cabinets not kept for validation"))
    if rounds:
        val = dagger.get("validation", {})
        figures = ", ".join(f"round {r['round']} **{r['val_success']} %**" for r in rounds)
        kinds = " / ".join(f"{r.get('val_door', '-')}" for r in rounds)
        drawers = " / ".join(f"{r.get('val_drawer', '-')}" for r in rounds)
        extras = []
        for r in rounds[1:]:
            made = [f"beta {r['beta']:g}", f"seed {r['rollout_seed']}"]
            if r.get("revisit"):
                made.append(f"{r['revisited']} revisits")
            if r.get("hold"):
                made.append("hold after the plan")
            extras.append(f"{r['round']}: " + ", ".join(made))
        rows.append(("DAgger", f"{len(rounds) - 1} rounds after round 0, each from the previous round's weights "
                               f"({'; '.join(extras)}). Validation ({val.get('cabinets', '?')} training cabinets kept "
                               f"apart, {rounds[0]['val_episodes']} targets, episode seed {val.get('seed', 100)}): "
                               f"{figures} (doors {kinds} %, drawers {drawers} %; `docs/dagger.png`)"))
        if later:
            rows.append(("later rounds, not in this policy", "kept by a longer run whose final policy was not "
                         "shipped: " + ", ".join(f"round {r['round']} {r['val_success']} % (doors {r.get('val_door')} "
                                                 f"%)" for r in later)))
        cost = (f"round 0 training {_seconds(rounds[:1], 'training')}; later rounds: rollouts "
                f"{_seconds(rounds[1:], 'rollouts')}, training {_seconds(rounds[1:], 'training')}, validation "
                f"{_seconds(rounds, 'validation')}")
        rows.append(("cost on 2 cores", cost + " (wall seconds of the run that made each round; a resumed "
                                               "round counts only what that run did)"))
    if final:
        seeds = (f"{len(members)} members of seeds {', '.join(str(m['seed']) for m in members)} bundled as one seed "
                 f"ensemble" if len(members) > 1 else f"seed {config['seed']}")
        rows.append(("final policy", f"every training cabinet ({final.get('demos')} demonstrations + "
                                     f"{final.get('rollouts')} labelled rollouts, {summary['samples']:,} samples), "
                                     f"from round {final.get('from_round')}'s weights, {final.get('steps')} steps "
                                     f"(batch {config['batch_size']}, AdamW lr {config['lr']:g}, {seeds}, "
                                     f"torch threads {summary.get('threads', 1)}): "
                                     f"{summary['seconds']:.0f} s" + (" per member" if len(members) > 1 else "")))
    if bundle:
        rows.append(("ensemble", ensemble_row(hand, bundle, root)))
    rows.append(("stop", f"{(bundle or summary)['stop_time']:.1f} s of simulated time (95th percentile of the training "
                         "episodes' lengths" + (", the members' mean)" if bundle else ")")))
    test = _test_cells(root / "results" / "bc" / f"{hand}_shipped_test.jsonl")
    if test:
        rows.append(("test, generated cabinets", f"`opend run --policy bc --hand {hand} --split test --out "
                     f"results/bc/{hand}_shipped_test.jsonl`: {_cells_text(test)}"))
    real_path = root / "results" / "real" / f"bc_{hand}_all.json"
    if real_path.is_file():
        real = json.loads(real_path.read_text())
        cell = next(iter(real["scores"].values()))[hand]
        rows.append(("real cabinets", f"all {real['targets']} targets of the {real['cabinets']} real OpenD training "
                     f"cabinets (`build/opend-train`, seed 0, Faster R-CNN; the {real.get('excluded_targets', 0)} "
                     f"targets the build excludes counted as failures): `opend run --policy bc --hand {hand} --split "
                     f"all --cabinets build/opend-train --workers 2 --out build/real-results/bc_{hand}_real.jsonl`: "
                     f"{_cells_text(cell)}. Records not committed; counts in `results/real/bc_{hand}_all.json`"))
    intro = textwrap.fill(
             f"`opend run --policy bc --hand {hand}` loads this checkpoint (`opend_mj.policy.bc_agent.BCAgent`). "
             + ("It is one model" if len(members) == 1 and not bundle else
                f"It averages {bundle['members']} models" if bundle else f"It is a seed ensemble of {len(members)} models")
             + f", made by the recipe every hand shares: `{recipe_command(hand, rounds, extra, root, len(members))}` "
             + "(docs/demonstrations.md, \"The planner as an interactive expert, and DAgger\"), trained on generated "
             f"cabinets only. `bc_{hand}.json` holds its training summary, loss history and DAgger rounds; each "
             f"round's policy and figures are kept in `bc_rounds/{hand}/`, from which a later run continues. "
             f"Written by `python tools/bc_model_card.py --hand {hand}` from those files and the results.", 110)
    lines = [title, "", intro, "", "| | |", "|---|---|"]
    lines += [f"| {k} | {v} |" for k, v in rows]
    lines += ["", textwrap.fill("Limits: validation on a few dozen targets (one episode moves a rate by about 2 "
                                "points); one seed; real cabinets are never trained on. Where failures end, per "
                                "kind: docs/results.md.", 110)]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hand", dest="hands", action="append", help="hand (repeatable) [every shipped one]")
    args = parser.parse_args(argv)
    hands = args.hands or sorted(p.stem[3:] for p in (ROOT / "checkpoints").glob("bc_*.pt"))
    for hand in hands:
        out = ROOT / "checkpoints" / f"bc_{hand}.md"
        out.write_text(model_card(hand))
        print(f"{hand} -> {out.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
