"""Convert an `opend demos` HDF5 file into a LeRobotDataset (format v3.0) with the lerobot library.

The lerobot library (0.4.x) pins torch < 2.11 while this project pins torch 2.14, so the two do not
install into one environment. This tool imports only h5py, numpy and lerobot, never ``opend_mj``:
run it in an environment of its own::

    python -m venv build/lerobot-venv && build/lerobot-venv/bin/pip install 'lerobot==0.4.*' h5py
    build/lerobot-venv/bin/python tools/demos_to_lerobot.py build/demos/allegro_train.hdf5 \
        --out build/lerobot/allegro_train --repo-id opend-mj/allegro_train

What each LeRobot feature holds (per control step, 60 frames per second):

* ``observation.state`` (float32): the hand's own state, the keys of ``STATE_KEYS`` side by side
  (finger joints and velocities, root pose and velocity, grasp site pose, commanded root pose,
  touch in N, time in s); ``names`` says which column is which.
* ``observation.environment_state`` (float32): the instruction's one-hot code (14), the solver's
  handle box (4, pixels) and the handle it back-projects to (25): what a shipped solver gives an agent.
* ``observation.images.front`` (video or image, uint8 RGB): the front camera, where the demos were
  recorded with ``--image-size``. Depth is not carried (LeRobot's video features are RGB).
* ``action`` (float32): the task's absolute action (root position m, quaternion w x y z, finger
  targets), or with ``--action delta`` the gymnasium environments' delta action.
* ``task``: the instruction text.

Failed demonstrations are left out unless ``--keep-failures``. Ground truth (open ratio, joint
value) stays out of the features, as in the HDF5 file.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

#: Per-step HDF5 observation keys that make up ``observation.state``, in order.
STATE_KEYS = ("hand_qpos", "hand_qvel", "root_pos", "root_quat", "root_vel", "grasp_site_pos", "grasp_site_quat",
              "mocap_pos", "mocap_quat", "touch", "time")
#: Per-step HDF5 observation keys that make up ``observation.environment_state``, in order.
ENVIRONMENT_KEYS = ("instruction", "handle_box", "handle_features")
FPS = 60  # the task's control rate (Hz)
IMAGE_KEY = "observation.images.front"


def _columns(group, keys) -> tuple[np.ndarray, list[str]]:
    """(T, sum of widths) float32 of the keys side by side, and a name per column."""
    parts, names = [], []
    for key in keys:
        if key not in group:
            raise ValueError(f"{group.name}: no {key} (not a file of `opend demos`)")
        a = np.asarray(group[key][()], np.float32)
        a = a.reshape(len(a), -1)
        parts.append(a)
        names += [key] if a.shape[1] == 1 else [f"{key}.{i}" for i in range(a.shape[1])]
    return np.concatenate(parts, axis=1), names


def _open_demos(src: Path):
    """The HDF5 file ``src`` open for reading; a clear error where it is not one of `opend demos`."""
    import h5py

    if not Path(src).is_file():
        raise FileNotFoundError(f"{src}: no such file")
    try:
        f = h5py.File(src, "r")
    except OSError as exc:
        raise ValueError(f"{src}: not an HDF5 file ({exc})") from None
    if "data" not in f:
        f.close()
        raise ValueError(f"{src}: not a demonstrations file (no data group)")
    return f


def _lerobot_dataset():
    try:
        from lerobot.datasets.lerobot_dataset import LeRobotDataset
    except ImportError as exc:
        raise ImportError(f"the lerobot library is not installed here ({exc}); `make install-lerobot` makes "
                          "build/lerobot-venv with it: run this tool with build/lerobot-venv/bin/python") from None
    return LeRobotDataset


def verify(src: Path, out: Path, repo_id: str, action: str = "absolute") -> dict:
    """Read ``out`` back with LeRobot's own loader and check it against ``src``: episode count and
    lengths, the task of every episode, and every frame's state, environment state and action
    (exactly, float32); images decoded from the video within 3 % mean error (video compression).
    Returns the figures checked; raises AssertionError on a mismatch."""
    LeRobotDataset = _lerobot_dataset()
    ds = LeRobotDataset(repo_id, root=out, video_backend="pyav")  # pyav: no system FFmpeg needed
    action_key = {"absolute": "actions", "delta": "actions_delta"}[action]
    table = ds.hf_dataset.with_format("numpy")
    columns = {k: np.stack(table[k]) for k in ("observation.state", "observation.environment_state", "action",
                                                 "episode_index", "frame_index")}
    image_error = 0.0
    with _open_demos(src) as f:
        data = f["data"]
        wanted = demo_names(data)
        row = 0
        for e in range(ds.meta.total_episodes):
            length = int(ds.meta.episodes[e]["length"])
            rows = slice(row, row + length)
            assert (columns["episode_index"][rows] == e).all() and (columns["frame_index"][rows] == np.arange(length)).all()
            tasks = ds.meta.episodes[e]["tasks"]
            match = [n for n in wanted if int(data[n][action_key].shape[0]) == length
                     and str(data[n].attrs["instruction"]) in tasks]
            assert match, f"episode {e} ({length} frames, {tasks}) matches no demo of {src}"
            d = data[match[0]]
            wanted.remove(match[0])
            state, _ = _columns(d["obs"], STATE_KEYS)
            env, _ = _columns(d["obs"], ENVIRONMENT_KEYS)
            np.testing.assert_array_equal(columns["observation.state"][rows], state)
            np.testing.assert_array_equal(columns["observation.environment_state"][rows], env)
            np.testing.assert_array_equal(columns["action"][rows], np.asarray(d[action_key][()], np.float32))
            if IMAGE_KEY in ds.features:
                t = length // 2
                img = ds[row + t][IMAGE_KEY].numpy().transpose(1, 2, 0)
                image_error = max(image_error, float(np.abs(img - d["obs"]["rgb"][t] / 255.0).mean()))
                assert image_error < 0.03, f"episode {e}: decoded image differs by {image_error:.3f} on average"
            row += length
    return {"episodes": ds.meta.total_episodes, "frames": len(ds),
            "image_error": round(image_error, 4) if IMAGE_KEY in ds.features else None}


def demo_names(data) -> list[str]:
    return sorted((k for k in data if k.startswith("demo_")), key=lambda k: int(k.split("_")[1]))


def convert(src: Path, out: Path, repo_id: str, action: str = "absolute", videos: bool = True,
            keep_failures: bool = False, limit: int | None = None, log=print) -> dict:
    """Write the demos of ``src`` as a LeRobotDataset at ``out``; returns counts (episodes, frames)."""
    import h5py

    src, out = Path(src), Path(out)
    if out.exists():
        raise FileExistsError(f"{out}: already exists (LeRobot writes a new dataset folder)")
    action_key = {"absolute": "actions", "delta": "actions_delta"}[action]
    with _open_demos(src) as f:
        data = f["data"]
        names = [n for n in demo_names(data) if keep_failures or bool(data[n].attrs.get("success"))]
        if limit is not None:
            names = names[:limit]
        if not names:
            raise ValueError(f"{src}: no demonstrations to convert" + ("" if keep_failures else " (no successful one; "
                                                                      "--keep-failures converts the others)"))
        first = data[names[0]]
        state, state_names = _columns(first["obs"], STATE_KEYS)
        env, env_names = _columns(first["obs"], ENVIRONMENT_KEYS)
        width = first[action_key].shape[1]
        features = {
            "observation.state": {"dtype": "float32", "shape": (state.shape[1],), "names": state_names},
            "observation.environment_state": {"dtype": "float32", "shape": (env.shape[1],), "names": env_names},
            "action": {"dtype": "float32", "shape": (width,), "names": [f"{action_key}.{i}" for i in range(width)]},
        }
        has_images = "rgb" in first["obs"]
        if has_images:
            size = first["obs"]["rgb"].shape[1:]
            features[IMAGE_KEY] = {"dtype": "video" if videos else "image", "shape": tuple(size),
                                   "names": ["height", "width", "channels"]}
        hand = str(first.attrs.get("hand", ""))
        LeRobotDataset = _lerobot_dataset()
        ds = LeRobotDataset.create(repo_id, fps=FPS, features=features, root=out, robot_type=hand or None,
                                   use_videos=videos and has_images)
        frames = 0
        for i, name in enumerate(names):
            d = data[name]
            if str(d.attrs.get("hand", "")) != hand:
                raise ValueError(f"{src}: {name} is of the {d.attrs.get('hand')} hand, {names[0]} of {hand}: "
                                 "one dataset holds one hand")
            state, _ = _columns(d["obs"], STATE_KEYS)
            env, _ = _columns(d["obs"], ENVIRONMENT_KEYS)
            acts = np.asarray(d[action_key][()], np.float32)
            rgb = d["obs"]["rgb"] if has_images else None
            task = str(d.attrs["instruction"])
            for t in range(len(acts)):
                frame = {"observation.state": state[t], "observation.environment_state": env[t], "action": acts[t],
                         "task": task}
                if rgb is not None:
                    frame[IMAGE_KEY] = np.asarray(rgb[t], np.uint8)
                ds.add_frame(frame)
            ds.save_episode()
            frames += len(acts)
            log(f"{i + 1}/{len(names)} {name}: {len(acts)} frames, {task!r}")
        ds.finalize()
    return {"episodes": len(names), "frames": frames, "features": sorted(features)}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("demos", type=Path, help="an HDF5 file of `opend demos`")
    p.add_argument("--out", type=Path, required=True, help="the new dataset's folder (must not exist)")
    p.add_argument("--repo-id", default="opend-mj/demos", help="the dataset's LeRobot repo id [%(default)s]")
    p.add_argument("--action", choices=["absolute", "delta"], default="absolute",
                   help="which action space the action feature holds [%(default)s]")
    p.add_argument("--images", choices=["video", "image"], default="video",
                   help="store the camera as MP4 video or as PNG images [%(default)s]")
    p.add_argument("--keep-failures", action="store_true", help="convert failed demonstrations too")
    p.add_argument("--limit", type=int, default=None, help="the first N demonstrations only")
    p.add_argument("--verify", action="store_true",
                   help="then read the dataset back with LeRobot's loader and check every frame against the file")
    args = p.parse_args(argv)
    try:
        counts = convert(args.demos, args.out, args.repo_id, action=args.action, videos=args.images == "video",
                         keep_failures=args.keep_failures, limit=args.limit)
        print(f"{counts['episodes']} episodes, {counts['frames']} frames -> {args.out}")
        if args.verify:
            checked = verify(args.demos, args.out, args.repo_id, action=args.action)
            images = ("no images" if checked["image_error"] is None
                      else f"images within {checked['image_error']:.3f} mean error")
            print(f"verified with LeRobot's loader: {checked['episodes']} episodes, {checked['frames']} frames "
                  f"(state, environment state and action exact; {images})")
    except (ValueError, FileExistsError, FileNotFoundError, ImportError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
