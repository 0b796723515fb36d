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
``--policy-arg key=value`` are passed to the constructor. One agent instance per worker
process and spec, reset at every episode.
"""

from __future__ import annotations

import importlib
import importlib.util
import json
import sys
import zlib
from pathlib import Path

import numpy as np

from opend_mj.evaluation.episode import EpisodeJob
from opend_mj.evaluation.grading import failure_stage
from opend_mj.evaluation.probes import HandReach, PenetrationProbe, VideoRecorder
from opend_mj.evaluation.runner import (
    instruction_for,
    run_episode_group,
)
from opend_mj.policy.agents import EpisodeInfo, agent_control, agent_images, agent_name, wants_image

#: The protocol's time limit for an agent (s of simulated time): TaskConfig's default episode length.
PROTOCOL_TIME_LIMIT = 15.0

_LOADED: dict[tuple, object] = {}

#: Agents shipped with the package, by short name (``opend run --policy bc``).
BUILTIN_POLICIES = {"bc": "opend_mj.policy.bc:BCAgent"}


def parse_policy_args(items) -> tuple[tuple[str, object], ...]:
    """``("k=v", ...)`` -> ``(("k", v), ...)``; a value is JSON where it parses (numbers, true, lists)."""
    out = []
    for item in items or ():
        key, sep, value = str(item).partition("=")
        if not sep or not key.strip():
            raise ValueError(f"policy argument {item!r} is not key=value")
        try:
            parsed = json.loads(value)
        except json.JSONDecodeError:
            parsed = value
        out.append((key.strip(), parsed))
    return tuple(out)


def resolve_policy(spec: str) -> tuple[str, str]:
    """``(module or absolute file path, attribute)`` of a policy spec; raises ValueError if not found."""
    spec = BUILTIN_POLICIES.get(spec, spec)
    target, sep, attr = spec.rpartition(":")
    if not sep:
        target, attr = spec, ""
    if target.endswith(".py") or Path(target).is_file():
        path = Path(target).expanduser().resolve()
        if not path.is_file():
            raise ValueError(f"policy file {target} not found")
        return str(path), attr or "Agent"
    if not attr:
        raise ValueError(f"policy {spec!r}: name a class, as module:Class or path/to/file.py:Class")
    return target, attr


def _import(target: str):
    if target.endswith(".py"):
        name = f"opend_policy_{zlib.crc32(target.encode()):08x}"
        if name in sys.modules:
            return sys.modules[name]
        spec = importlib.util.spec_from_file_location(name, target)
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
        return module
    return importlib.import_module(target)


def load_agent(spec: str, args: tuple = ()):
    """The agent a spec names, made with ``args`` (cached per process)."""
    key = (spec, args)
    agent = _LOADED.get(key)
    if agent is None:
        target, attr = resolve_policy(spec)
        try:
            module = _import(target)
        except ImportError as exc:
            raise ValueError(f"policy {spec!r}: cannot import {target} ({exc})") from exc
        factory = getattr(module, attr, None)
        if factory is None:
            raise ValueError(f"policy {spec!r}: {target} has no {attr!r}")
        # a class or a factory function is called with the arguments; an instance is used as it is
        is_factory = isinstance(factory, type) or (callable(factory) and not hasattr(factory, "act"))
        agent = factory(**dict(args)) if is_factory else factory
        if not callable(getattr(agent, "act", None)):
            raise ValueError(f"policy {spec!r}: {attr} has no act(obs) method")
        agent_control(agent)
        agent_images(agent)
        _LOADED[key] = agent
    return agent


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
    the agent of the jobs' ``policy`` acting."""
    return run_episode_group(jobs, episode=_agent_episode, timeout=episode_timeout)


def _agent_episode(job: EpisodeJob, env) -> dict:
    env.task.set_target(job.joint, instruction_for(job))
    return run_agent_episode(job, env, load_agent(job.policy, job.policy_args))


def run_agent_episode(job: EpisodeJob, env, agent) -> dict:
    """One episode of ``agent`` on ``env`` (a scene made by `runner.make_episode_env` for ``job``)."""
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
    return {
        "cabinet_dir": job.cabinet_dir,
        "target_type": task.target.kind,
        "instruction": task.instruction,
        "room": task.episode.room_index(),
        "joint_range": [task.target.lower, task.target.upper],
        "closed_value": task.target.closed,
        **values,
        "failed_stage": failed,
        "site_to_handle": round(closest, 4),
        "hand_to_handle": round(hand_closest, 4),
        "steps": steps,
        "agent_stopped": stopped,
        "sim_seconds": round(float(physics.data.time), 3),
        "max_penetration_mm": round(penetration.deepest * 1000, 2),
        "physics_warnings": list(task.physics_warnings),
        "video": str(video.path) if video else None,
        **extra,
    }


__all__ = ["BUILTIN_POLICIES", "PROTOCOL_TIME_LIMIT", "agent_name", "load_agent", "parse_policy_args", "resolve_policy",
           "run_agent_episode", "run_agent_group", "run_group"]
