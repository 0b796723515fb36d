"""DAgger (Ross et al. 2011, "A reduction of imitation learning and structured prediction to no-regret
online learning") for the behaviour-cloning policy, with the planner as its interactive expert.

Round 0 trains the policy on the planner's demonstrations (`opend demos`). Each round after that
rolls the current policy out on the training targets: at every control step the policy acts, and
:class:`~opend_mj.policy.expert.PlannerExpert` labels the state with the action it would send there;
the action stepped is the expert's with probability ``beta`` (``beta0 * beta_decay ** (round - 1)``,
drawn per step from the episode's seed), else the policy's. Every labelled state becomes a training
sample (its label the expert's action, its context the handle the *policy's own* solver found), the
policy is trained again on the demonstrations and every round's rollouts, and its success on the
validation targets goes into the summary. A rollout ends where the expert has nothing more to label
(its plan finished, or the hand is where it cannot label) or the policy stops.

Rollouts are recorded like demonstrations (`opend_mj.apps.planner_demos.record_demos`: the same file,
keys and log, resumable without losing or repeating an episode); they carry the attribute
``labels = "expert"`` (usable for training whether or not the rollout opened its part), ``beta`` and
the ``policy`` checkpoint. Every round's files live under one folder (``build/dagger/<hand>`` by
default): ``round_<i>.hdf5`` (rollouts), ``policy_<i>.pt`` (+ ``.json``), ``val_<i>.jsonl`` (the
validation episodes); a DAgger run that is killed resumes where it stopped.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class Rollout:
    """What a DAgger round's episodes run: the policy (an `opend run --policy` spec and its
    constructor arguments) and the share ``beta`` of steps at which the expert's action is stepped."""

    policy: str
    policy_args: tuple = ()
    beta: float = 0.0
    round: int = 1

    def __post_init__(self):
        if not 0.0 <= self.beta <= 1.0:
            raise ValueError(f"DAgger beta must be within [0, 1], not {self.beta}")

    def episode(self, job, env, config) -> tuple[dict, object]:
        """One rollout episode of DAgger round ``round`` (:func:`rollout_episode`)."""
        return rollout_episode(job, env, config)


@dataclass(frozen=True)
class DaggerConfig:
    """A DAgger run: ``rounds`` after round 0; ``beta0`` and ``beta_decay`` the expert's share of the
    stepped actions per round; ``val_share`` of the training cabinets (drawn from ``seed``) kept
    apart for validation (never rolled out, never trained on); ``val_seed``: the episode seed of the
    validation episodes (other rooms, lights and cameras than the training episodes'); ``limit``: the
    first K training targets only are rolled out; ``val_limit``: the first K validation targets only
    are run; ``final_steps``: optimiser steps of the final round's training (its policy is the
    one shipped where it validates best; it trains on all the data), where the rounds before it, whose policies only roll out,
    train for the `BCConfig`'s ``steps`` (None: those steps too); ``warm_start``: each round between
    round 0 and the final one starts from the previous round's weights (`bc_train.train_bc`'s
    ``init``) instead of from scratch, so that it needs fewer optimiser steps (``round_steps``; None:
    the `BCConfig`'s ``steps``); ``init``: round 0 starts from this checkpoint (None: from scratch).
    See :meth:`round_training`."""

    rounds: int = 2
    beta0: float = 0.5
    beta_decay: float = 0.5
    val_share: float = 0.15
    val_seed: int = 100
    seed: int = 0
    limit: int | None = None  # roll out the first K training targets only (small runs, tests)
    val_limit: int | None = None  # validate on the first K validation targets only
    final_steps: int | None = None  # optimiser steps of the final round (None: the BCConfig's)
    warm_start: bool = False  # rounds between round 0 and the final one start from the previous round's policy
    round_steps: int | None = None  # optimiser steps of the rounds between round 0 and the final one
    init: Path | None = None  # round 0 starts from this checkpoint (None: from scratch)

    def beta(self, round_: int) -> float:
        return float(self.beta0 * self.beta_decay ** (round_ - 1))

    def round_training(self, round_: int, steps: int, folder: Path) -> tuple[int, Path | None]:
        """(optimiser steps, checkpoint to start from or None) of round ``round_``'s training, where
        ``steps`` is the `BCConfig`'s: round 0 from ``init``; a round between it and the final one
        for ``round_steps``, from the previous round's policy where ``warm_start``; the final round
        from scratch on all the data for ``final_steps`` (its policy is the one shipped)."""
        if round_ == 0:
            return steps, self.init
        if round_ == self.rounds:
            return self.final_steps or steps, None
        previous = Path(folder) / f"policy_{round_ - 1}.pt" if self.warm_start else None
        return self.round_steps or steps, previous


def rollout_episode(job, env, config) -> tuple[dict, object]:
    """One DAgger episode of ``job`` (``config``: a `RecordConfig` whose ``rollout`` is set): (its log
    line, the labelled demonstration or None where the policy found no handle)."""
    from opend_mj.apps.demos import Demo, _episode_json, env_args
    from opend_mj.apps.planner_demos import noise_seed
    from opend_mj.evaluation.agents import PROTOCOL_TIME_LIMIT, load_agent
    from opend_mj.evaluation.runner import PhysicsDiverged, instruction_for
    from opend_mj.evaluation.takeover import agent_info
    from opend_mj.policy.expert import PlannerExpert
    from opend_mj.policy.learned.bc import style_index
    from opend_mj.policy.planner import Observation
    from opend_mj.sim.camera import RGBDCamera
    from opend_mj.sim.envs import SceneReader, instruction_onehot

    rollout: Rollout = config.rollout
    t0 = time.perf_counter()
    env.task.set_target(job.joint, instruction_for(job))
    env.reset()
    task, physics = env.task, env.physics
    size = task.config.image_size
    reader = SceneReader(env, size)
    agent = load_agent(rollout.policy, rollout.policy_args)
    rng = np.random.default_rng(noise_seed(job) + [rollout.round])
    steps: dict[str, list] = {}
    labels, executed, styles = [], [], []
    percept = None
    why = "time"
    try:
        with RGBDCamera(physics, "front", size, size) as cam:
            rgb, depth = cam.render()
            depth = task.sense_depth(rgb, depth, frames=task.config.depth_frames)
            first = Observation(rgb=rgb, depth=depth, instruction=task.instruction, camera_view=task.camera_view(physics))
            expert = PlannerExpert(env, first, cam)
            agent.reset(agent_info(job, env, reader))
            camera = reader.camera_arrays()  # the camera does not move within an episode
            obs = {**reader.proprio(), "instruction": task.instruction, **camera, "rgb": rgb, "depth": depth}
            max_steps = int(round(PROTOCOL_TIME_LIMIT / task.control_timestep))
            try:
                for _ in range(max_steps):
                    proprio = reader.proprio()
                    action = agent.act(obs)
                    percept = getattr(agent, "percept", None)
                    label = expert.action()
                    if action is None or label is None or percept is None:
                        why = "policy_stopped" if action is None else ("expert_" + str(expert.why))
                        break
                    for k, v in proprio.items():
                        steps.setdefault(k, []).append(np.array(v, float))
                    labels.append(np.asarray(label, float))
                    styles.append(style_index(expert.style))
                    sent = label if rng.random() < rollout.beta else np.asarray(action, float)
                    executed.append(sent)
                    if env.step(sent).last():
                        raise PhysicsDiverged(f"physics instability: {task.physics_warnings}")
                    obs = {**reader.proprio(), "instruction": task.instruction, **camera}
            except PhysicsDiverged:
                why = "physics"
            finally:
                expert.close()
    finally:
        reader.close()
        if callable(getattr(agent, "close", None)):
            agent.close()
    outcome = task.outcome(physics)
    n = len(labels)
    line = {"key": list(job.key()), "cabinet": job.cabinet, "joint": job.joint, "hand": job.hand, "seed": job.seed,
            "split": job.split, "success": bool(outcome.success), "open_ratio": round(float(outcome.open_ratio), 4),
            "steps": n, "ended": why, "wall_seconds": round(time.perf_counter() - t0, 2)}
    if n == 0 or percept is None:
        return line, None
    feats = np.asarray(percept.vector(), float)
    obs_arrays = {k: np.asarray(v) for k, v in steps.items()}
    obs_arrays["instruction"] = np.repeat(instruction_onehot(task.instruction)[None].astype(np.float64), n, axis=0)
    obs_arrays["handle_box"] = np.repeat(np.asarray(percept.box.as_tuple(), float)[None], n, axis=0)
    obs_arrays["handle_features"] = np.repeat(feats[None], n, axis=0)
    attrs = {
        "instruction": str(task.instruction), "cabinet": job.cabinet, "cabinet_dir": str(Path(job.cabinet_dir).resolve()),
        "target_joint": job.joint, "target_type": str(task.target.kind), "hand": job.hand, "solver": "oracle",
        "split": job.split, "seed": int(job.seed), "room": int(task.episode.room_index()),
        "success": bool(outcome.success), "failed_stage": "" if outcome.success else why,
        "open_ratio": float(outcome.open_ratio), "joint_value": float(outcome.joint_value), "num_samples": n,
        "episode": _episode_json(task.episode), "sim_seconds": float(physics.data.time),
        "wall_seconds": float(time.perf_counter() - t0), "job_key": json.dumps(list(job.key())),
        "handle_kind": percept.handle.kind, "handle_orientation": percept.handle.orientation,
        "hinge_seen": percept.hinge or "", "action_noise": "", "labels": "expert", "beta": float(rollout.beta),
        "policy": json.dumps([rollout.policy, [list(a) for a in rollout.policy_args]]), "dagger_round": rollout.round,
        "expert_restarts": int(expert.restarts),
    }
    demo = Demo(actions=np.asarray(labels, float).reshape(n, -1), obs=obs_arrays, attrs=attrs,
                extra={"actions_executed": np.asarray(executed, float).reshape(n, -1),
                       "grasp_style": np.asarray(styles, np.int8).reshape(n)})
    demo.env_args = env_args(task.config)  # type: ignore[attr-defined]
    return line, demo


def split_cabinets(jobs, share: float, seed: int) -> tuple[set, set]:
    """(training cabinets, validation cabinets) of ``jobs``: ``share`` of the cabinets, drawn from ``seed``."""
    cabinets = sorted({j.cabinet for j in jobs})
    rng = np.random.default_rng([seed, 46])
    n_val = max(1, int(round(len(cabinets) * share))) if len(cabinets) > 1 and share > 0 else 0
    val = set(rng.choice(cabinets, size=n_val, replace=False).tolist()) if n_val else set()
    return set(cabinets) - val, val


def best_round(summary: dict) -> dict:
    """The round whose policy to ship: the highest validation success, the later round on a tie
    (it trained on more of the policy's own states)."""
    return max(summary["rounds"], key=lambda r: (r["val_success"], r["round"]))


def run_dagger(demo_files, hand: str, cabinets_dir: Path, folder: Path, bc_config, config: DaggerConfig = DaggerConfig(),
               workers: int = 1, threads: int = 1, progress: bool = True, log=print, solver: str = "fasterrcnn") -> dict:
    """DAgger from ``demo_files`` (the planner's demonstrations of ``hand``) on the training split of
    ``cabinets_dir``; every round's files under ``folder``. Returns the summary (also written to
    ``folder/dagger.json``): per round, the data it trained on and its validation success, and
    ``chosen``, the round whose policy to ship (:func:`best_round`)."""
    from dataclasses import replace

    from opend_mj.apps.planner_demos import RecordConfig, load_training_demos, record_demos
    from opend_mj.evaluation.jobs import make_jobs
    from opend_mj.evaluation.pool import run_jobs
    from opend_mj.evaluation.results import load_results
    from opend_mj.policy.learned.bc_train import train_bc

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    train_jobs = make_jobs(cabinets_dir, [hand], "oracle", split="train", seed=config.seed)
    train_cabs, val_cabs = split_cabinets(train_jobs, config.val_share, config.seed)
    rollout_jobs = [j for j in train_jobs if j.cabinet in train_cabs][:config.limit]
    val_jobs = make_jobs(cabinets_dir, [hand], "oracle", split="train", seed=config.val_seed,
                         cabinet_ids=sorted(val_cabs))[:config.val_limit]
    demos = [d for d in load_training_demos(list(demo_files), hand=hand) if d.attrs.get("cabinet") not in val_cabs]
    summary = {"hand": hand, "demo_files": [str(p) for p in demo_files],
               "config": {k: (str(v) if isinstance(v, Path) else v) for k, v in config.__dict__.items()},
               "validation": {"cabinets": len(val_cabs), "targets": len(val_jobs), "seed": config.val_seed},
               "rounds": []}
    data_files: list[Path] = []
    for round_ in range(config.rounds + 1):
        ckpt = folder / f"policy_{round_}.pt"
        if round_ > 0:
            previous = folder / f"policy_{round_ - 1}.pt"
            rollout = Rollout(policy="bc", policy_args=(("checkpoint", str(previous)), ("solver", solver)),
                              beta=config.beta(round_), round=round_)
            data = folder / f"round_{round_}.hdf5"
            log(f"round {round_}: rollouts of {previous.name} on {len(rollout_jobs)} targets, beta {rollout.beta:g}")
            record_demos(rollout_jobs, data, workers=workers, config=RecordConfig(keep_failures=True, rollout=rollout),
                         progress=progress)
            data_files.append(data)
        labelled = load_training_demos(data_files, hand=hand, successes_only=False) if data_files else []
        if not ckpt.is_file():
            log(f"round {round_}: training on {len(demos)} demonstrations and {len(labelled)} labelled rollouts")
            steps, init = config.round_training(round_, bc_config.steps, folder)
            trained = train_bc(demos + labelled, hand, replace(bc_config, seed=config.seed, steps=steps), out=ckpt,
                               progress=progress, threads=threads, init=init)
        else:
            trained = json.loads(ckpt.with_suffix(".json").read_text())
        val_out = folder / f"val_{round_}.jsonl"
        jobs = [replace(j, policy="bc", policy_args=(("checkpoint", str(ckpt)), ("solver", solver)),
                        solver=f"bc-{solver}")
                for j in val_jobs]
        run_jobs(jobs, val_out, workers=workers, progress=progress)
        recs = [r for r in load_results(val_out)]
        opened = sum(bool(r.get("success")) for r in recs)
        entry = {"round": round_, "checkpoint": str(ckpt), "demos": len(demos), "rollouts": len(labelled),
                 "samples": trained.get("samples"), "beta": config.beta(round_) if round_ else None,
                 "val_success": round(100.0 * opened / max(1, len(recs)), 1), "val_episodes": len(recs)}
        summary["rounds"].append(entry)
        summary["chosen"] = best_round(summary)["round"]
        log(f"round {round_}: validation {opened}/{len(recs)} opened ({entry['val_success']} %)")
        (folder / "dagger.json").write_text(json.dumps(summary, indent=1) + "\n")
    return summary


__all__ = ["DaggerConfig", "Rollout", "best_round", "rollout_episode", "run_dagger", "split_cabinets"]
