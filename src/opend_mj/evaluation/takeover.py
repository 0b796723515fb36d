"""Episodes taken over mid-way by the planner as an interactive expert (`opend expert-check`).

A ``lead`` acts from the episode's start until ``switch`` seconds of simulated time; then a fresh
:class:`~opend_mj.policy.expert.PlannerExpert` acts from the state the lead left, until it has
nothing more to do or the protocol's time limit. The lead is the planner itself (``"planner"``:
a first expert, so the switch lands in the middle of the planner's own approach, grasp or pull)
or any agent (`opend_mj.policy.agents`: the BC policy, ``"bc"``). What the fresh expert opens
from those states is what DAgger's labels are worth (`opend train-policy --dagger`).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from opend_mj.evaluation.agents import PROTOCOL_TIME_LIMIT, episode_seed
from opend_mj.evaluation.episode import EpisodeJob
from opend_mj.evaluation.runner import instruction_for, make_episode_env
from opend_mj.sim.hands import list_hands

#: Leads of `opend expert-check` that are not agents: the planner itself.
PLANNER_LEAD = "planner"


def agent_info(job: EpisodeJob, env, reader):
    """What an agent is told at the start of an episode of ``job`` on ``env`` (absolute control)."""
    from opend_mj.policy.agents import EpisodeInfo

    spec = env.action_spec()
    return EpisodeInfo(instruction=env.task.instruction, hand=job.hand, hand_spec=env.task.hand.spec,
                       camera_view=reader.camera_view(), control_dt=env.task.control_timestep,
                       time_limit=PROTOCOL_TIME_LIMIT, action_names=tuple(spec.name.split("\t")),
                       action_low=spec.minimum, action_high=spec.maximum, seed=episode_seed(job))


def takeover_episode(job: EpisodeJob, lead, switch: float, env=None, expert_config=None) -> dict:
    """One episode of ``job``: ``lead`` (:data:`PLANNER_LEAD` or an agent object) acts for ``switch``
    seconds, then a fresh expert acts to the end. Returns the record: success and open ratio at the
    end, the open ratio (range share) at the switch, the expert's restarts and unlabelled steps."""
    from opend_mj.policy.expert import ExpertConfig, PlannerExpert
    from opend_mj.policy.planner import Observation
    from opend_mj.sim.camera import RGBDCamera
    from opend_mj.sim.envs import SceneReader

    config = expert_config or ExpertConfig()
    env = env if env is not None else make_episode_env(job)
    env.task.set_target(job.joint, instruction_for(job))
    env.reset()
    task, physics = env.task, env.physics
    size = task.config.image_size
    max_steps = int(round(PROTOCOL_TIME_LIMIT / task.control_timestep))
    reader = SceneReader(env, size)
    lead_expert = expert = None
    steps, diverged = 0, False
    at_switch = None
    lead_stage = ""  # the planner lead's stage at the switch
    try:
        with RGBDCamera(physics, "front", size, size) as cam:
            rgb, depth = cam.render()
            first = Observation(rgb=rgb, depth=task.sense_depth(rgb, depth, frames=task.config.depth_frames),
                                instruction=task.instruction, camera_view=task.camera_view(physics))
            if lead == PLANNER_LEAD:
                lead_expert = PlannerExpert(env, first, cam, config, hand=job.hand)
                act = lead_expert.action
            else:
                lead.reset(agent_info(job, env, reader))
                camera = reader.camera_arrays()  # the camera does not move within an episode
                obs0 = {**reader.proprio(), "instruction": task.instruction, **camera, "rgb": rgb, "depth": first.depth}

                def act(obs=[obs0]):  # noqa: B006 (the first observation, then the hand's own state)
                    action = lead.act(obs[0])
                    obs[0] = {**reader.proprio(), "instruction": task.instruction, **camera}
                    return action
            while steps < max_steps:
                if at_switch is None and physics.data.time >= switch - 1e-9:
                    at_switch = task.outcome(physics)
                    if lead_expert is not None:
                        lead_stage = lead_expert.stage
                        lead_expert.close()
                    expert = PlannerExpert(env, first, cam, config, hand=job.hand)
                    act = expert.action
                action = act()
                if action is None:
                    if expert is not None:
                        break
                    at_switch = task.outcome(physics)  # the lead stopped early: the expert takes over now
                    expert = PlannerExpert(env, first, cam, config, hand=job.hand)
                    act = expert.action
                    continue
                ts = env.step(np.asarray(action, float))
                steps += 1
                if ts.last():
                    diverged = True
                    break
    finally:
        for e in (lead_expert, expert):
            if e is not None:
                e.close()
        reader.close()
        if lead != PLANNER_LEAD and callable(getattr(lead, "close", None)):
            lead.close()
    outcome = task.outcome(physics)
    at = at_switch or outcome
    return {
        "cabinet": job.cabinet, "joint": job.joint, "hand": job.hand, "seed": job.seed, "split": job.split,
        "target_type": task.target.kind, "instruction": task.instruction,
        "lead": lead if lead == PLANNER_LEAD else str(getattr(lead, "name", type(lead).__name__)),
        "switch": float(switch), "success": bool(outcome.success) and not diverged,
        "open_ratio": float(outcome.open_ratio), "range_ratio": float(outcome.range_ratio),
        "switch_open_ratio": round(float(at.open_ratio), 4), "switch_range_ratio": round(float(at.range_ratio), 4),
        "lead_stage": lead_stage,
        "taken_over": None if expert is None else expert.taken_over,
        "restarts": 0 if expert is None else expert.restarts,
        "unlabelled": 0 if expert is None else expert.unlabelled,
        "why": None if expert is None else expert.why,
        "steps": steps, "diverged": diverged, "sim_seconds": round(float(physics.data.time), 3),
    }


def takeover_key(rec: dict) -> tuple:
    """What identifies a takeover episode in a results file."""
    return (rec["cabinet"], rec["joint"], rec["hand"], int(rec["seed"]), rec["lead_spec"], float(rec["switch"]))


def _takeover_group(args) -> list[dict]:
    """Worker: the takeovers of one scene (one cabinet and hand), the scene built once."""
    from opend_mj.evaluation.agents import load_agent
    from opend_mj.evaluation.runner import error_reason

    jobs, lead_spec, lead_args, switches = args
    out, env = [], None
    lead = PLANNER_LEAD if lead_spec == PLANNER_LEAD else load_agent(lead_spec, lead_args)
    for job in jobs:
        for switch in switches:
            key = {"cabinet": job.cabinet, "joint": job.joint, "hand": job.hand, "seed": job.seed,
                   "lead_spec": lead_spec, "switch": float(switch)}
            try:
                env = env or make_episode_env(job)
                out.append({**takeover_episode(job, lead, switch, env), **key})
            except Exception as exc:  # noqa: BLE001 (one bad episode must not stop the check)
                env = None
                out.append({**key, "success": False, "error": error_reason(exc)})
    return out


def check_expert(jobs: list[EpisodeJob], out: Path, lead: str = PLANNER_LEAD, lead_args: tuple = (),
                 switches=(2.0, 4.0, 6.0), workers: int = 1, progress: bool = True) -> dict:
    """`opend expert-check`: every job taken over at every switch time (s) from ``lead``
    (:data:`PLANNER_LEAD`, or an agent spec of `opend run --policy`), one JSON line per takeover in
    ``out``; resumable (takeovers already in ``out`` are skipped). Returns counts."""
    from tqdm import tqdm

    from opend_mj.backends import make_executor
    from opend_mj.evaluation.jobs import group_jobs
    from opend_mj.evaluation.runner import error_reason

    out = Path(out)
    done = set()
    if out.exists():
        for line in out.read_text().splitlines():
            try:
                done.add(takeover_key(json.loads(line)))
            except (ValueError, KeyError):
                continue  # a torn last line (a killed check): that takeover runs again
    switches = tuple(float(s) for s in switches)
    todo = [j for j in jobs if any((j.cabinet, j.joint, j.hand, j.seed, lead, s) not in done for s in switches)]
    counts = {"total": len(jobs) * len(switches), "ran": 0, "success": 0, "errors": 0}
    if not todo:
        return counts
    groups = [(g, lead, tuple(lead_args), switches) for g in group_jobs(todo)]
    bar = tqdm(total=len(todo) * len(switches), desc="takeovers", unit="ep", disable=not progress)
    out.parent.mkdir(parents=True, exist_ok=True)
    with open(out, "a") as f:
        def take(records):
            for rec in records:
                if takeover_key(rec) in done:
                    continue
                f.write(json.dumps(rec) + "\n")
                counts["ran"] += 1
                counts["success"] += bool(rec.get("success"))
                counts["errors"] += "error" in rec
                bar.update(1)
            f.flush()
            bar.set_postfix(success=f"{counts['success']}/{counts['ran']}")

        with make_executor("local", workers) as executor:
            for (group, *_), records, error in executor.imap_unordered(_takeover_group, groups):
                if error is not None:  # the worker itself failed: every takeover of the group is an error record
                    records = [{"cabinet": j.cabinet, "joint": j.joint, "hand": j.hand, "seed": j.seed,
                                "lead_spec": lead, "switch": s, "success": False, "error": error_reason(error)}
                               for j in group for s in switches]
                take(records)
    bar.close()
    return counts


def summarise_takeovers(records: list[dict]) -> dict:
    """Success per lead and switch time, and over all: {(lead, switch): (successes, episodes)}."""
    table: dict = {}
    for r in records:
        for key in ((r["lead_spec"], float(r["switch"])), (r["lead_spec"], "all")):
            s, n = table.get(key, (0, 0))
            table[key] = (s + bool(r.get("success")), n + 1)
    return table


def takeover_summary(records: list[dict], command: str = "") -> dict:
    """The aggregate `opend report` reads (``--summary``; the only form in which takeovers on real
    cabinets are kept): per lead, hand and switch time, [opened, episodes, opened to >= 75 % of the
    range]; ``cabinets`` and ``targets`` counted over the records."""
    cells: dict = {}
    for r in records:
        for switch in (f"{float(r['switch']):g}", "all"):
            cell = cells.setdefault(r["lead_spec"], {}).setdefault(r["hand"], {}).setdefault(switch, [0, 0, 0])
            cell[0] += bool(r.get("success"))
            cell[1] += 1
            cell[2] += bool(r.get("success")) and (r.get("range_ratio") or 0.0) >= 0.75
    return {"cabinets": len({r["cabinet"] for r in records}),
            "targets": len({(r["cabinet"], r["joint"]) for r in records}), "command": command, "cells": cells}


def load_takeovers(path: Path) -> dict:
    """A takeover summary: a records file (``.jsonl``, summarised) or a summary (``.json``)."""
    path = Path(path)
    if path.suffix == ".jsonl":
        records = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
        return takeover_summary(records, command=f"opend expert-check ... --out {path.as_posix()}")
    return json.loads(path.read_text())


def takeover_markdown(summary: dict, title: str) -> list[str]:
    """A summary as a table: one row per lead and hand, a column per switch time (opened %, n)."""
    hands = list_hands()
    out = [f"### {title}", "", f"Made by: `{summary.get('command', 'opend expert-check')}` "
           f"({summary.get('cabinets')} cabinets, {summary.get('targets')} targets). Cells: opened (> 20 %) / "
           ">= 75 % of the range, in percent.", ""]
    for lead, by_hand in summary["cells"].items():
        switches = sorted({s for h in by_hand.values() for s in h if s != "all"}, key=float) + ["all"]
        out += [f"| lead `{lead}`, hand | " + " | ".join(f"switch {s} s" if s != "all" else "all" for s in switches)
                + " |", "|---" * (len(switches) + 1) + "|"]
        for hand in [h for h in hands if h in by_hand] + [h for h in by_hand if h not in hands]:
            cells = []
            for s in switches:
                ok, n, full = by_hand[hand].get(s, [0, 0, 0])
                cells.append(f"{100.0 * ok / n:.1f} / {100.0 * full / n:.1f} ({n})" if n else "-")
            out.append(f"| {hand} | " + " | ".join(cells) + " |")
        out.append("")
    return out


__all__ = ["PLANNER_LEAD", "agent_info", "check_expert", "load_takeovers", "summarise_takeovers", "takeover_episode", "takeover_key",
           "takeover_markdown", "takeover_summary"]
