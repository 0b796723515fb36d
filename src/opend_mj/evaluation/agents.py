"""`opend run --policy`: any agent (see `opend_mj.policy.agents`) on the benchmark's episodes.

The episodes, scenes, seeds, records, resume and scoring are those of `opend run --solver`: the same
jobs (`evaluation.jobs.make_jobs`), the same scene per cabinet and hand (`runner.make_episode_env`), one
JSON line per episode. What differs is who acts: each control step the agent gets the observation
the protocol allows (`policy.agents`) and returns an action, for at most ``PROTOCOL_TIME_LIMIT``
seconds of simulated time (900 steps at 60 Hz) or until it returns None; then the success checker
reads the final state. Ground truth is read here only to label the record (failure stage, the
closest the grasp site and the hand's gripping surfaces came to the handle).

An agent is named ``module:Class``, ``path/to/file.py:Class``, ``path/to/file.py`` (its class
``Agent``) or by a built-in name (`BUILTIN_POLICIES`: ``bc``, the behaviour-cloning policy);
``--policy-arg key=value`` are passed to the constructor. The agent runs in a process of its own
that holds no simulator (`evaluation.agent_process`: observation in, action out, over a pipe): one
per worker process and spec, reset at every episode, started afresh after an episode it failed
(an error, its memory limit, its death, the wall-clock limit). With ``--agent-in-process`` it runs
in the worker, beside the simulator (for debugging; every record says so).
"""

from __future__ import annotations

import zlib

import numpy as np

from opend_mj.evaluation.agent_loader import BUILTIN_POLICIES, load_agent, parse_policy_args, resolve_policy
from opend_mj.evaluation.agent_process import (
    CONTAINMENT_FIELDS,
    ISOLATION_IN_PROCESS,
    AgentProcess,
    contained_agent,
    discard,
)
from opend_mj.evaluation.episode import EPISODE_FIELDS, EpisodeJob
from opend_mj.evaluation.grading import episode_ending, failure_stage
from opend_mj.evaluation.probes import HandReach, HoldProbe, PenetrationProbe, VideoRecorder
from opend_mj.evaluation.runner import (
    instruction_for,
    run_episode_group,
)
from opend_mj.policy.agents import EpisodeInfo, agent_control, agent_images, agent_name, wants_image

#: The protocol's time limit for an agent (s of simulated time): TaskConfig's default episode length.
PROTOCOL_TIME_LIMIT = 15.0

#: Record fields an agent's own extra fields (``episode_info()``) may not set: who ran, what, how.
RESERVED_FIELDS = frozenset({f.name for f in EPISODE_FIELDS} | set(CONTAINMENT_FIELDS)
                            | {"target_type", "instruction", "wall_seconds", "error", "error_reason", "error_kind"})


def episode_seed(job: EpisodeJob) -> int:
    """A seed for the agent's own randomness, fixed per episode (cabinet, target, seed)."""
    return zlib.crc32(f"{job.cabinet}/{job.joint}/{job.hand}/{job.seed}".encode())


def run_group(jobs, episode_timeout: float | None = None) -> list[dict]:
    """The unit of work of `opend run`: a group of episodes sharing a scene, by agent or planner,
    each within ``episode_timeout`` seconds of wall-clock time (None: no limit)."""
    if jobs and jobs[0].policy:
        return run_agent_group(jobs, episode_timeout)
    return run_episode_group(jobs, timeout=episode_timeout)


def run_agent_group(jobs, episode_timeout: float | None = None) -> list[dict]:
    """Like `runner.run_episode_group` (the same scene sharing and fresh scene after a failure), with
    the agent of the jobs' ``policy`` acting: in an agent process of its own (`evaluation.agent_process`,
    one per worker and spec, kept across episodes), or in this process for ``agent_isolation ==
    "in-process"``."""
    return run_episode_group(jobs, episode=_agent_episode, timeout=episode_timeout, prepare=_start_agent)


def _start_agent(job: EpisodeJob) -> None:
    """The job's agent process, started (or found running) before its episode's wall-clock limit
    starts: a process start costs seconds on a loaded machine and is not the agent's acting time."""
    if job.agent_isolation != ISOLATION_IN_PROCESS:
        contained_agent(job.policy, job.policy_args, job.agent_memory)


def _agent_episode(job: EpisodeJob, env) -> dict:
    env.task.set_target(job.joint, instruction_for(job))
    if job.agent_isolation == ISOLATION_IN_PROCESS:
        return run_agent_episode(job, env, load_agent(job.policy, job.policy_args))
    agent = contained_agent(job.policy, job.policy_args, job.agent_memory)
    done = False
    try:
        record = run_agent_episode(job, env, agent)
        done = True
        return record
    finally:
        if not done:  # it raised, died, or its episode ran out of time: the next episode gets a fresh one
            discard(agent)


def run_agent_episode(job: EpisodeJob, env, agent) -> dict:
    """One episode of ``agent`` on ``env`` (a scene made by `runner.make_episode_env` for ``job``).

    ``agent``: an agent object in this process, or an `AgentProcess` (the same interface across its
    channel). Its extra record fields (``episode_info()``) never replace the record's own."""
    from opend_mj.sim.envs import ActionAdapter, SceneReader

    task = env.task
    config = task.config
    env.reset()
    physics = env.physics
    reader = SceneReader(env, config.image_size)
    control = agent_control(agent)
    adapter = ActionAdapter(job.hand, config)
    if control == "delta":
        low, high = -np.ones(adapter.delta_dim), np.ones(adapter.delta_dim)
        names = ["d_root_x", "d_root_y", "d_root_z", "rot_x", "rot_y", "rot_z"] + list(task.hand.spec.actuator_names)
    else:
        spec = env.action_spec()
        low, high, names = spec.minimum, spec.maximum, spec.name.split("\t")
    info = EpisodeInfo(instruction=task.instruction, hand=job.hand, hand_spec=task.hand.spec,
                       camera_view=reader.camera_view(), control_dt=task.control_timestep,
                       time_limit=PROTOCOL_TIME_LIMIT, action_names=tuple(names), action_low=low,
                       action_high=high, seed=episode_seed(job))
    camera = reader.camera_arrays()

    def observe(with_images: bool, frames: int = 1) -> dict:
        obs = reader.proprio()
        obs["instruction"] = task.instruction
        obs.update(camera)
        if with_images:
            obs["rgb"], obs["depth"] = reader.render(frames)
        return obs

    video = None
    penetration = PenetrationProbe(physics.data.ptr)
    max_steps = int(round(PROTOCOL_TIME_LIMIT / task.control_timestep))
    closest = reader.probe.distance()
    reach = HandReach(task, physics)
    hand_closest = reach() if closest < reach.span + reach.cap else reach.cap
    hold = HoldProbe(task, physics)
    steps, stopped, diverged = 0, False, False
    try:
        # before the video's renderer opens (one renderer at a time). The scene is still before the
        # first action: its depth is the sensor's fused over `depth_frames` frames, as the planner's
        obs = observe(True, frames=config.depth_frames)
        video = VideoRecorder(job, physics, config, task.cabinet.bounds) if job.video_dir else None
        agent.reset(info)
        while steps < max_steps:
            action = agent.act(obs)
            if action is None:
                stopped = True
                break
            if control == "delta":
                d = reader._data
                action = adapter.from_delta(action, d.mocap_pos[reader._mocap], d.mocap_quat[reader._mocap])
            ts = env.step(np.asarray(action, dtype=np.float64))
            steps += 1
            penetration()
            hold()
            if video:
                video.capture()
            site_distance = reader.probe.distance()
            closest = min(closest, site_distance)
            if site_distance < reach.span + hand_closest:
                hand_closest = min(hand_closest, reach())
            if ts.last():  # the scene's time limit is far away: a physics instability ended it
                diverged = True
                break
            obs = observe(wants_image(agent, steps))
    finally:
        reader.close()
        if video:
            video.close()
    extra = agent.episode_info() if callable(getattr(agent, "episode_info", None)) else {}
    extra = dict(extra or {})
    outcome = task.outcome(physics) if not diverged else None
    values = {}
    if outcome is not None:
        values = {"success": bool(outcome.success), "open_ratio": float(outcome.open_ratio),
                  "range_ratio": float(outcome.range_ratio), "joint_value": float(outcome.joint_value),
                  "others_moved": list(outcome.others_moved)}
    if diverged:
        failed = "physics"
        values = {"success": False, "open_ratio": None, "range_ratio": None, "joint_value": None, "others_moved": []}
    else:
        failed = failure_stage(outcome.success, outcome.range_ratio, min(closest, hand_closest), check_locate=False)
    held = hold.summary()
    ending = None if outcome is None else episode_ending(outcome.success, outcome.open_ratio,
                                                         min(closest, hand_closest), held)
    record = {
        "cabinet_dir": job.cabinet_dir,
        "target_type": task.target.kind,
        "instruction": task.instruction,
        "room": task.episode.room_index(),
        "joint_range": [task.target.lower, task.target.upper],
        "closed_value": task.target.closed,
        **values,
        "failed_stage": failed,
        "ending": ending,
        "hold": held,
        "site_to_handle": round(closest, 4),
        "hand_to_handle": round(hand_closest, 4),
        "steps": steps,
        "agent_stopped": stopped,
        "sim_seconds": round(float(physics.data.time), 3),
        "max_penetration_mm": round(penetration.deepest * 1000, 2),
        "physics_warnings": list(task.physics_warnings),
        "video": str(video.path) if video else None,
    }
    return {**record, **{str(k): v for k, v in extra.items() if k not in record and k not in RESERVED_FIELDS}}


__all__ = ["BUILTIN_POLICIES", "PROTOCOL_TIME_LIMIT", "AgentProcess", "agent_name", "load_agent", "parse_policy_args",
           "resolve_policy", "run_agent_episode", "run_agent_group", "run_group"]
