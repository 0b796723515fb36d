"""`opend demos`: the planner's episodes recorded as demonstrations, in the agents' own action space.

Each episode is one `opend run` episode (the same jobs, scenes and seeds: `evaluation.jobs`) of the
planner with a handle solver. Every 60 Hz control step stores what an agent would have observed
before it (`opend_mj.policy.agents`: the hand's own state and touch, the instruction) and the action
the planner sent, in both agent action spaces: ``actions`` (the task's absolute action, which
`opend replay` steps) and ``actions_delta`` (the gymnasium environments' normalised delta action,
clipped to [-1, 1]). The solver's box and the handle it gives in the first image (`policy.learned.bc_model`:
the planner's own back-projection) are stored with every step, and optionally an RGB-D image per step.

With :class:`ActionNoise` on (DART, Laskey et al. 2017, "DART: Noise injection for robust imitation
learning"), the action sent to the scene is the planner's plus a smooth random offset, while the
stored label (``actions``, ``actions_delta``) stays the planner's own, clean action: the planner
then acts from the perturbed states that the hand really reaches (its pull steers from the measured
grasp site, its grasp check reads touch, its waypoints are absolute targets), so the demonstrations
show what to do from slightly wrong states, which a learner's own errors lead it into. The sent
actions are stored as ``actions_executed``, which is what a replay steps.

The file is the robomimic / LIBERO HDF5 layout of `opend_mj.apps.demos` (see there and the docs
page ``docs/demonstrations.md`` for the keys). Successful episodes are kept by default; with
``keep_failures`` the failed ones too, labelled (``success``, ``failed_stage``). Every episode tried
is logged to ``<out>.episodes.jsonl`` (its key, success, whether kept); a resumed recording skips
the demos in the file and the failed episodes of the log (:func:`tried_keys`). Episodes run in ``spawn`` worker processes (an EGL context does not survive fork).
"""

from __future__ import annotations

import json
import math
import time
import zlib
import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from opend_mj.apps.demos import Demo, _episode_json, append_demos, env_args, read_demos
from opend_mj.evaluation.episode import EpisodeJob
from opend_mj.evaluation.jobs import group_jobs
from opend_mj.policy.perception.watch import WatchConfig

#: Per-step observation keys of a planner demonstration (besides optional ``rgb`` / ``depth``).
DEMO_OBS_KEYS = ("hand_qpos", "hand_qvel", "root_pos", "root_quat", "root_vel", "grasp_site_pos", "grasp_site_quat",
                 "mocap_pos", "mocap_quat", "touch", "time", "instruction", "handle_box", "handle_features",
                 "front_watch")


@dataclass(frozen=True)
class ActionNoise:
    """DART noise on the actions sent while recording (labels stay the planner's clean actions).

    Each part is an Ornstein-Uhlenbeck offset (zero at the start, then stationary spread ``pos`` etc.,
    correlation time ``tau``): a hand under a mocap weld filters out step-to-step jitter, so the offset
    has to persist for a fraction of a second to move the hand off the planner's path."""

    pos: float = 0.0  # m: spread of the root target's offset, per axis
    rot: float = 0.0  # rad: spread of the root target's rotation offset, per axis (a rotation vector)
    fingers: float = 0.0  # spread of each finger target's offset, as a fraction of its actuator range
    tau: float = 0.3  # s: correlation time of the offsets

    def __post_init__(self):
        for name in ("pos", "rot", "fingers"):
            if getattr(self, name) < 0:
                raise ValueError(f"action noise {name} must be >= 0, not {getattr(self, name)}")
        if self.tau <= 0:
            raise ValueError(f"action noise tau must be > 0 s, not {self.tau}")

    @property
    def active(self) -> bool:
        return max(self.pos, self.rot, self.fingers) > 0


@dataclass(frozen=True)
class RecordConfig:
    """What `record_demos` keeps, and the noise injected into the recorded planner's actions."""

    image_size: int = 0  # RGB-D of the front camera at every step, this many pixels square (0: none)
    keep_failures: bool = False
    noise: ActionNoise = ActionNoise()
    #: a DAgger round: a policy acts and the planner as an expert labels (`opend_mj.apps.dagger`)
    rollout: object | None = None
    #: how the front is watched while acting (`perception.watch`): stored per step as ``front_watch``
    watch: WatchConfig = field(default_factory=WatchConfig)

    def __post_init__(self):
        if self.image_size and self.image_size < 16:
            raise ValueError(f"image_size must be 0 (no images) or >= 16, not {self.image_size}")


class NoiseProcess:
    """The offsets of :class:`ActionNoise` for one episode, drawn from ``seed`` (deterministic)."""

    def __init__(self, noise: ActionNoise, finger_low, finger_high, dt: float, seed):
        self.noise = noise
        self.low, self.high = np.asarray(finger_low, float), np.asarray(finger_high, float)
        self.rho = math.exp(-dt / noise.tau)  # per-step correlation
        self.scale = np.concatenate([[noise.pos] * 3, [noise.rot] * 3, noise.fingers * (self.high - self.low)])
        self.offset = np.zeros(len(self.scale))
        self.rng = np.random.default_rng(seed)

    def perturb(self, action) -> np.ndarray:
        """The action to send: ``action`` (task action: root pos, quat w x y z, finger targets) plus
        this step's offset (fingers kept inside their actuator ranges)."""
        from opend_mj.transforms import axis_angle_quat, quat_mul

        self.offset = self.rho * self.offset + math.sqrt(1 - self.rho ** 2) * self.scale * \
            self.rng.standard_normal(len(self.scale))
        a = np.asarray(action, float).copy()
        a[:3] += self.offset[:3]
        angle = float(np.linalg.norm(self.offset[3:6]))
        if angle > 1e-12:
            q = quat_mul(axis_angle_quat(self.offset[3:6], angle), a[3:7] / np.linalg.norm(a[3:7]))
            a[3:7] = q / np.linalg.norm(q)
        a[7:] = np.clip(a[7:] + self.offset[6:], self.low, self.high)
        return a


def noise_seed(job: EpisodeJob) -> list[int]:
    """The noise seed of a job: its key (cabinet, target, hand, seed...), hashed stably."""
    return [35, zlib.crc32(json.dumps(list(job.key())).encode())]


def log_path(out: Path) -> Path:
    return Path(str(out) + ".episodes.jsonl")


def _rotvec(q) -> np.ndarray:
    """Rotation vector (rad) of a unit quaternion (w x y z), the short way round."""
    q = np.asarray(q, float)
    if q[0] < 0:
        q = -q
    s = float(np.linalg.norm(q[1:]))
    if s < 1e-12:
        return np.zeros(3)
    return q[1:] / s * 2.0 * math.atan2(s, q[0])


class _RecordingEnv:
    """The scene as the planner steps it, storing the agent's observation and the action of each step."""

    def __init__(self, env, reader, adapter, camera=None, noise: NoiseProcess | None = None, watcher=None,
                 look=None):
        self._env, self._reader, self._adapter, self._camera = env, reader, adapter, camera
        self._noise = noise
        #: the front watched as a learner watches it (`perception.watch`): a look every
        #: ``watcher.config.every`` steps through ``look`` (a depth image of the front camera)
        self._watcher, self._look = watcher, look
        self._n = 0  # control steps taken
        self.style = -1  # the planner's current grasp style (`bc.style_index`), set as each approach starts
        self.styles: list[int] = []  # one per step
        self.obs: dict[str, list] = {}
        self.actions: list[np.ndarray] = []  # the planner's (clean) actions: the labels
        self.executed: list[np.ndarray] = []  # the actions sent (the labels plus noise, where noise is on)
        self.deltas: list[np.ndarray] = []

    def __getattr__(self, name):
        return getattr(self._env, name)

    def step(self, action):
        from opend_mj.evaluation.runner import PhysicsDiverged
        from opend_mj.transforms import quat_mul

        obs = self._reader.proprio()
        for k, v in obs.items():
            self.obs.setdefault(k, []).append(np.array(v, float))
        if self._watcher is not None:
            site, now = obs["grasp_site_pos"], float(obs["time"][0])
            if self._watcher.config.looks_at(self._n):
                self._watcher.look(self._look(), site, now)
            self.obs.setdefault("front_watch", []).append(self._watcher.vector(site, now).astype(float))
        self._n += 1
        if self._camera is not None:
            rgb, depth = self._camera.render()
            self.obs.setdefault("rgb", []).append(rgb)
            self.obs.setdefault("depth", []).append(np.asarray(depth, np.float32))
        a = np.asarray(action, float)
        self.actions.append(a.copy())
        self.styles.append(self.style)
        ad = self._adapter
        conj = obs["mocap_quat"] * np.array([1.0, -1.0, -1.0, -1.0])
        rot = _rotvec(quat_mul(a[3:7] / np.linalg.norm(a[3:7]), conj))
        delta = np.concatenate([(a[:3] - obs["mocap_pos"]) / ad.step_pos, rot / ad.step_rot, ad.fingers_to_unit(a[7:])])
        self.deltas.append(np.clip(delta, -1.0, 1.0))
        sent = self._noise.perturb(a) if self._noise is not None else a
        self.executed.append(sent)
        ts = self._env.step(sent)
        if ts.last():
            raise PhysicsDiverged(f"physics instability: {self._env.task.physics_warnings}")
        return ts


def record_episode(job: EpisodeJob, env=None, config: RecordConfig = RecordConfig()) -> tuple[dict, Demo]:
    """One planner episode of ``job``: (its log line, the demonstration). ``env``: a scene of the
    job's `scene_key` to reuse (as `opend run` reuses them), else one is made."""
    from opend_mj.evaluation.runner import PhysicsDiverged, instruction_for, make_episode_env
    from opend_mj.policy.factory import build_planner
    from opend_mj.policy.learned.bc_model import PERCEPT_DIM, perceive_handle, style_index
    from opend_mj.policy.perception import WATCH_DIM, FrontWatcher
    from opend_mj.policy.planner import Observation, Robot
    from opend_mj.sim.camera import RGBDCamera
    from opend_mj.language import instruction_onehot
    from opend_mj.sim.envs import ActionAdapter, SceneReader

    t0 = time.perf_counter()
    env = env if env is not None else make_episode_env(job)
    env.task.set_target(job.joint, instruction_for(job))
    env.reset()
    task, physics = env.task, env.physics
    size = task.config.image_size
    reader = SceneReader(env, size)
    extra_cam = RGBDCamera(physics, "front", config.image_size, config.image_size) if config.image_size else None
    try:
        with RGBDCamera(physics, "front", size, size) as cam:
            rgb, depth = cam.render()
            view = task.camera_view(physics)
            def on_stage(name, info):  # the grasp style of each approach, for the steps that follow it
                if name == "approach" and "style" in info:
                    rec.style = style_index(info["style"])

            planner = build_planner(job.solver, task.hand.spec.name, pull=job.pull, use_grasp_file=job.use_grasp_file,
                                    ground_truth=lambda: task.handle_boxes(physics)[task.target.joint],
                                    on_stage=on_stage)
            percept = perceive_handle(planner.solver, rgb, depth, task.instruction, view, planner.config)
            adapter = ActionAdapter(job.hand, task.config)
            noise = NoiseProcess(config.noise, adapter.finger_low, adapter.finger_high, task.control_timestep,
                                 noise_seed(job)) if config.noise.active else None
            watcher = FrontWatcher.from_percept(depth, view, percept, config.watch) if percept is not None else None
            rec = _RecordingEnv(env, reader, adapter, extra_cam, noise, watcher, look=lambda: cam.render()[1])
            robot = Robot(rec, look=lambda: cam.render()[1])
            diverged = None
            try:
                plan = planner.run(robot, Observation(rgb=rgb, depth=depth, instruction=task.instruction,
                                                      camera_view=view))
            except PhysicsDiverged as exc:
                plan, diverged = None, str(exc)
    finally:
        reader.close()
        if extra_cam is not None:
            extra_cam.close()
    outcome = task.outcome(physics)
    n = len(rec.actions)
    success = bool(outcome.success) and diverged is None
    failed = None if success else ("physics" if diverged else (plan.failed_stage or "pull"))
    box = np.asarray(percept.box.as_tuple() if percept is not None else (np.nan,) * 4, float)
    feats = percept.vector() if percept is not None else np.full(PERCEPT_DIM, np.nan)
    obs = {k: np.asarray(v) for k, v in rec.obs.items()}
    obs["instruction"] = np.repeat(instruction_onehot(task.instruction)[None].astype(np.float64), n, axis=0)
    obs["handle_box"] = np.repeat(box[None], n, axis=0)
    obs["handle_features"] = np.repeat(feats[None], n, axis=0)
    if "front_watch" not in obs:  # no handle located: nothing watched
        obs["front_watch"] = np.full((n, WATCH_DIM), np.nan)
    key = list(job.key())
    attrs = {
        "instruction": str(task.instruction), "cabinet": job.cabinet, "cabinet_dir": str(Path(job.cabinet_dir).resolve()),
        "target_joint": job.joint, "target_type": str(task.target.kind), "hand": job.hand, "solver": job.solver,
        "split": job.split, "seed": int(job.seed), "room": int(task.episode.room_index()), "success": success,
        "failed_stage": failed or "", "open_ratio": float(outcome.open_ratio), "joint_value": float(outcome.joint_value),
        "num_samples": n, "episode": _episode_json(task.episode), "sim_seconds": float(physics.data.time),
        "wall_seconds": float(time.perf_counter() - t0), "job_key": json.dumps(key),
        "handle_kind": percept.handle.kind if percept is not None else "",
        "handle_orientation": percept.handle.orientation if percept is not None else "",
        "hinge_seen": (percept.hinge or "") if percept is not None else "",
        "action_noise": json.dumps(dataclasses.asdict(config.noise)) if config.noise.active else "",
        "watch_every": int(config.watch.every) if percept is not None else 0,
    }
    extra = {"actions_delta": np.asarray(rec.deltas, float).reshape(n, -1),
             "grasp_style": np.asarray(rec.styles, np.int8).reshape(n)}
    if config.noise.active:
        extra["actions_executed"] = np.asarray(rec.executed, float).reshape(n, -1)
    demo = Demo(actions=np.asarray(rec.actions, float).reshape(n, -1), obs=obs, attrs=attrs,
                final={k: np.asarray(v)[None] for k, v in reader.proprio().items()},
                extra=extra)
    demo.env_args = env_args(task.config)  # type: ignore[attr-defined]
    line = {"key": key, "cabinet": job.cabinet, "joint": job.joint, "hand": job.hand, "solver": job.solver,
            "seed": job.seed, "split": job.split, "success": success, "failed_stage": failed,
            "open_ratio": round(float(outcome.open_ratio), 4), "steps": n, "wall_seconds": round(attrs["wall_seconds"], 2)}
    return line, demo


def _record_group(args) -> list[tuple[dict, Demo | None]]:
    """Worker: the episodes of one scene, one scene built for all (a fresh one after an error)."""
    from opend_mj.evaluation.runner import error_reason, make_episode_env

    jobs, config = args
    out, env = [], None
    for job in jobs:
        try:
            env = env or make_episode_env(job)
            if config.rollout is not None:  # a DAgger round (`apps.dagger.Rollout`)
                line, demo = config.rollout.episode(job, env, config)
                line["kept"] = demo is not None
                out.append((line, demo))
                continue
            line, demo = record_episode(job, env, config)
            keep = line["success"] or config.keep_failures
            line["kept"] = keep
            out.append((line, demo if keep else None))
        except Exception as exc:  # noqa: BLE001 (one bad episode must not stop a recording)
            env = None
            out.append(({"key": list(job.key()), "cabinet": job.cabinet,
                         "joint": job.joint, "hand": job.hand, "seed": job.seed, "success": False, "kept": False,
                         "error": error_reason(exc)}, None))
    return out


def _worker_init() -> None:
    from opend_mj.backends import worker_init

    worker_init()


def tried_keys(out: Path) -> set[tuple]:
    """The job keys a recording into ``out`` has done: those of the demos in the file, and those its
    log (``<out>.episodes.jsonl``) says were tried and not kept. A kept episode that the log has but the
    file lacks (a recording killed while writing) is not done; a torn last log line (killed while
    logging) is dropped from the log, so that new lines start on a line of their own."""
    from opend_mj.apps.demos import _demo_names, open_demo_file

    out = Path(out)
    done: set[tuple] = set()
    if out.exists():
        with open_demo_file(out) as f:
            g = f["data"]
            for name in _demo_names(g):
                key = g[name].attrs.get("job_key")
                if key is not None:
                    done.add(tuple(json.loads(key)))
    log = log_path(out)
    if log.exists():
        text = log.read_bytes()
        if text and not text.endswith(b"\n"):
            text = text[:text.rfind(b"\n") + 1]
            with open(log, "r+b") as f:
                f.truncate(len(text))
        for line in text.decode().splitlines():
            if not line.strip():
                continue
            entry = json.loads(line)
            if not entry.get("kept"):
                done.add(tuple(entry["key"]))
    return done


def record_demos(jobs: list[EpisodeJob], out: Path, workers: int = 1, config: RecordConfig = RecordConfig(),
                 progress: bool = True, flush_every: int = 16) -> dict:
    """Record the jobs not yet tried (:func:`tried_keys`) into ``out`` (HDF5; a killed recording
    resumes without losing or repeating an episode).

    Returns counts: total, skipped (tried before), ran, kept, success, errors."""
    from tqdm import tqdm

    out = Path(out)
    log = log_path(out)
    done = tried_keys(out)
    todo = [j for j in jobs if tuple(j.key()) not in done]
    counts = {"total": len(jobs), "skipped": len(jobs) - len(todo), "ran": 0, "kept": 0, "success": 0, "errors": 0}
    if not todo:
        return counts
    groups = [(g, config) for g in group_jobs(todo)]
    pending: list[tuple[dict, Demo | None]] = []
    bar = tqdm(total=len(todo), desc="demos", unit="ep", disable=not progress)

    def flush():
        batch = list(pending)
        pending.clear()  # a failed write is not retried by the final flush (no demo twice)
        demos = [d for _, d in batch if d is not None]
        if demos:
            append_demos(out, demos)  # the file first: a kill before the log lines costs no demo
        log.parent.mkdir(parents=True, exist_ok=True)
        with open(log, "a") as f:
            for line, _ in batch:
                f.write(json.dumps(line) + "\n")

    def take(results):
        for line, demo in results:
            counts["ran"] += 1
            counts["kept"] += demo is not None
            counts["success"] += bool(line.get("success"))
            counts["errors"] += "error" in line
            pending.append((line, demo))
            bar.update(1)
        bar.set_postfix(kept=counts["kept"], success=f"{counts['success']}/{counts['ran']}")
        if len(pending) >= flush_every:
            flush()

    try:
        if workers <= 1:
            for g in groups:
                take(_record_group(g))
        else:
            import multiprocessing as mp

            with mp.get_context("spawn").Pool(workers, initializer=_worker_init) as pool:
                for results in pool.imap(_record_group, groups):
                    take(results)
    finally:
        flush()
        bar.close()
    return counts


#: The observation keys behaviour cloning reads (`policy.learned.bc_model`), and the watched front
#: (`perception.watch`), read where a file has it (a policy that watches needs it: `bc_train`).
TRAINING_KEYS = ("grasp_site_pos", "grasp_site_quat", "mocap_pos", "mocap_quat", "root_vel", "hand_qpos", "touch",
                 "time", "handle_features")
WATCH_KEY = "front_watch"


def load_training_demos(paths, max_demos: int | None = None, successes_only: bool = True,
                        kind: str | None = None, hand: str | None = None) -> list[Demo]:
    """The demos of one or more files with only the keys training reads (float32 where they are float),
    in file order, at most ``max_demos`` of them (counting the kept ones only); with ``kind``
    ("drawer" or "door") only those whose instruction names that kind of target. With ``hand``, a
    file holding demos of another hand is refused (:class:`~opend_mj.apps.demos.DemoFileError`, as
    are truncated files and files of another format version)."""
    from opend_mj.apps.demos import DemoFileError, _damaged, _demo_names, _h5_value, _is_hdf5, open_demo_file
    from opend_mj.language import target_kind

    def wanted(attrs) -> bool:
        return (attrs.get("success") or not successes_only) and (
            kind is None or target_kind(str(attrs.get("instruction", ""))) == kind)

    def check_hand(path, attrs) -> None:
        if hand is not None and attrs.get("hand") != hand:
            raise DemoFileError(f"{path}: demonstrations of the {attrs.get('hand')} hand, but training is for "
                                f"the {hand} hand (--hand)")

    out: list[Demo] = []
    for path in [paths] if isinstance(paths, (str, Path)) else paths:
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no demonstrations file; record one with `opend demos --out {path}`")
        if not _is_hdf5(path):
            _, demos = read_demos(path)
            for d in demos:
                check_hand(path, d.attrs)
            out += [d for d in demos if wanted(d.attrs)]
            continue
        with open_demo_file(path) as f:
            g = f["data"]
            try:
                for name in _demo_names(g):
                    d = g[name]
                    attrs = {k: _h5_value(v) for k, v in d.attrs.items()}
                    check_hand(path, attrs)
                    if not wanted(attrs):
                        continue
                    missing = [k for k in TRAINING_KEYS if k not in d["obs"]]
                    if missing:
                        raise DemoFileError(f"{path}: {name} has no obs/{missing[0]} (not recorded by `opend demos`)")
                    obs = {k: d["obs"][k][()].astype(np.float32) for k in TRAINING_KEYS}
                    if WATCH_KEY in d["obs"]:  # recorded by `opend demos` since the front is watched
                        obs[WATCH_KEY] = d["obs"][WATCH_KEY][()].astype(np.float32)
                    extra = {"grasp_style": d["grasp_style"][()]} if "grasp_style" in d else {}
                    out.append(Demo(actions=d["actions"][()], obs=obs, attrs=attrs, extra=extra))
                    if max_demos is not None and len(out) >= max_demos:
                        return out
            except (OSError, KeyError, RuntimeError) as exc:
                raise _damaged(path, exc) from None
    return out[:max_demos] if max_demos is not None else out


def demo_jobs(cabinets_dir, hands, solver: str = "oracle", split: str = "train", seeds=(0,), limit=None,
              cabinet_ids=None, pull: str = "arc", perturb: str | None = None) -> list[EpisodeJob]:
    """The episodes of a recording: `opend run`'s jobs for every seed (under the canonical
    perturbation ``perturb``, `sim.perturb.parse_perturb`; None: the nominal scenes)."""
    from opend_mj.evaluation.jobs import make_jobs

    return [job for seed in dict.fromkeys(seeds)
            for job in make_jobs(cabinets_dir, hands, solver, split=split, seed=seed, limit=limit,
                                 cabinet_ids=cabinet_ids, pull=pull, perturb=perturb)]


__all__ = ["ActionNoise", "DEMO_OBS_KEYS", "NoiseProcess", "RecordConfig", "TRAINING_KEYS", "demo_jobs",
           "load_training_demos", "log_path", "noise_seed", "record_demos", "record_episode", "tried_keys"]
