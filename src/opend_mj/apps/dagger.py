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
the ``policy`` checkpoint. Each round's policy (float16, under 1 MB) and its validation figures are
kept in a small folder meant for the repository (``checkpoints/bc_rounds/<hand>`` from `opend
train-policy`), so that the next run extends the same recipe; the rollouts, validation episodes and
working checkpoints live under ``build/`` and are made again from the kept policies where missing
(the episodes are deterministic). A run that is killed loses at most the round in flight.
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
    constructor arguments) and the share ``beta`` of steps at which the expert's action is stepped.
    ``hold``: once the expert's plan has ended with the part open, the rollout goes on to the
    policy's stop, each state labelled with the plan's last action (where the planner leaves the
    hand), instead of ending there."""

    policy: str
    policy_args: tuple = ()
    beta: float = 0.0
    round: int = 1
    hold: bool = False

    def __post_init__(self):
        if not 0.0 <= self.beta <= 1.0:
            raise ValueError(f"DAgger beta must be within [0, 1], not {self.beta}")

    def episode(self, job, env, config) -> tuple[dict, object]:
        """One rollout episode of DAgger round ``round`` (:func:`rollout_episode`)."""
        return rollout_episode(job, env, config)


@dataclass(frozen=True)
class DaggerConfig:
    """A DAgger run: rounds 0 to ``rounds``, then the final policy.

    ``beta0`` and ``beta_decay``: the expert's share of the stepped actions per round;
    ``val_share`` of the training cabinets (drawn from ``seed``) kept apart for validation (never
    rolled out, never trained on by a round); ``val_seed``: the episode seed of the validation
    episodes (other rooms, lights and cameras than the training episodes'); round ``r``'s rollouts
    run at episode seed ``rollout_seed + r`` (each round other rooms, lights, cameras and
    percepts); ``limit``: the first K training targets only are rolled out; ``val_limit``: the
    first K validation targets only are run; ``warm_start``: each round after round 0 starts from
    the previous round's weights (`bc_train.train_bc`'s ``init``) and trains ``round_steps`` (None:
    the `BCConfig`'s ``steps``); ``init``: round 0 starts from this checkpoint (None: from scratch).
    The final policy trains on every training cabinet (the validation cabinets' demonstrations
    too) and every round's rollouts, from the best round's weights (:func:`best_round`) where
    ``warm_start``, for ``final_steps`` (None: the `BCConfig`'s ``steps``). See
    :meth:`round_training`."""

    rounds: int = 2
    beta0: float = 0.5
    beta_decay: float = 0.5
    val_share: float = 0.15
    val_seed: int = 100
    rollout_seed: int = 10
    seed: int = 0
    limit: int | None = None  # roll out the first K training targets only (small runs, tests)
    val_limit: int | None = None  # validate on the first K validation targets only
    final_steps: int | None = None  # optimiser steps of the final policy (None: the BCConfig's)
    warm_start: bool = True  # rounds after round 0 (and the final policy) start from a previous policy
    round_steps: int | None = None  # optimiser steps of the rounds after round 0
    init: Path | None = None  # round 0 starts from this checkpoint (None: from scratch)
    #: Each round after round 0 also rolls out, this many times more at other episode seeds, the
    #: training targets whose rollout of that round failed: the learner's hard cases (rare layouts,
    #: handles near the floor) get more of the expert's labels than their share of the cabinets.
    revisit: int = 0
    #: Rollouts go on after the expert's plan ended with the part open, labelled with its last action
    #: (`Rollout.hold`): the policy acts to its stop time, past where demonstrations end, and learns
    #: to stay where the planner leaves the hand instead of wandering into the opened part.
    hold: bool = False
    #: More compiled datasets whose every target (all splits) each round also rolls out, e.g. extra
    #: training cabinets from `opend generate --family` (their demonstrations come in ``demo_files``);
    #: validation stays on the main dataset's held-out training cabinets.
    extra_cabinets: tuple[str, ...] = ()
    #: The final policy is a seed ensemble of this many members, each trained as the final policy is
    #: (the same rounds' data, from the same best round) with seeds ``seed``, ``seed + 1``, ...: their
    #: batches and dropout differ, so they err differently, and the agent averages their chunks
    #: (`bc_agent.BCAgent`, `bc_model.bundle_policies`). 1: one policy.
    final_members: int = 1

    def beta(self, round_: int) -> float:
        return float(self.beta0 * self.beta_decay ** (round_ - 1))

    def revisit_seed(self, round_: int, visit: int) -> int:
        """The episode seed of the ``visit``-th (0-based) revisit of round ``round_``'s failed targets:
        apart from every round's rollout seed and from the validation seed."""
        return self.rollout_seed + 1000 * (visit + 1) + round_

    def round_training(self, round_: int, steps: int, previous: Path | None) -> tuple[int, Path | None]:
        """(optimiser steps, checkpoint to start from or None) of round ``round_``'s training, where
        ``steps`` is the `BCConfig`'s and ``previous`` the previous round's policy: round 0 from
        ``init``; a later round for ``round_steps``, from ``previous`` where ``warm_start``."""
        if round_ == 0:
            return steps, self.init
        return self.round_steps or steps, previous if self.warm_start else None

    def final_training(self, steps: int, best: Path) -> tuple[int, Path | None]:
        """(optimiser steps, checkpoint to start from or None) of the final policy, ``best`` the
        best round's policy."""
        return self.final_steps or steps, best if self.warm_start else None


def rollout_episode(job, env, config) -> tuple[dict, object]:
    """One DAgger episode of ``job`` (``config``: a `RecordConfig` whose ``rollout`` is set): (its log
    line, the labelled demonstration or None where the policy found no handle)."""
    from opend_mj.apps.demos import Demo, _episode_json, env_args
    from opend_mj.apps.planner_demos import noise_seed
    from opend_mj.evaluation.agents import PROTOCOL_TIME_LIMIT, load_agent
    from opend_mj.evaluation.runner import PhysicsDiverged, instruction_for
    from opend_mj.evaluation.takeover import agent_info
    from opend_mj.policy.expert import PlannerExpert
    from opend_mj.policy.agents import agent_image_every, wants_image
    from opend_mj.policy.learned.bc_model import WATCH_KEY, style_index
    from opend_mj.policy.planner import Observation
    from opend_mj.sim.camera import RGBDCamera
    from opend_mj.language import instruction_onehot
    from opend_mj.sim.envs import SceneReader

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
    held = 0  # steps labelled with the finished plan's last action (`Rollout.hold`)
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
                    holding = bool(label is None and rollout.hold and labels and (held or (
                        expert.why == "finished" and task.outcome(physics).success)))
                    if holding:
                        label = labels[-1]  # the plan ended with the part open: the hand stays
                    if action is None or label is None or percept is None:
                        why = "policy_stopped" if action is None else ("expert_" + str(expert.why))
                        break
                    held += holding
                    for k, v in proprio.items():
                        steps.setdefault(k, []).append(np.array(v, float))
                    labels.append(np.asarray(label, float))
                    styles.append(style_index(expert.style))  # after the plan: its last style
                    sent = label if rng.random() < rollout.beta else np.asarray(action, float)
                    executed.append(sent)
                    watched = getattr(agent, "last_watch", None)
                    if watched is not None:
                        steps.setdefault(WATCH_KEY, []).append(np.array(watched, float))
                    if env.step(sent).last():
                        raise PhysicsDiverged(f"physics instability: {task.physics_warnings}")
                    obs = {**reader.proprio(), "instruction": task.instruction, **camera}
                    if wants_image(agent, len(labels)):  # the images `opend run` would give the agent
                        rgb, depth = cam.render()
                        obs["rgb"], obs["depth"] = rgb, task.sense_depth(rgb, depth)
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
            "steps": n, "held": held, "ended": why, "wall_seconds": round(time.perf_counter() - t0, 2)}
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
        "expert_restarts": int(expert.restarts), "held_steps": int(held),
        "watch_every": int(agent_image_every(agent)) if WATCH_KEY in obs_arrays else 0,
    }
    demo = Demo(actions=np.asarray(labels, float).reshape(n, -1), obs=obs_arrays, attrs=attrs,
                extra={"actions_executed": np.asarray(executed, float).reshape(n, -1),
                       "grasp_style": np.asarray(styles, np.int8).reshape(n)})
    demo.env_args = env_args(task.config)  # type: ignore[attr-defined]
    return line, demo


def kept_rounds(keep: Path) -> list[dict]:
    """The figures of every round kept in ``keep`` (``round_<i>.json``, as `run_dagger` writes them), by round."""
    rounds = [json.loads(p.read_text()) for p in Path(keep).glob("round_*.json") if not p.name.endswith(".train.json")]
    return sorted(rounds, key=lambda r: r["round"])


def failed_targets(log: Path) -> set[tuple[str, str]]:
    """(cabinet, joint) of the rollouts in a round's episode log (`planner_demos.log_path`) that did
    not open their part."""
    out = set()
    if log.is_file():
        for line in log.read_text().splitlines():
            if line.strip():
                entry = json.loads(line)
                if not entry.get("success"):
                    out.add((entry["cabinet"], entry["joint"]))
    return out


def split_cabinets(jobs, share: float, seed: int) -> tuple[set, set]:
    """(training cabinets, validation cabinets) of ``jobs``: ``share`` of the cabinets, drawn from ``seed``."""
    cabinets = sorted({j.cabinet for j in jobs})
    rng = np.random.default_rng([seed, 46])
    n_val = max(1, int(round(len(cabinets) * share))) if len(cabinets) > 1 and share > 0 else 0
    val = set(rng.choice(cabinets, size=n_val, replace=False).tolist()) if n_val else set()
    return set(cabinets) - val, val


def best_round(summary: dict) -> dict:
    """The round whose policy the final policy starts from: the highest validation success, the
    later round on a tie (it trained on more of the policy's own states)."""
    return max(summary["rounds"], key=lambda r: (r["val_success"], r["round"]))


def validation_figures(records) -> dict:
    """Validation success (%) over ``records`` (`opend run` episodes), overall and per target kind."""
    out = {"val_episodes": len(records),
           "val_success": round(100.0 * sum(bool(r.get("success")) for r in records) / max(1, len(records)), 1)}
    for kind in ("drawer", "door"):
        mine = [r for r in records if r.get("target_type") == kind]
        out[f"val_{kind}"] = round(100.0 * sum(bool(r.get("success")) for r in mine) / max(1, len(mine)), 1)
        out[f"val_{kind}_episodes"] = len(mine)
    return out


def run_dagger(demo_files, hand: str, cabinets_dir: Path, folder: Path, bc_config, config: DaggerConfig = DaggerConfig(),
               workers: int = 1, threads: int = 1, progress: bool = True, log=print, solver: str = "fasterrcnn",
               keep: Path | None = None) -> dict:
    """DAgger from ``demo_files`` (the planner's demonstrations of ``hand``) on the training split of
    ``cabinets_dir``, then the final policy (``folder/final.pt``).

    ``keep`` (default: ``folder``): where each round's policy (``round_<i>.pt``, float16 weights) and
    its figures (``round_<i>.json``: validation success overall and per kind, data sizes, wall
    seconds per stage) are kept: a small folder meant for the repository, so that a later run
    continues after the latest kept round instead of starting over. ``folder`` holds what can be
    made again: the rollouts (``round_<i>.hdf5``; missing ones are recorded again, deterministically,
    from the kept policies), the validation episodes and the final policy. A killed run loses at
    most the round in flight. Returns the summary (also ``folder/dagger.json``)."""
    import shutil
    from dataclasses import replace

    from opend_mj.apps.planner_demos import RecordConfig, load_training_demos, log_path, record_demos
    from opend_mj.evaluation.jobs import make_jobs
    from opend_mj.evaluation.pool import run_jobs
    from opend_mj.evaluation.results import load_results
    from opend_mj.policy.learned.bc_train import train_bc

    folder = Path(folder)
    keep = Path(keep) if keep is not None else folder
    for f in (folder, keep):
        f.mkdir(parents=True, exist_ok=True)
    train_jobs = make_jobs(cabinets_dir, [hand], "oracle", split="train", seed=config.seed)
    train_cabs, val_cabs = split_cabinets(train_jobs, config.val_share, config.seed)
    val_jobs = make_jobs(cabinets_dir, [hand], "oracle", split="train", seed=config.val_seed,
                         cabinet_ids=sorted(val_cabs))[:config.val_limit]
    all_demos = load_training_demos(list(demo_files), hand=hand)
    demos = [d for d in all_demos if d.attrs.get("cabinet") not in val_cabs]
    summary = {"hand": hand, "demo_files": [str(p) for p in demo_files], "kept": str(keep),
               "config": {k: (str(v) if isinstance(v, Path) else v) for k, v in config.__dict__.items()},
               "validation": {"cabinets": len(val_cabs), "targets": len(val_jobs), "seed": config.val_seed},
               "rounds": []}
    data_files: list[Path] = []
    loaded: dict = {}

    def rollouts_of(files: list[Path]) -> list:
        """The labelled rollouts of ``files``, read once for the latest list asked for."""
        key = tuple(files)
        if key not in loaded:
            loaded.clear()
            loaded[key] = load_training_demos(list(files), hand=hand, successes_only=False) if files else []
        return loaded[key]

    def timed(stage: str, seconds: dict, fn):
        t0 = time.perf_counter()
        out = fn()
        seconds[stage] = round(time.perf_counter() - t0, 1)
        log(f"  {stage}: {seconds[stage]:.0f} s")
        return out

    for round_ in range(config.rounds + 1):
        ckpt, figures = keep / f"round_{round_}.pt", keep / f"round_{round_}.json"
        seconds: dict = {}
        kept = ckpt.is_file() and figures.is_file()
        # a kept round's rollouts are made again as it made them (rounds kept before revisits had none)
        made = json.loads(figures.read_text()) if kept else {}
        revisit = made.get("revisit", 0) if kept else config.revisit
        hold = made.get("hold", False) if kept else config.hold
        extra_dirs = made.get("extra_cabinets", []) if kept else list(config.extra_cabinets)
        revisited = 0
        if round_ > 0:
            previous = keep / f"round_{round_ - 1}.pt"
            rollout = Rollout(policy="bc", policy_args=(("checkpoint", str(previous)), ("solver", solver)),
                              beta=config.beta(round_), round=round_, hold=hold)
            jobs = make_jobs(cabinets_dir, [hand], "oracle", split="train", seed=config.rollout_seed + round_,
                             cabinet_ids=sorted(train_cabs))[:config.limit]
            for more in extra_dirs:
                jobs += make_jobs(Path(more), [hand], "oracle", split="all",
                                  seed=config.rollout_seed + round_)[:config.limit]
            data = folder / f"round_{round_}.hdf5"
            if not rollouts_made_by(folder, round_, {"policy_sha256": file_sha256(previous), "beta": rollout.beta,
                                                     "hold": hold, "revisit": revisit, "extra_cabinets": extra_dirs,
                                                     "seed": config.rollout_seed + round_, "targets": len(jobs)}):
                log(f"round {round_}: the rollouts in {folder} were made by another policy or recipe: made again")
            log(f"round {round_}: rollouts of {previous.name} on {len(jobs)} targets (episode seed "
                f"{config.rollout_seed + round_}), beta {rollout.beta:g}")
            timed("rollouts", seconds, lambda: record_demos(
                jobs, data, workers=workers, config=RecordConfig(keep_failures=True, rollout=rollout),
                progress=progress))
            data_files.append(data)
            failed = failed_targets(log_path(data)) if revisit else set()
            again = [j for j in jobs if (j.cabinet, j.joint) in failed]
            for visit in range(revisit if again else 0):
                seed = config.revisit_seed(round_, visit)
                extra = folder / f"round_{round_}_revisit_{visit}.hdf5"
                log(f"round {round_}: revisit {visit + 1} of the {len(again)} targets whose rollout failed "
                    f"(episode seed {seed})")
                timed(f"revisit_{visit}", seconds, lambda: record_demos(
                    [replace(j, seed=seed) for j in again], extra, workers=workers,
                    config=RecordConfig(keep_failures=True, rollout=rollout), progress=progress))
                data_files.append(extra)
                revisited += len(again)
        if kept:
            entry = made
            log(f"round {round_}: kept ({ckpt}): validation {entry['val_success']} %")
        else:
            labelled = rollouts_of(data_files)
            steps, init = config.round_training(round_, bc_config.steps, keep / f"round_{round_ - 1}.pt")
            log(f"round {round_}: training on {len(demos)} demonstrations and {len(labelled)} labelled rollouts "
                f"({steps} steps{', from ' + str(init) if init else ''})")
            work = folder / f"policy_{round_}.pt"
            trained = timed("training", seconds, lambda: train_bc(
                demos + labelled, hand, replace(bc_config, seed=config.seed, steps=steps), out=work,
                progress=progress, threads=threads, init=init))
            save_half(work, ckpt)  # the policy kept, validated and rolled out: float16 weights
            shutil.copyfile(work.with_suffix(".json"), ckpt.with_suffix(".train.json"))  # its training summary
            val_out = folder / f"val_{round_}.jsonl"
            val_out.unlink(missing_ok=True)  # episodes of a policy trained before this one
            jobs = [replace(j, policy="bc", policy_args=(("checkpoint", str(ckpt)), ("solver", solver)),
                            solver=f"bc-{solver}") for j in val_jobs]
            timed("validation", seconds, lambda: run_jobs(jobs, val_out, workers=workers, progress=progress))
            entry = {"round": round_, "demos": len(demos), "rollouts": len(labelled),
                     "samples": trained.get("samples"), "steps": steps, "init": str(init) if init else None,
                     "beta": config.beta(round_) if round_ else None,
                     "rollout_seed": config.rollout_seed + round_ if round_ else None,
                     "revisit": revisit, "revisited": revisited, "hold": hold, "extra_cabinets": extra_dirs,
                     **validation_figures(list(load_results(val_out))), "seconds": seconds}
            figures.write_text(json.dumps(entry, indent=1) + "\n")
            log(f"round {round_}: validation {entry['val_success']} % (drawers {entry['val_drawer']} %, doors "
                f"{entry['val_door']} %) -> {ckpt}")
        summary["rounds"].append({**entry, "checkpoint": str(ckpt)})
        summary["chosen"] = best_round(summary)["round"]
        (folder / "dagger.json").write_text(json.dumps(summary, indent=1) + "\n")
    best = keep / f"round_{summary['chosen']}.pt"
    labelled = rollouts_of(data_files)
    steps, init = config.final_training(bc_config.steps, best)
    plan = {"from_round": summary["chosen"], "rounds": config.rounds, "steps": steps, "demos": len(all_demos),
            "rollouts": len(labelled), "warm_start": init is not None, "from_sha256": file_sha256(best)}
    summary["final"] = {**plan, "members": []}
    for member in range(config.final_members):
        # member 0 is `final.pt` (as before ensembles), member i `final_<i>.pt`, seed ``seed + i``
        final = folder / ("final.pt" if member == 0 else f"final_{member}.pt")
        wanted = {**plan, **({"member": member, "seed": config.seed + member} if member else {})}
        done = final.with_suffix(".plan.json")
        made = json.loads(done.read_text()) if final.is_file() and done.is_file() else None
        # a plan written before plans named a hash is taken as made from the chosen round
        if made is not None and "from_sha256" not in made:
            made["from_sha256"] = plan["from_sha256"]
        seconds = {}
        if made == wanted:
            log(f"final: {final} already trained for these rounds")
        else:
            log(f"final{f' member {member}' if config.final_members > 1 else ''}: training on {len(all_demos)} "
                f"demonstrations (every training cabinet) and {len(labelled)} labelled rollouts ({steps} steps"
                f"{', from ' + str(init) if init else ''}, seed {config.seed + member})")
            timed("training", seconds, lambda: train_bc(
                all_demos + labelled, hand, replace(bc_config, seed=config.seed + member, steps=steps), out=final,
                progress=progress, threads=threads, init=init))
            done.write_text(json.dumps(wanted) + "\n")
        summary["final"]["members"].append({"checkpoint": str(final), "seed": config.seed + member,
                                            **({"seconds": seconds} if seconds else {})})
    summary["final"]["checkpoint"] = summary["final"]["members"][0]["checkpoint"]
    (folder / "dagger.json").write_text(json.dumps(summary, indent=1) + "\n")
    return summary


def file_sha256(path: Path) -> str:
    """The SHA-256 of a file's bytes (hex)."""
    import hashlib

    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def rollouts_made_by(folder: Path, round_: int, maker: dict) -> bool:
    """Whether round ``round_``'s rollout files in the work ``folder`` (the round's and its revisits',
    with their episode logs) were made by ``maker`` (the policy's SHA-256 and the rollout's settings).
    Files made by another maker (a work folder left by an earlier run whose kept rounds were since
    replaced, or another recipe) are deleted, so that resuming never mixes another policy's states
    into a round; the maker is then written as ``round_<i>.maker.json``. Files from before makers
    were written are taken as this maker's. Returns False where files were deleted."""
    stamp = folder / f"round_{round_}.maker.json"
    files = [*folder.glob(f"round_{round_}.hdf5*"), *folder.glob(f"round_{round_}_revisit_*.hdf5*")]
    agrees = not stamp.is_file() or json.loads(stamp.read_text()) == maker
    if not agrees:
        for f in files:
            f.unlink(missing_ok=True)
    stamp.write_text(json.dumps(maker, indent=1) + "\n")
    return agrees


def save_half(src: Path, dst: Path) -> None:
    """Copy the checkpoint ``src`` of `bc_train.train_bc` to ``dst`` with its weights as float16
    (half the bytes; the policy loads them as float32)."""
    from opend_mj.policy.learned.checkpoint_io import read_checkpoint, write_checkpoint

    ckpt = read_checkpoint(src, "behaviour-cloning policy checkpoint")
    ckpt["model"] = {k: (v.half() if v.is_floating_point() else v) for k, v in ckpt["model"].items()}
    dst.parent.mkdir(parents=True, exist_ok=True)
    tmp = dst.with_suffix(".tmp")
    write_checkpoint(ckpt, tmp)
    tmp.replace(dst)


__all__ = ["DaggerConfig", "Rollout", "best_round", "failed_targets", "file_sha256", "kept_rounds", "rollout_episode", "rollouts_made_by", "run_dagger", "save_half", "split_cabinets",
           "validation_figures"]
