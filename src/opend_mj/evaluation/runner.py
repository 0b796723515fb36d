"""The episode runner: one episode (or a group sharing a scene) from job to record (`opend run`).

One episode = (cabinet, target joint, hand, solver, seed, light scale, pull strategy). The runner
builds the task, renders the one front RGB-D image, runs the planner and records a JSON line.
Ground truth is used here only to label results (failure stage, success); the planner never sees it
(except through the ``oracle`` solver, whose whole point is to hand it the true box).

Reliability: an episode never raises. An episode that runs past its wall-clock limit
(``episode_timeout``, `evaluation.deadline`) gives an error record of kind ``timeout``. A task that raises (e.g. a non-finite action: ``ValueError: action has non-finite values``)
gives an error record; an agent in its own process that fails (`agent_process.AgentFailure`) gives
one of its kind: ``exception`` (it raised), ``agent_memory`` (past ``--agent-memory``),
``agent_died`` (its process ended), ``protocol`` (a malformed message); a MuJoCo instability (BADQACC/BADQPOS/BADQVEL, or NaN state) ends the episode
as a failure with ``failed_stage = "physics"`` and the warnings in ``physics_warnings``. Error
records count as done on resume (delete their lines to retry them).
"""

from __future__ import annotations

import os
import time
import traceback
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402

from opend_mj.evaluation.deadline import EpisodeTimeout, episode_deadline  # noqa: E402
from opend_mj.evaluation.episode import EpisodeJob, record_fields, scene_seed  # noqa: E402
from opend_mj.evaluation.grading import failure_stage  # noqa: E402
from opend_mj.evaluation.probes import HandReach, PenetrationProbe, VideoRecorder  # noqa: E402


def run_episode(job: EpisodeJob, env=None, episode=None, timeout: float | None = None) -> dict:
    """Run one episode; returns its record (never raises: errors become an ``error`` record).

    ``episode(job, env) -> record``: who acts (default: the planner; `evaluation.agents` passes an
    agent's episode). ``timeout``: its wall-clock limit in seconds (None: none)."""
    t0 = time.perf_counter()
    try:
        with episode_deadline(timeout):
            record = (episode or _run_episode)(job, env)
    except (Exception, EpisodeTimeout) as exc:  # noqa: BLE001 (an episode's failure must not stop the run)
        record = error_record(job, exc)
    out = {**record_fields(job), **record}
    out["wall_seconds"] = round(time.perf_counter() - t0, 3)
    return out


def run_episode_group(jobs: tuple[EpisodeJob, ...] | list[EpisodeJob], episode=None,
                      timeout: float | None = None, prepare=None) -> list[dict]:
    """Run episodes that share one `scene_key` on one scene, built once (the unit of work of a run).

    Building a scene (room, cabinet, hand, compile) costs about as much as simulating an episode;
    the episodes of one cabinet's targets differ only in the target and the instruction, and each
    starts from a full reset, so their records are the same as with a scene each. ``episode`` and
    ``timeout`` (each episode's wall-clock limit): as in `run_episode`. ``prepare(job)``, where given,
    runs before each episode outside its wall-clock limit, as the scene's build does (starting an
    agent's process); what it raises is left for the episode to meet and record.
    """
    records = []
    env = None
    for job in jobs:
        if prepare is not None:
            try:
                prepare(job)
            except Exception:  # noqa: BLE001 (raised again inside the episode, and recorded there)
                pass
        if env is None:
            t0 = time.perf_counter()
            try:
                env = make_episode_env(job)
            except Exception as exc:  # noqa: BLE001 (reported per episode; nothing else can run here)
                records.append({**error_record(job, exc), "wall_seconds": round(time.perf_counter() - t0, 3)})
                continue
            build_s = time.perf_counter() - t0
            rec = run_episode(job, env, episode, timeout)
            rec["wall_seconds"] = round(rec["wall_seconds"] + build_s, 3)
        else:
            rec = run_episode(job, env, episode, timeout)
        records.append(rec)
        if rec.get("failed_stage") == "physics" or "error" in rec:
            env = None  # a diverged or failed episode: the next one gets a fresh scene
    return records


def error_reason(exc: BaseException | str) -> str:
    """One line saying what went wrong (the exception type and message; a file is named in it)."""
    if isinstance(exc, str):  # a traceback's text: its last non-empty line
        lines = [ln for ln in exc.strip().splitlines() if ln.strip()]
        return lines[-1].strip() if lines else "unknown error"
    if isinstance(getattr(exc, "error_kind", None), str) and str(exc):  # an agent's failure says it in full
        return str(exc).splitlines()[0]
    return f"{type(exc).__name__}: {exc}".splitlines()[0] if str(exc) else type(exc).__name__


def error_record(job: EpisodeJob, exc: BaseException | str) -> dict:
    """The record of an episode that could not run: ``error`` (traceback) and ``error_reason`` (one line)."""
    if isinstance(exc, str):
        tb = exc
    elif getattr(exc, "remote_traceback", None):  # an agent's error, with its own process's traceback
        tb = exc.remote_traceback
    else:
        tb = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
        if not tb.startswith("Traceback"):
            tb = "Traceback (most recent call last):\n" + tb
    return {**record_fields(job), "success": False, "error": tb, "error_reason": error_reason(exc),
            "error_kind": _error_kind(exc)}


def _error_kind(exc) -> str:
    from opend_mj.sim.cabinet import CabinetError

    if isinstance(exc, CabinetError) or (isinstance(exc, str) and "CabinetError" in exc):
        return "cabinet"
    if isinstance(exc, EpisodeTimeout):
        return "timeout"
    if isinstance(getattr(exc, "error_kind", None), str):  # `agent_process.AgentFailure`: its own kind
        return exc.error_kind
    if isinstance(exc, str) and "BrokenProcessPool" in exc:
        return "worker_died"
    if isinstance(exc, ValueError) and "action" in str(exc):
        return "action"
    return "exception"


class PhysicsDiverged(RuntimeError):
    """MuJoCo reported an instability (or the state went NaN): the episode is over."""


class _StopAtLast:
    """The environment as the planner sees it, except that a LAST time step ends the episode.

    ``OpenDEnvironment`` ends an episode on a MuJoCo instability warning; composer would *reset*
    the episode on the next ``step``, so the planner must not step again.
    """

    def __init__(self, env):
        self._env = env

    def __getattr__(self, name):
        return getattr(self._env, name)

    def step(self, action):
        ts = self._env.step(action)
        if ts.last():
            warnings = self._env.task.physics_warnings
            raise PhysicsDiverged(f"physics instability: {warnings}" if warnings else "episode ended (time limit)")
        return ts


def instruction_for(job: EpisodeJob) -> str | None:
    """The job's own phrasing, its paraphrased instruction, or None for the task's: the target's own
    (Algorithm 1), or as the perturbation's instruction axis rewords it (`sim.perturb`, applied by the
    task, which draws it with the rest of the scene's perturbation)."""
    if job.phrasing is not None:
        return job.phrasing
    from opend_mj.sim.perturb import perturb_items

    if not job.paraphrase or "instruction" in perturb_items(job.perturb):
        return None
    from opend_mj.language import Description, paraphrase
    from opend_mj.sim.cabinet import load_cabinet_info

    target = next(t for t in load_cabinet_info(Path(job.cabinet_dir))["targets"] if t["joint"] == job.joint)
    return paraphrase(Description(target["vertical"], target["horizontal"], target["type"]), job.paraphrase)


def make_episode_env(job: EpisodeJob):
    from opend_mj.sim.task import EpisodeSpec, TaskConfig, make_environment

    spec_ep = EpisodeSpec(cabinet_dir=Path(job.cabinet_dir), target_joint=job.joint, hand=job.hand,
                          seed=scene_seed(job), room=job.room, instruction=instruction_for(job))
    config = TaskConfig(enable_rgbd=False, light_scale=job.light_scale, time_limit=1e6, perturb=job.perturb)
    if job.physics_timestep is not None:
        config = replace(config, physics_timestep=float(job.physics_timestep))
    return make_environment(spec_ep, config, observations=False)  # every caller reads MjData itself


def _run_episode(job: EpisodeJob, env=None) -> dict:
    """One episode. ``env``: a scene built for a job with the same `scene_key` (else a new one)."""
    from opend_mj.sim.camera import RGBDCamera

    if env is None:
        env = make_episode_env(job)
    else:
        env.task.set_target(job.joint, instruction_for(job))
    env.reset()
    size = env.task.config.image_size
    # the episode's camera: the first observation, and the planner's looks mid-pull
    with RGBDCamera(env.physics, "front", size, size) as cam:
        return _run_episode_with_camera(job, env, cam)


def _run_episode_with_camera(job: EpisodeJob, env, cam) -> dict:
    from opend_mj.policy.factory import build_planner
    from opend_mj.policy.planner import Observation, Robot

    task = env.task
    config = task.config
    physics = env.physics
    target = task.target
    instruction = task.instruction

    rgb, depth = cam.render()  # the one observation
    depth = task.sense_depth(rgb, depth, frames=config.depth_frames)  # the scene is still: fused frames
    view = task.camera_view(physics)
    gt_box = task.handle_boxes(physics)[target.joint]

    # ground-truth probes for labelling only
    probes: dict = {}
    reach = HandReach(task, physics)

    def true_handle_box():
        corners = task.handle_corners(physics)
        return corners.min(axis=0), corners.max(axis=0)

    def on_stage(name, info):
        if name == "grasp":
            lo, hi = true_handle_box()
            site = physics.bind(task.hand.grasp_site).xpos.copy()
            outside = np.maximum(0.0, np.maximum(lo - site, site - hi))
            probes["site_to_handle"] = float(np.linalg.norm(outside))
            probes["hand_to_handle"] = reach()
            probes["t_grasp"] = float(physics.data.time)
        elif name == "pull":
            probes["hand_to_handle"] = min(probes.get("hand_to_handle", reach.cap), reach())
            probes["q_pull_start"] = task.outcome(physics).range_ratio
            probes["t_pull"] = float(physics.data.time)

    video = VideoRecorder(job, physics, config, task.cabinet.bounds) if job.video_dir else None
    penetration = PenetrationProbe(physics.data.ptr)

    def on_step():
        penetration()
        if video:
            video.capture()

    # a look while the hand moves is one frame (fusing frames would blur a moving front)
    robot = Robot(_StopAtLast(env), on_step=on_step, look=lambda: task.sense_depth(*cam.render()))
    planner = build_planner(job.solver, task.hand.spec.name, pull=job.pull, use_grasp_file=job.use_grasp_file,
                            overrides=job.planner_overrides,
                            ground_truth=lambda: task.handle_boxes(physics)[target.joint], on_stage=on_stage)
    warnings = task.physics_warnings  # the list of this episode (a reset would make a new one)
    try:
        plan = planner.run(robot, Observation(rgb=rgb, depth=depth, instruction=instruction, camera_view=view))
    except PhysicsDiverged as exc:
        return _diverged_record(job, task, physics, instruction, gt_box, warnings, str(exc))
    finally:
        if video:
            video.close()
    outcome = task.outcome(physics)

    # failure stage (ground truth, for the tables)
    failed = failure_stage(outcome.success, outcome.range_ratio,
                           min(probes.get("site_to_handle", 1.0), probes.get("hand_to_handle", 1.0)),
                           box=plan.box["box"] if plan.box else None, gt_box=gt_box)
    if plan.failed_stage == "language" and not outcome.success:
        failed = "language"  # the instruction was refused: the robot did not act
    return {
        **language_fields(instruction),
        "cabinet_dir": job.cabinet_dir,
        "target_type": target.kind,
        "instruction": instruction,
        "room": task.episode.room_index(),
        "success": bool(outcome.success),
        "open_ratio": float(outcome.open_ratio),
        "range_ratio": float(outcome.range_ratio),
        "joint_value": float(outcome.joint_value),
        "joint_range": [target.lower, target.upper],
        "closed_value": target.closed,
        "others_moved": list(outcome.others_moved),
        "failed_stage": failed,
        "planner_failed_stage": plan.failed_stage,
        "handle_kind": plan.handle["kind"] if plan.handle else None,
        "handle_orientation": plan.handle["orientation"] if plan.handle else None,
        "box": plan.box["box"] if plan.box else None,
        "gt_box": [round(x, 2) for x in gt_box] if gt_box else None,
        "site_to_handle": round(probes.get("site_to_handle", float("nan")), 4),
        "hand_to_handle": round(probes.get("hand_to_handle", float("nan")), 4),
        "pulled": round(plan.pulled, 4),
        "regrasps": int(plan.regrasps),
        "grasp_style": plan.grasp_style or None,
        "handle_shape": plan.shape,
        "pushed": bool(plan.pushed),
        "wrong_kind": list(plan.wrong_kind),
        "kind_seen": [[e["kind_seen"], e["turn_deg"], e["tilt_deg"]] for e in plan.events if "kind_seen" in e],
        "front_seen": [e["front_seen"] for e in plan.events if "front_seen" in e],
        "verify": [e["verify"] for e in plan.events if "verify" in e],
        "turned_deg": round(plan.turned_deg, 2),
        "pull_end": [e["pull_end"] for e in plan.events if "pull_end" in e],  # why each pull ended
        "sim_seconds": round(float(physics.data.time), 3),
        "max_penetration_mm": round(penetration.deepest * 1000, 2),
        "physics_warnings": list(warnings),
        "video": str(video.path) if video else None,
        # boxes given up because the hand closed on nothing there (absent where none was)
        **({"no_handle": list(plan.no_handle)} if plan.no_handle else {}),
    }


def language_fields(instruction: str) -> dict:
    """How the parser read the instruction: ``understood_as`` (the canonical template, None when
    refused) and, when refused, ``language_refusal`` (what is missing or ambiguous)."""
    from opend_mj.language import InstructionNotUnderstood, canonical_instruction

    try:
        return {"understood_as": canonical_instruction(instruction)}
    except InstructionNotUnderstood as exc:
        return {"understood_as": None, "language_refusal": exc.reason}


def _diverged_record(job, task, physics, instruction, gt_box, warnings, reason) -> dict:
    """A failed episode: the physics went unstable (MuJoCo warnings in ``physics_warnings``)."""
    try:
        outcome = task.outcome(physics)
        values = {"open_ratio": float(outcome.open_ratio), "range_ratio": float(outcome.range_ratio),
                  "joint_value": float(outcome.joint_value), "others_moved": list(outcome.others_moved)}
        values = {k: (v if not isinstance(v, float) or np.isfinite(v) else None) for k, v in values.items()}
    except Exception:  # noqa: BLE001 (a NaN state)
        values = {"open_ratio": None, "range_ratio": None, "joint_value": None, "others_moved": []}
    return {
        "cabinet_dir": job.cabinet_dir,
        "target_type": task.target.kind,
        "instruction": instruction,
        "room": task.episode.room_index(),
        "success": False,
        **values,
        "joint_range": [task.target.lower, task.target.upper],
        "closed_value": task.target.closed,
        "failed_stage": "physics",
        "planner_failed_stage": None,
        "gt_box": [round(x, 2) for x in gt_box] if gt_box else None,
        "sim_seconds": round(float(physics.data.time), 3),
        "physics_warnings": list(warnings),
        "failure_reason": reason,
        "video": None,
    }
