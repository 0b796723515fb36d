"""Episode runner, parallel pool and the resumable results file (`opend run`).

One episode = (cabinet, target joint, hand, solver, seed, light scale, pull strategy). The runner
builds the task, renders the one front RGB-D image, runs the planner and records a JSON line.
Ground truth is used here only to label results (failure stage, success); the planner never sees it
(except through the ``oracle`` solver, whose whole point is to hand it the true box).

Results file: one JSON object per line, written by the parent process only, one ``write()`` of a
full line, then flush and ``os.fsync``. On load, a torn last line (no newline, or not JSON) is
dropped and truncated away, so after ``kill -9`` a rerun neither loses nor repeats an episode.
Records arrive in completion order while a run is going (so nothing is held back in memory); when
every job of the run is in the file, the file is rewritten (atomically: temporary file, fsync,
rename) in job order, so that the same command gives the same file whatever ``--workers`` or
``--backend`` (only ``wall_seconds`` differs). Records of other runs sharing the file keep their
place, before this run's.

Reliability: an episode never stops the run. A cabinet whose files are missing or corrupt (checked
cheaply in the parent: ``cabinet.json`` parses, ``cabinet.xml`` is well-formed XML; deeper faults
surface in the worker as ``CabinetError``) gives error records with ``error_reason`` naming the
file; a task that raises (e.g. a non-finite action: ``ValueError: action has non-finite values``)
gives an error record; a MuJoCo instability (BADQACC/BADQPOS/BADQVEL, or NaN state) ends the episode
as a failure with ``failed_stage = "physics"`` and the warnings in ``physics_warnings``. Error
records count as done on resume (delete their lines to retry them).
"""

from __future__ import annotations

import json
import os
import time
import traceback
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Iterable

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402

KEY_FIELDS = ("cabinet", "joint", "hand", "solver", "seed", "light_scale", "pull")
#: Fields that depend on the machine and the clock, not on the episode (left out when comparing runs).
WALL_CLOCK_FIELDS = ("wall_seconds",)
_BASE_FIELDS = ("cabinet", "joint", "hand", "solver", "split", "seed", "light_scale", "pull")


@dataclass(frozen=True)
class EpisodeJob:
    cabinet: str
    cabinet_dir: str
    joint: str
    split: str
    hand: str
    solver: str
    seed: int = 0
    light_scale: float = 1.0
    pull: str = "arc"
    video_dir: str | None = None
    room: int | None = None
    planner_overrides: tuple = ()  # ((field, value), ...) for grasp search / experiments
    use_grasp_file: bool = True
    #: From the manifest, so that even an episode that could not run is scored in its column.
    target_type: str | None = None
    instruction: str | None = None
    #: 0: the Algorithm 1 instruction; k > 0: the k-th paraphrase template (language.PARAPHRASES)
    paraphrase: int = 0
    #: Physics timestep in seconds; None: TaskConfig's default.
    physics_timestep: float | None = None

    def key(self) -> tuple:
        return episode_key(asdict(self))


def episode_key(record: dict) -> tuple:
    return (str(record["cabinet"]), str(record["joint"]), str(record["hand"]), str(record["solver"]),
            int(record["seed"]), round(float(record.get("light_scale", 1.0)), 6), str(record.get("pull", "arc")),
            int(record.get("paraphrase", 0)),
            None if record.get("physics_timestep") is None else round(float(record["physics_timestep"]), 9))


# --------------------------------------------------------------------------------------------------
# Results file
# --------------------------------------------------------------------------------------------------
def load_results(path: Path, repair: bool = True) -> list[dict]:
    """All complete records of a results file; a torn last line is dropped (and truncated away)."""
    path = Path(path)
    if not path.exists():
        return []
    data = path.read_bytes()
    records: list[dict] = []
    good_end = 0
    pos = 0
    while pos < len(data):
        nl = data.find(b"\n", pos)
        if nl < 0:  # last line without newline: torn
            break
        line = data[pos:nl]
        pos = nl + 1
        if line.strip():
            try:
                records.append(json.loads(line))
            except json.JSONDecodeError:
                if pos >= len(data):  # a torn last line that happens to end in a newline
                    break
                raise ValueError(f"{path}: corrupt line in the middle of the file at byte {pos}")
        good_end = pos
    if repair and good_end < len(data):
        with open(path, "r+b") as f:
            f.truncate(good_end)
            f.flush()
            os.fsync(f.fileno())
    return records


class ResultsWriter:
    """Appends one record per line: one write of the full line, flush, fsync (parent process only)."""

    def __init__(self, path: Path):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)

    def write(self, record: dict) -> None:
        line = (json.dumps(record, default=_json_default) + "\n").encode()
        n = os.write(self._fd, line)
        if n != len(line):
            raise OSError(f"short write to {self.path}")
        os.fsync(self._fd)

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o)}")


# --------------------------------------------------------------------------------------------------
# Jobs
# --------------------------------------------------------------------------------------------------
def make_jobs(cabinets_dir: Path, hands: Iterable[str], solver: str, split: str = "test", seed: int = 0,
              light_scale: float = 1.0, pull: str = "arc", limit: int | None = None,
              video_dir: Path | None = None, cabinet_ids: Iterable[str] | None = None,
              paraphrase: int = 0, physics_timestep: float | None = None) -> list[EpisodeJob]:
    from opend_mj.dataset import load_manifest

    cabinets_dir = Path(cabinets_dir)
    manifest = load_manifest(cabinets_dir)
    pairs = manifest.targets(split)
    if cabinet_ids is not None:
        ids = set(cabinet_ids)
        pairs = [(c, t) for c, t in pairs if c["id"] in ids]
    if limit is not None:
        pairs = pairs[:limit]
    jobs = []
    for hand in hands:
        for cab, tgt in pairs:
            cab_dir = cabinets_dir / cab.get("path", cab["id"]) if not Path(cab.get("path", "")).is_absolute() \
                else Path(cab["path"])
            if not (cab_dir / "cabinet.json").is_file():
                cab_dir = cabinets_dir / cab["id"]
            jobs.append(EpisodeJob(cabinet=cab["id"], cabinet_dir=str(cab_dir), joint=tgt["joint"],
                                   split=cab["split"], hand=hand, solver=solver, seed=seed,
                                   light_scale=light_scale, pull=pull,
                                   video_dir=str(video_dir) if video_dir else None,
                                   target_type=tgt.get("type"), instruction=tgt.get("instruction"),
                                   paraphrase=paraphrase, physics_timestep=physics_timestep))
    return jobs


# --------------------------------------------------------------------------------------------------
# One episode
# --------------------------------------------------------------------------------------------------
def _box_contains(box, u, v, pad=3.0) -> bool:
    return box is not None and box[0] - pad <= u <= box[2] + pad and box[1] - pad <= v <= box[3] + pad


def run_episode(job: EpisodeJob, env=None) -> dict:
    """Run one episode; returns its record (never raises: errors become an ``error`` record)."""
    t0 = time.perf_counter()
    try:
        record = _run_episode(job, env)
    except Exception as exc:  # noqa: BLE001 (an episode's failure must not stop the run)
        record = error_record(job, exc)
    out = {**_base(job), **record}
    out["wall_seconds"] = round(time.perf_counter() - t0, 3)
    return out


def run_episode_group(jobs: tuple[EpisodeJob, ...] | list[EpisodeJob]) -> list[dict]:
    """Run episodes that share one `scene_key` on one scene, built once (the unit of work of a run).

    Building a scene (room, cabinet, hand, compile) costs about as much as simulating an episode;
    the episodes of one cabinet's targets differ only in the target and the instruction, and each
    starts from a full reset, so their records are the same as with a scene each.
    """
    records = []
    env = None
    for job in jobs:
        if env is None:
            t0 = time.perf_counter()
            try:
                env = _make_env(job)
            except Exception as exc:  # noqa: BLE001 (reported per episode; nothing else can run here)
                records.append({**error_record(job, exc), "wall_seconds": round(time.perf_counter() - t0, 3)})
                continue
            build_s = time.perf_counter() - t0
            rec = run_episode(job, env)
            rec["wall_seconds"] = round(rec["wall_seconds"] + build_s, 3)
        else:
            rec = run_episode(job, env)
        records.append(rec)
        if rec.get("failed_stage") == "physics" or "error" in rec:
            env = None  # a diverged or failed episode: the next one gets a fresh scene
    return records


def group_jobs(jobs: list[EpisodeJob], max_size: int = 8) -> list[tuple[EpisodeJob, ...]]:
    """Consecutive jobs with the same `scene_key`, in order, at most ``max_size`` per group."""
    groups: list[list[EpisodeJob]] = []
    for job in jobs:
        if groups and len(groups[-1]) < max_size and scene_key(groups[-1][-1]) == scene_key(job):
            groups[-1].append(job)
        else:
            groups.append([job])
    return [tuple(g) for g in groups]


def _base(job: EpisodeJob) -> dict:
    base = {k: getattr(job, k) for k in _BASE_FIELDS}
    if job.paraphrase:
        base["paraphrase"] = job.paraphrase
    if job.physics_timestep is not None:
        base["physics_timestep"] = job.physics_timestep
    for k in ("target_type", "instruction"):
        if getattr(job, k) is not None:
            base[k] = getattr(job, k)
    return base


def error_reason(exc: BaseException | str) -> str:
    """One line saying what went wrong (the exception type and message; a file is named in it)."""
    if isinstance(exc, str):  # a traceback's text: its last non-empty line
        lines = [ln for ln in exc.strip().splitlines() if ln.strip()]
        return lines[-1].strip() if lines else "unknown error"
    return f"{type(exc).__name__}: {exc}".splitlines()[0] if str(exc) else type(exc).__name__


def error_record(job: EpisodeJob, exc: BaseException | str) -> dict:
    """The record of an episode that could not run: ``error`` (traceback) and ``error_reason`` (one line)."""
    if isinstance(exc, str):
        tb = exc
    else:
        tb = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
        if not tb.startswith("Traceback"):
            tb = "Traceback (most recent call last):\n" + tb
    return {**_base(job), "success": False, "error": tb, "error_reason": error_reason(exc),
            "error_kind": _error_kind(exc)}


def _error_kind(exc) -> str:
    from opend_mj.cabinet import CabinetError

    if isinstance(exc, CabinetError) or (isinstance(exc, str) and "CabinetError" in exc):
        return "cabinet"
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


def scene_key(job: EpisodeJob) -> tuple:
    """Episodes with the same key share one compiled scene (room, cabinet, hand, physics)."""
    return (job.cabinet_dir, job.hand, job.seed, job.room, round(float(job.light_scale), 6),
            None if job.physics_timestep is None else round(float(job.physics_timestep), 9))


def _instruction_for(job: EpisodeJob) -> str | None:
    """The job's paraphrased instruction, or None for the target's own (Algorithm 1)."""
    if not job.paraphrase:
        return None
    from opend_mj.cabinet import load_cabinet_info
    from opend_mj.language import Description, paraphrase

    target = next(t for t in load_cabinet_info(Path(job.cabinet_dir))["targets"] if t["joint"] == job.joint)
    return paraphrase(Description(target["vertical"], target["horizontal"], target["type"]), job.paraphrase)


def _make_env(job: EpisodeJob):
    from opend_mj.task import EpisodeSpec, TaskConfig, make_environment

    spec_ep = EpisodeSpec(cabinet_dir=Path(job.cabinet_dir), target_joint=job.joint, hand=job.hand,
                          seed=job.seed, room=job.room, instruction=_instruction_for(job))
    config = TaskConfig(enable_rgbd=False, light_scale=job.light_scale, time_limit=1e6)
    if job.physics_timestep is not None:
        config = replace(config, physics_timestep=float(job.physics_timestep))
    return make_environment(spec_ep, config)


def _run_episode(job: EpisodeJob, env=None) -> dict:
    """One episode. ``env``: a scene built for a job with the same `scene_key` (else a new one)."""
    from opend_mj.camera import RGBDCamera
    from opend_mj.hands import load_spec
    from opend_mj.planner import GraspProfile, Observation, Planner, PlannerConfig, Robot
    from opend_mj.solvers import get_solver, needs_ground_truth

    if env is None:
        env = _make_env(job)
    else:
        env.task.set_target(job.joint, _instruction_for(job))
    task = env.task
    config = task.config
    env.reset()
    physics = env.physics
    target = task.target
    instruction = task.instruction

    # the one observation
    cam = RGBDCamera(physics, "front", config.image_size, config.image_size)
    try:
        rgb, depth = cam.render()
    finally:
        cam.close()
    view = task.camera_view(physics)
    gt_box = task.handle_boxes(physics)[target.joint]

    options = {}
    if needs_ground_truth(job.solver):
        options["ground_truth"] = lambda: task.handle_boxes(physics)[target.joint]
    solver = get_solver(job.solver, **options)

    # ground-truth probes for labelling only
    probes: dict = {}

    def true_handle_box():
        corners = task.handle_corners(physics)
        return corners.min(axis=0), corners.max(axis=0)

    def on_stage(name, info):
        if name == "grasp":
            lo, hi = true_handle_box()
            site = physics.bind(task.hand.grasp_site).xpos.copy()
            outside = np.maximum(0.0, np.maximum(lo - site, site - hi))
            probes["site_to_handle"] = float(np.linalg.norm(outside))
            probes["t_grasp"] = float(physics.data.time)
        elif name == "pull":
            probes["q_pull_start"] = task.outcome(physics).range_ratio
            probes["t_pull"] = float(physics.data.time)

    video = _VideoRecorder(job, physics, config, task.cabinet.bounds) if job.video_dir else None
    penetration = _PenetrationProbe(physics.data.ptr)

    def on_step():
        penetration()
        if video:
            video.capture()

    robot = Robot(_StopAtLast(env), on_step=on_step)
    overrides = dict(job.planner_overrides)
    pconfig = replace(PlannerConfig(pull=job.pull))
    grasp = GraspProfile.load(job.hand) if job.use_grasp_file else None
    if grasp is not None:
        pconfig = grasp.apply(pconfig)
    if overrides:
        pconfig = replace(pconfig, **overrides)
        grasp = None if "close_scale" in overrides or "grasp_depth" in overrides else grasp
    planner = Planner(solver, load_spec(job.hand), pconfig, grasp=None, on_stage=on_stage)
    if grasp is not None:
        planner.grasp = grasp  # knob orientation
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
    failed = None
    if not outcome.success:
        box = plan.box["box"] if plan.box else None
        if box is None or gt_box is None or not _box_contains(gt_box, (box[0] + box[2]) / 2, (box[1] + box[3]) / 2):
            failed = "locate"
        elif probes.get("site_to_handle", 1.0) > 0.02:
            failed = "approach"
        elif outcome.range_ratio < 0.03:
            failed = "grasp"
        else:
            failed = "pull"
    return {
        "cabinet_dir": job.cabinet_dir,
        "target_type": target.kind,
        "instruction": instruction,
        "room": task.episode.room_index(),
        "success": bool(outcome.success),
        "open_ratio": float(outcome.open_ratio),
        "range_ratio": float(outcome.range_ratio),
        "joint_value": float(outcome.joint_value),
        "others_moved": list(outcome.others_moved),
        "failed_stage": failed,
        "planner_failed_stage": plan.failed_stage,
        "handle_kind": plan.handle["kind"] if plan.handle else None,
        "handle_orientation": plan.handle["orientation"] if plan.handle else None,
        "box": plan.box["box"] if plan.box else None,
        "gt_box": [round(x, 2) for x in gt_box] if gt_box else None,
        "site_to_handle": round(probes.get("site_to_handle", float("nan")), 4),
        "pulled": round(plan.pulled, 4),
        "turned_deg": round(plan.turned_deg, 2),
        "sim_seconds": round(float(physics.data.time), 3),
        "max_penetration_mm": round(penetration.deepest * 1000, 2),
        "physics_warnings": list(warnings),
        "video": str(video.path) if video else None,
    }


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
        "failed_stage": "physics",
        "planner_failed_stage": None,
        "gt_box": [round(x, 2) for x in gt_box] if gt_box else None,
        "sim_seconds": round(float(physics.data.time), 3),
        "physics_warnings": list(warnings),
        "failure_reason": reason,
        "video": None,
    }


class _PenetrationProbe:
    """Deepest contact penetration seen at the end of any control step (metres): how soft the
    contacts are in practice (a coarser physics timestep makes them softer)."""

    def __init__(self, data):
        self._data = data
        self.deepest = 0.0

    def __call__(self) -> None:
        if self._data.ncon:
            deepest = -float(self._data.contact.dist.min())
            if deepest > self.deepest:
                self.deepest = deepest


class _VideoRecorder:
    """Front camera and a side view side by side, every few control steps, written as MP4."""

    def __init__(self, job: EpisodeJob, physics, config, bounds, every: int = 2, size: int = 256):
        import mujoco

        from opend_mj.camera import make_renderer

        self.physics = physics
        self.every = every
        self.frames: list[np.ndarray] = []
        self.n = 0
        name = f"{job.cabinet}_{job.joint}_{job.hand}_{job.solver}_s{job.seed}_l{job.light_scale:g}_{job.pull}.mp4"
        self.path = Path(job.video_dir) / name
        self.fps = int(round(config.control_hz / every))
        m, d = physics.model.ptr, physics.data.ptr
        self._m, self._d = m, d
        self._renderer = make_renderer(m, height=size, width=size)
        self._front = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_CAMERA, "front")
        if self._front < 0:
            self._front = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_CAMERA, "front/front")
        cam = mujoco.MjvCamera()
        cam.type = mujoco.mjtCamera.mjCAMERA_FREE
        # look at the cabinet from its front-right side
        lo, hi = (np.asarray(b, float) for b in bounds)
        cam.lookat[:] = [lo[0] - 0.2, 0.5 * (lo[1] + hi[1]), 0.5 * (lo[2] + hi[2])]
        cam.distance = float(1.2 + 1.0 * max(hi[1] - lo[1], hi[2] - lo[2]))
        cam.azimuth = 25.0
        cam.elevation = -50.0
        self._side = cam
        self.capture(force=True)

    def capture(self, force: bool = False) -> None:
        self.n += 1
        if not force and self.n % self.every:
            return
        r = self._renderer
        cams = []
        if self._front >= 0:
            r.update_scene(self._d, camera=self._front)
            cams.append(r.render().copy())
        r.update_scene(self._d, camera=self._side)
        cams.append(r.render().copy())
        self.frames.append(np.concatenate(cams, axis=1))

    def close(self) -> None:
        import imageio.v2 as imageio

        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        if self.frames:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            imageio.mimwrite(str(self.path), self.frames, fps=self.fps, codec="libx264", macro_block_size=1)
            self.frames = []


# --------------------------------------------------------------------------------------------------
# The pool
# --------------------------------------------------------------------------------------------------
def _worker_init() -> None:
    from opend_mj.backends import worker_init

    worker_init()


def check_cabinet_files(cabinet_dir: str | Path) -> None:
    """Cheap checks of a compiled cabinet folder in the parent; raises ``CabinetError`` naming the file."""
    import xml.etree.ElementTree as ET

    from opend_mj.cabinet import CABINET_XML, CabinetError, load_cabinet_info

    load_cabinet_info(Path(cabinet_dir))
    xml_path = Path(cabinet_dir) / CABINET_XML
    try:
        ET.parse(xml_path)
    except FileNotFoundError as exc:
        raise CabinetError(f"{xml_path}: missing") from exc
    except (ET.ParseError, OSError) as exc:
        raise CabinetError(f"{xml_path}: corrupt MJCF ({exc})") from exc


def run_jobs(jobs: list[EpisodeJob], out: Path, workers: int = 1, progress: bool = True,
             backend: str = "local", address: str | None = None, executor=None, sort: bool = True) -> dict:
    """Run the jobs not yet in ``out`` (resumable) and append their records. Returns counts.

    ``backend``: ``"local"`` (this process when ``workers == 1``, else a spawn pool of ``workers``)
    or ``"ray"`` (``address`` of a cluster, or a local Ray instance); or pass an ``executor`` from
    `opend_mj.backends`. Only this process writes ``out``. With ``sort``, the file ends in job order.
    """
    from tqdm import tqdm

    from opend_mj.backends import make_executor

    out = Path(out)
    done = {episode_key(r) for r in load_results(out)}
    seen = set()
    todo = []
    for j in jobs:
        k = j.key()
        if k in done or k in seen:
            continue
        seen.add(k)
        todo.append(j)
    counts = {"total": len(jobs), "skipped": len(jobs) - len(todo), "ran": 0, "errors": 0, "success": 0}
    if not todo:
        if sort:
            sort_results(out, jobs)
        return counts
    bar = tqdm(total=len(todo), desc="episodes", unit="ep", disable=not progress, dynamic_ncols=True)

    # cabinets whose files are broken: their episodes become error records without running
    broken: dict[str, BaseException] = {}
    for cab_dir in dict.fromkeys(j.cabinet_dir for j in todo):
        try:
            check_cabinet_files(cab_dir)
        except Exception as exc:  # noqa: BLE001 (CabinetError, or anything odd about the folder)
            broken[cab_dir] = exc
    runnable = [j for j in todo if j.cabinet_dir not in broken]

    with ResultsWriter(out) as writer:
        def record(rec: dict) -> None:
            writer.write(rec)
            counts["ran"] += 1
            counts["errors"] += int("error" in rec)
            counts["success"] += int(bool(rec.get("success")))
            bar.update(1)
            bar.set_postfix(success=f"{counts['success']}/{counts['ran']}")

        for j in todo:
            if j.cabinet_dir in broken:
                exc = broken[j.cabinet_dir]
                record({**error_record(j, exc), "wall_seconds": 0.0})
                if progress:
                    bar.write(f"skipped {j.cabinet}/{j.joint}: {error_reason(exc)}")
        if runnable:
            ex = executor if executor is not None else make_executor(backend, workers, address,
                                                                     initializer=_worker_init)
            try:
                for group, recs, err in ex.imap_unordered(run_episode_group, group_jobs(runnable)):
                    if err is not None:
                        recs = [{**error_record(j, err), "wall_seconds": None} for j in group]
                    for rec in recs:
                        record(rec)
            finally:
                if executor is None:
                    ex.close()
    bar.close()
    if sort:
        sort_results(out, jobs)
    return counts


def sort_results(path: Path, jobs: list[EpisodeJob]) -> bool:
    """Rewrite ``path`` with this run's records in job order (others first, in their order).

    Atomic (a temporary file, fsync, rename), so a ``kill -9`` leaves either the old or the new file.
    Returns whether the file was rewritten (not when it is already in order, or jobs are missing).
    """
    path = Path(path)
    records = load_results(path)
    if not records:
        return False
    index = {j.key(): i for i, j in enumerate(jobs)}
    if not set(index) <= {episode_key(r) for r in records}:
        return False  # an incomplete run: leave the file as it is
    lines = [ln for ln in path.read_bytes().split(b"\n") if ln.strip()]
    if len(lines) != len(records):
        return False
    order = sorted(range(len(records)), key=lambda i: (1, index[k], i) if (k := episode_key(records[i])) in index
                   else (0, 0, i))
    if order == list(range(len(records))):
        return False
    tmp = path.with_name(f".{path.name}.sorting")
    with open(tmp, "wb") as f:
        f.write(b"".join(lines[i] + b"\n" for i in order))
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)
    try:
        dir_fd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(dir_fd)
        finally:
            os.close(dir_fd)
    except OSError:
        pass
    return True


def strip_wall_clock(record: dict) -> dict:
    """A record without its machine- and clock-dependent fields (to compare runs)."""
    return {k: v for k, v in record.items() if k not in WALL_CLOCK_FIELDS}


__all__ = ["EpisodeJob", "KEY_FIELDS", "PhysicsDiverged", "ResultsWriter", "WALL_CLOCK_FIELDS",
           "check_cabinet_files", "episode_key", "error_reason", "error_record", "load_results", "make_jobs",
           "run_episode", "run_jobs", "sort_results", "strip_wall_clock"]
