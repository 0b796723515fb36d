"""Demonstrations: recording teleoperated episodes, the file format, deterministic replay.

File format
-----------
The robomimic / LIBERO layout, in HDF5 (``.hdf5`` / ``.h5``, needs ``h5py``) or in NumPy ``.npz``
(any other suffix; no extra dependency) with the same paths as keys::

    data/                                   group; attrs: total (samples over all demos),
                                            env_args (JSON, below), format ("opend-mj-demos"),
                                            format_version (2)
    data/demo_<i>/actions                   float64 (T, A): the task action of step t
                                            [root x, y, z, root quat w, x, y, z, finger targets...]
    data/demo_<i>/obs/hand_joint_pos        float32 (T, n_fingers): finger joint positions before step t
    data/demo_<i>/obs/root_pos              float32 (T, 3): hand root position (world) before step t
    data/demo_<i>/obs/root_quat             float32 (T, 4): hand root orientation (w x y z)
    data/demo_<i>/obs/open_ratio            float32 (T,): target open ratio before step t
    data/demo_<i>/obs/rgb                   uint8 (T, H, W, 3), only when the env config has RGB-D on
    data/demo_<i>/final/<key>               the same observation keys after the last step (1 sample)
    data/demo_<i>/<name>                    other per-step arrays of a recorder (``Demo.extra``), e.g.
                                            ``actions_delta`` of `opend demos` (apps.planner_demos)
    data/demo_<i>  attrs                    instruction, cabinet (id), cabinet_dir, target_joint,
                                            target_type, hand, seed, room (resolved preset index),
                                            success, open_ratio (final), joint_value (final),
                                            num_samples (T), episode (JSON of the EpisodeSpec),
                                            sim_seconds, wall_seconds

``env_args`` (JSON): ``{"env_name": "OpenCabinet", "type": "opend-mj",
"env_kwargs": {<TaskConfig fields>}}``: every TaskConfig field, so the environment is re-created
exactly. Demos are numbered in the order they were appended, from 0.

Format version 2 stores every floating-point array as float32, except the actions a replay steps
(:data:`FLOAT64_KEYS`: ``actions``, ``actions_executed``), which stay float64 so that a replay is
exact; integer, bool and uint8 (image) arrays keep their types. HDF5 datasets are chunked and
gzip-compressed (with the byte shuffle), ``.npz`` files are written with ``np.savez_compressed``.
Files of another format or version are refused (:class:`DemoFileError`, one line naming the file):
re-record them.

In ``.npz`` files, group attrs are stored as one JSON string under ``<group>/.attrs``
(``data/.attrs``, ``data/demo_0/.attrs``), and arrays under their paths above.

Replay (:func:`replay_demo`) rebuilds the env from the stored episode and config, resets it and
steps the stored actions: MuJoCo is deterministic on one machine, so the final open ratio equals the
recorded one (to rounding; the tests ask for 1e-9).
"""

from __future__ import annotations

import dataclasses
import json
import os
import time
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402

FORMAT = "opend-mj-demos"
FORMAT_VERSION = 2
#: Arrays kept in float64: the actions a replay steps (float32 would end a replay elsewhere).
FLOAT64_KEYS = ("actions", "actions_executed")
#: HDF5 dataset options of format 2: chunked, byte-shuffled, gzip level 4 (small arrays stay contiguous).
_H5_COMPRESS = {"compression": "gzip", "compression_opts": 4, "shuffle": True}
_H5_MIN_COMPRESS_BYTES = 1024


class DemoFileError(ValueError):
    """A demonstrations file that cannot be used: its message is one line naming the file and the problem."""
OBS_KEYS = ("hand_joint_pos", "root_pos", "root_quat", "open_ratio")
ENV_NAME = "OpenCabinet"


@dataclass
class Demo:
    """One demonstration: actions (T, A), observations {key: (T, ...)}, final observation, attrs."""

    actions: np.ndarray
    obs: dict[str, np.ndarray]
    attrs: dict
    final: dict[str, np.ndarray] = field(default_factory=dict)
    #: further per-step arrays stored beside ``actions`` (``data/demo_<i>/<name>``)
    extra: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def num_samples(self) -> int:
        return int(len(self.actions))

    def episode_spec(self):
        from opend_mj.sim.task import EpisodeSpec

        d = json.loads(self.attrs["episode"])
        d["cabinet_dir"] = Path(d["cabinet_dir"])
        return EpisodeSpec(**d)


# --------------------------------------------------------------------------------------------------
# env config <-> JSON
# --------------------------------------------------------------------------------------------------
def env_args(config) -> dict:
    """robomimic-style ``env_args`` for a TaskConfig."""
    kwargs = dataclasses.asdict(config)
    return {"env_name": ENV_NAME, "type": "opend-mj", "env_kwargs": kwargs}


def task_config_from_args(args: dict | str):
    from opend_mj.sim.task import TaskConfig

    if isinstance(args, str):
        args = json.loads(args)
    kwargs = dict(args["env_kwargs"])
    names = {f.name: f for f in dataclasses.fields(TaskConfig)}
    out = {}
    for k, v in kwargs.items():
        if k not in names:
            continue
        out[k] = tuple(v) if isinstance(v, list) else v
    return TaskConfig(**out)


def _episode_json(spec) -> str:
    d = dataclasses.asdict(spec)
    d["cabinet_dir"] = str(Path(d["cabinet_dir"]).resolve())
    return json.dumps(d)


# --------------------------------------------------------------------------------------------------
# Recording
# --------------------------------------------------------------------------------------------------
def _obs_of(timestep, keys) -> dict[str, np.ndarray]:
    return {k: np.array(timestep.observation[k], copy=True) for k in keys if k in timestep.observation}


class DemoRecorder:
    """Records what a :class:`~opend_mj.apps.teleop.TeleopController` does (pass it as ``recorder``).

    ``start`` is called on every reset (a reset discards the unfinished demo), ``add`` on every step,
    :meth:`finish` at the end (returns the :class:`Demo`, also kept in ``self.demos``)."""

    def __init__(self, rgb: bool = False):
        self.rgb = rgb
        self.demos: list[Demo] = []
        self._env = None

    def start(self, env, timestep) -> None:
        self._env = env
        self._actions: list[np.ndarray] = []
        self._obs: dict[str, list] = {}
        self._t0 = time.perf_counter()
        self._keys = OBS_KEYS + (("rgb",) if self.rgb and env.task.config.enable_rgbd else ())

    def add(self, action, timestep_before) -> None:
        self._actions.append(np.array(action, float, copy=True))
        for k, v in _obs_of(timestep_before, self._keys).items():
            self._obs.setdefault(k, []).append(v)

    def finish(self, controller=None) -> Demo:
        env = self._env if controller is None else controller.env
        task, physics = env.task, env.physics
        ep = task.episode
        o = task.outcome(physics)
        final = {}
        ts = controller.timestep if controller is not None else None
        if ts is not None:
            final = {k: v[None] for k, v in _obs_of(ts, self._keys).items()}
        n_act = len(task.hand.actuators) + 7
        actions = np.asarray(self._actions, float).reshape(-1, n_act)
        attrs = {
            "instruction": str(task.instruction), "cabinet": str(task.cabinet.id),
            "cabinet_dir": str(Path(ep.cabinet_dir).resolve()), "target_joint": str(task.target.joint),
            "target_type": str(task.target.kind), "hand": str(ep.hand), "seed": int(ep.seed),
            "room": int(ep.room_index()), "success": bool(o.success), "open_ratio": float(o.open_ratio),
            "joint_value": float(o.joint_value), "num_samples": int(len(actions)),
            "episode": _episode_json(ep), "sim_seconds": float(physics.data.time),
            "wall_seconds": float(time.perf_counter() - self._t0),
        }
        obs = {k: np.asarray(v) for k, v in self._obs.items()}
        demo = Demo(actions=actions, obs=obs, attrs=attrs, final=final)
        demo.env_args = env_args(task.config)  # type: ignore[attr-defined]
        self.demos.append(demo)
        return demo


# --------------------------------------------------------------------------------------------------
# Files
# --------------------------------------------------------------------------------------------------
def _is_hdf5(path: Path) -> bool:
    return Path(path).suffix.lower() in (".hdf5", ".h5")


def _h5py():
    try:
        import h5py
    except ImportError as exc:  # pragma: no cover - depends on the install
        raise ImportError("HDF5 demo files need h5py (pip install h5py); or use a .npz file") from exc
    return h5py


def check_header(path, file_attrs: dict) -> dict:
    """``file_attrs`` if they are of this format and version, else :class:`DemoFileError`."""
    fmt, version = file_attrs.get("format"), file_attrs.get("format_version")
    if fmt != FORMAT:
        raise DemoFileError(f"{path}: not an opend-mj demonstrations file (format {fmt!r}, expected {FORMAT!r})")
    if version != FORMAT_VERSION:
        raise DemoFileError(f"{path}: demonstrations format version {version}, this opend-mj reads version "
                            f"{FORMAT_VERSION} only (float32, compressed); re-record it (`opend demos` or "
                            f"`opend teleop --record`) into a new file")
    return file_attrs


def _damaged(path, exc: BaseException) -> DemoFileError:
    reason = " ".join(str(exc).split()) or type(exc).__name__
    return DemoFileError(f"{path}: truncated or damaged demonstrations file ({reason[:160]}); "
                         f"copy it again or re-record it")


def open_demo_file(path):
    """The open HDF5 file of a demo file (``h5py.File``, read only) after :func:`check_header`; a
    missing, truncated or foreign file raises FileNotFoundError / :class:`DemoFileError` naming it."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no demonstrations file")
    h5py = _h5py()
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise _damaged(path, exc) from None
    try:
        if "data" not in f:
            raise DemoFileError(f"{path}: not an opend-mj demonstrations file (no data group)")
        check_header(path, {k: _h5_value(v) for k, v in f["data"].attrs.items()})
    except BaseException:
        f.close()
        raise
    return f


def _demo_names(g) -> list[str]:
    return sorted((k for k in g.keys() if k.startswith("demo_")), key=lambda s: int(s.split("_")[1]))


def read_demos(path) -> tuple[dict, list[Demo]]:
    """(file-level attrs, demos in index order) of a demo file (of format version 2: else
    :class:`DemoFileError`, as for a truncated file)."""
    path = Path(path)
    if _is_hdf5(path):
        with open_demo_file(path) as f:
            g = f["data"]
            try:
                file_attrs = {k: _h5_value(v) for k, v in g.attrs.items()}
                demos = [_h5_demo(g[name]) for name in _demo_names(g)]
            except (OSError, KeyError, RuntimeError) as exc:
                raise _damaged(path, exc) from None
        return file_attrs, demos
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no demonstrations file")
    try:
        with np.load(path, allow_pickle=False) as z:
            files = {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
        raise _damaged(path, exc) from None
    if "data/.attrs" not in files:
        raise DemoFileError(f"{path}: not an opend-mj demonstrations file (no data/.attrs)")
    file_attrs = check_header(path, json.loads(str(files["data/.attrs"])))
    names = sorted({k.split("/")[1] for k in files if k.startswith("data/demo_")}, key=lambda s: int(s.split("_")[1]))
    demos = []
    for name in names:
        pre = f"data/{name}/"
        demos.append(Demo(actions=files[pre + "actions"],
                          obs={k[len(pre + "obs/"):]: v for k, v in files.items() if k.startswith(pre + "obs/")},
                          final={k[len(pre + "final/"):]: v for k, v in files.items() if k.startswith(pre + "final/")},
                          attrs=json.loads(str(files[pre + ".attrs"])),
                          extra={k[len(pre):]: v for k, v in files.items() if k.startswith(pre) and "/" not in
                                 k[len(pre):] and k[len(pre):] not in ("actions", ".attrs")}))
    return file_attrs, demos


def _h5_demo(d) -> Demo:
    """A demo from its HDF5 group."""
    return Demo(actions=d["actions"][()], obs={k: d["obs"][k][()] for k in d["obs"]},
                final={k: d["final"][k][()] for k in d["final"]} if "final" in d else {},
                attrs={k: _h5_value(v) for k, v in d.attrs.items()},
                extra={k: d[k][()] for k in d if k not in ("actions", "obs", "final")})


def _h5_value(v):
    if isinstance(v, bytes):
        return v.decode()
    if isinstance(v, np.generic):
        return v.item()
    return v


def write_demos(path, demos: list[Demo], config=None, append: bool = True) -> Path:
    """Write demos to ``path`` (appending to an existing file unless ``append=False``).

    ``config``: the TaskConfig (default: the one the demos were recorded with). All demos of a file
    share one env config."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    args = env_args(config) if config is not None else getattr(demos[0], "env_args", None) if demos else None
    old: list[Demo] = []
    if append and path.exists():
        old_attrs, old = read_demos(path)
        old_args = json.loads(old_attrs["env_args"])
        if args is not None and old_args != json.loads(json.dumps(args)):
            raise ValueError(f"{path}: its demos were recorded with another env config")
        args = old_args
    if args is None:
        raise ValueError("no env config given and none recorded with the demos")
    for d in demos:
        rec_args = getattr(d, "env_args", None)
        if rec_args is not None and json.loads(json.dumps(rec_args)) != json.loads(json.dumps(args)):
            raise ValueError("a demo was recorded with another env config than the file's")
    all_demos = old + list(demos)
    file_attrs = {"total": int(sum(d.num_samples for d in all_demos)), "env_args": json.dumps(args),
                  "format": FORMAT, "format_version": FORMAT_VERSION}
    tmp = path.with_name(path.name + ".tmp" + path.suffix)
    if _is_hdf5(path):
        h5py = _h5py()
        with h5py.File(tmp, "w") as f:
            g = f.create_group("data")
            g.attrs.update(file_attrs)
            for i, d in enumerate(all_demos):
                _h5_write_demo(g, i, d)
    else:
        arrays = {"data/.attrs": np.array(json.dumps(file_attrs))}
        for i, d in enumerate(all_demos):
            pre = f"data/demo_{i}/"
            arrays[pre + "actions"] = _stored("actions", d.actions)
            arrays[pre + ".attrs"] = np.array(json.dumps(d.attrs))
            for k, v in d.obs.items():
                arrays[pre + "obs/" + k] = _stored(k, v)
            for k, v in d.final.items():
                arrays[pre + "final/" + k] = _stored(k, v)
            for k, v in d.extra.items():
                arrays[pre + k] = _stored(k, v)
        with open(tmp, "wb") as f:
            np.savez_compressed(f, **arrays)
    os.replace(tmp, path)
    return path


def _stored(key: str, value) -> np.ndarray:
    """``value`` as format 2 stores it: floating point as float32 (float64 for :data:`FLOAT64_KEYS`)."""
    v = np.asarray(value)
    if np.issubdtype(v.dtype, np.floating):
        return v.astype(np.float64 if key in FLOAT64_KEYS else np.float32, copy=False)
    return v


def _h5_dataset(group, key: str, value) -> None:
    v = _stored(key, value)
    group.create_dataset(key, data=v, **(_H5_COMPRESS if v.nbytes >= _H5_MIN_COMPRESS_BYTES and v.ndim else {}))


def _h5_write_demo(g, i: int, d: Demo) -> None:
    dg = g.create_group(f"demo_{i}")
    _h5_dataset(dg, "actions", d.actions)
    for k, v in d.extra.items():
        _h5_dataset(dg, k, v)
    og = dg.create_group("obs")
    for k, v in d.obs.items():
        _h5_dataset(og, k, v)
    fg = dg.create_group("final")
    for k, v in d.final.items():
        _h5_dataset(fg, k, v)
    dg.attrs.update({k: v for k, v in d.attrs.items()})


def append_demos(path, demos: list[Demo]) -> Path:
    """Add demos to ``path`` in place (HDF5: only the new groups are written, so a long recording
    stays linear in time; ``.npz``: rewritten by :func:`write_demos`). The demos carry their env
    config (``env_args``), which must be the file's."""
    path = Path(path)
    if not _is_hdf5(path):
        return write_demos(path, demos, append=True)
    h5py = _h5py()
    args = json.loads(json.dumps(getattr(demos[0], "env_args")))
    if any(json.loads(json.dumps(getattr(d, "env_args", args))) != args for d in demos):
        raise ValueError("demos recorded with different env configs cannot share one file")
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.exists():
        open_demo_file(path).close()  # refuses a truncated file or one of another format / version
    with h5py.File(path, "a") as f:
        if "data" not in f:
            g = f.create_group("data")
            g.attrs.update({"total": 0, "env_args": json.dumps(args), "format": FORMAT,
                            "format_version": FORMAT_VERSION})
        g = f["data"]
        if json.loads(_h5_value(g.attrs["env_args"])) != args:
            raise ValueError(f"{path}: its demos were recorded with another env config")
        start = len(_demo_names(g))
        for i, d in enumerate(demos):
            _h5_write_demo(g, start + i, d)
        g.attrs["total"] = int(g.attrs["total"]) + int(sum(d.num_samples for d in demos))
    return path


def load_demo(path, index: int = 0) -> tuple[Demo, dict]:
    """One demo and the file's env_args (dict)."""
    attrs, demos = read_demos(path)
    if not 0 <= index < len(demos):
        raise IndexError(f"{path}: demo {index} out of range (file has {len(demos)})")
    return demos[index], json.loads(attrs["env_args"])


# --------------------------------------------------------------------------------------------------
# Replay
# --------------------------------------------------------------------------------------------------
@dataclass
class ReplayResult:
    open_ratio: float
    joint_value: float
    success: bool
    recorded_open_ratio: float
    obs: dict[str, np.ndarray]  # observations before each step, as recorded
    final_qpos: np.ndarray

    @property
    def error(self) -> float:
        return abs(self.open_ratio - self.recorded_open_ratio)


def replay_demo(demo: Demo, args: dict | str, cabinet_dir: Path | None = None) -> ReplayResult:
    """Re-create the env from the demo's episode and the file's env config, step the stored actions
    (the ones sent, ``actions_executed``, where a recording with noise stored them beside its labels)."""
    from opend_mj.sim.task import make_environment

    config = task_config_from_args(args)
    spec = demo.episode_spec()
    if cabinet_dir is not None:
        spec = dataclasses.replace(spec, cabinet_dir=Path(cabinet_dir))
    env = make_environment(spec, config)
    try:
        ts = env.reset()
        obs: dict[str, list] = {}
        for a in demo.extra.get("actions_executed", demo.actions):
            for k, v in _obs_of(ts, demo.obs.keys()).items():
                obs.setdefault(k, []).append(v)
            ts = env.step(a)
        o = env.task.outcome(env.physics)
        return ReplayResult(open_ratio=float(o.open_ratio), joint_value=float(o.joint_value),
                            success=bool(o.success), recorded_open_ratio=float(demo.attrs["open_ratio"]),
                            obs={k: np.asarray(v) for k, v in obs.items()},
                            final_qpos=env.physics.data.qpos.copy())
    finally:
        env.close()


__all__ = ["Demo", "DemoFileError", "DemoRecorder", "FLOAT64_KEYS", "FORMAT", "FORMAT_VERSION", "OBS_KEYS",
           "append_demos", "check_header", "open_demo_file", "ReplayResult", "env_args", "load_demo", "read_demos",
           "replay_demo", "task_config_from_args", "write_demos"]
