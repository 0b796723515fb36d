"""Training data for the learned handle solvers (`opend make-data`).

As in the OpenD paper: front-camera renders of the training cabinets at 256 x 256, the camera
shifted by up to 10 cm along each axis, a 50 % chance of a random handle colour, randomised rooms
(room type, furniture, floor, walls and lights all follow the scene seed) and a mild light scale;
optionally views of the cabinet plain light grey (``DataConfig.plain_prob``: most real cabinets compile
untextured, one light grey; off by default, as the shipped checkpoints were trained); 1740 images by default, 80 % train / 20 % validation. Validation cabinets are held out whole
(the split is by cabinet, drawn from a seeded hash), so validation measures unseen cabinets.

On-disk format (version 1), one folder::

    DIR/info.json          generator settings, counts, format version
    DIR/labels.jsonl       one JSON object per image (below), ordered by id
    DIR/rgb/000123.png     RGB, uint8, H x W x 3
    DIR/depth/000123.png   planar depth, uint16 millimetres (0 = nothing / beyond 65 m)
    DIR/mask/000123.png    uint8 label image: 0 = background, k = handle pixels of targets[k-1]

A record of labels.jsonl::

    {"id": 123, "subset": "train" | "val" | "test", "cabinet": "proc_0007",
     "rgb": "rgb/000123.png", "depth": "depth/000123.png", "mask": "mask/000123.png",
     "width": 256, "height": 256, "room": 4, "seed": 991, "light_scale": 1.07,
     "camera_shift": [dx, dy, dz], "handle_colour": [r, g, b] | null, "plain_grey": g | null,
     "camera": {"fx", "fy", "cx", "cy", "pos": [3], "rot": [[3 x 3]]},
     "targets": [{"joint", "type": "door" | "drawer", "instruction", "vertical", "horizontal",
                  "orientation": "horizontal" | "vertical", "box": [u0, v0, u1, v1] | null,
                  "mask_value": k, "mask_pixels": n}]}

Boxes are in pixels (u right, v down; torchvision's x1, y1, x2, y2) from the simulator's handle
geoms; the mask holds the visible pixels of each target's handle geoms (rendered with only the
cabinet's collision group, so the cabinet itself occludes them). "Every handle box" is the list of
target boxes: in the procedural and PartNet cabinets every handle belongs to a target.

Handle colour: the compiler merges each link's visual meshes into one geom with one colour, so a
handle cannot be recoloured on its own visual geom. For a recoloured view the handle collision
geoms (``handle_<link>_<i>``, the handle meshes themselves) are made visible (group 2) with the
random colour; they coincide with the handle's visual surface and win the depth test.
"""

from __future__ import annotations

import hashlib
import json
import multiprocessing
import os
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

FORMAT_VERSION = 1
LABELS = "labels.jsonl"
INFO = "info.json"


@dataclass(frozen=True)
class DataConfig:
    """What `opend make-data` renders."""

    n_images: int = 1740
    image_size: int = 256
    max_shift: float = 0.10  # metres, per axis, uniform
    colour_prob: float = 0.5
    #: Chance that a view shows the cabinet plain: every visual geom one light grey (level drawn from
    #: ``plain_grey``), as a PartNet-Mobility cabinet without textures compiles: real fronts render
    #: nearly unsaturated and lighter than most generated ones, which a solver must also see.
    plain_prob: float = 0.0
    plain_grey: tuple[float, float] = (0.7, 1.0)
    val_fraction: float = 0.2
    views_per_scene: int = 4  # camera shifts / colours per built scene (one room each)
    light_range: tuple[float, float] = (0.85, 1.15)
    hand: str = "franka"  # in the scene but out of view
    seed: int = 0
    split: str = "train"  # cabinets of this dataset split ("train" -> train/val, "test" -> test)


@dataclass(frozen=True)
class SceneJob:
    first_id: int
    n_views: int
    cabinet_id: str
    cabinet_dir: str
    subset: str
    seed: int
    out_dir: str
    config: dict = field(default_factory=dict)


def cabinet_subset(cabinet_id: str, split: str, val_fraction: float, seed: int) -> str:
    """train / val (held-out cabinets of the train split) / test."""
    if split == "test":
        return "test"
    h = int(hashlib.sha256(f"val:{seed}:{cabinet_id}".encode()).hexdigest()[:8], 16) / 0xFFFFFFFF
    return "val" if h < val_fraction else "train"


def plan_jobs(cabinets_dir: Path, out_dir: Path, config: DataConfig, cabinet_ids: list[str] | None = None) -> list[SceneJob]:
    """Scenes to render: cabinets visited round-robin in a seeded order, ``views_per_scene`` each."""
    from opend_mj.assets.layout import load_manifest

    cabinets_dir = Path(cabinets_dir)
    if cabinet_ids is None:
        manifest = load_manifest(cabinets_dir)
        cabs = [(c["id"], cabinets_dir / c["path"]) for c in manifest.cabinets if c["split"] == config.split]
    else:
        cabs = [(cid, cabinets_dir / cid) for cid in cabinet_ids]
    if not cabs:
        raise ValueError(f"no cabinets of split {config.split!r} in {cabinets_dir}")
    rng = np.random.default_rng([config.seed, 17])
    order = [cabs[i] for i in rng.permutation(len(cabs))]
    jobs, next_id, k = [], 0, 0
    while next_id < config.n_images:
        cid, cdir = order[k % len(order)]
        n = min(config.views_per_scene, config.n_images - next_id)
        jobs.append(SceneJob(first_id=next_id, n_views=n, cabinet_id=cid, cabinet_dir=str(cdir),
                             subset=cabinet_subset(cid, config.split, config.val_fraction, config.seed),
                             seed=int(rng.integers(2**31 - 1)), out_dir=str(out_dir), config=asdict(config)))
        next_id += n
        k += 1
    return jobs


def _png(path: Path, array: np.ndarray) -> None:
    from PIL import Image

    Image.fromarray(array).save(path)


def render_scene(job: SceneJob) -> list[dict]:
    """Build one scene (cabinet + random room) and render ``job.n_views`` labelled views of it."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    import mujoco

    from opend_mj.sim.camera import RGBDCamera
    from opend_mj.sim.task import EpisodeSpec, TaskConfig, make_environment

    cfg = DataConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in job.config.items()})
    rng = np.random.default_rng(job.seed)
    out = Path(job.out_dir)
    info_targets = json.loads((Path(job.cabinet_dir) / "cabinet.json").read_text())["targets"]
    light = float(rng.uniform(*cfg.light_range))
    episode = EpisodeSpec(Path(job.cabinet_dir), info_targets[0]["joint"], cfg.hand, seed=job.seed)
    tcfg = TaskConfig(image_size=cfg.image_size, light_scale=light, enable_rgbd=False)
    env = make_environment(episode, tcfg)
    records = []
    try:
        env.reset()
        physics = env.physics
        task = env.task
        model = physics.model
        cam_id = model.name2id(task.camera.full_identifier, "camera")
        base_pos = np.array(model.cam_pos[cam_id])
        targets = task.cabinet.targets
        geom_ids = [[model.name2id(f"cabinet/{g}", "geom") for g in t.handle_geoms] for t in targets]
        all_ids = [g for ids in geom_ids for g in ids]
        group0 = np.array(model.geom_group[all_ids])
        rgba0 = np.array(model.geom_rgba[all_ids])
        visual_ids = [i for i in range(model.ngeom)  # the cabinet's untextured visual geoms, for plain views
                      if cfg.plain_prob > 0 and (model.id2name(i, "geom") or "").startswith("cabinet/vis_")
                      and model.geom_matid[i] < 0]
        visual_rgba0 = np.array(model.geom_rgba[visual_ids])
        seg_option = mujoco.MjvOption()
        seg_option.geomgroup[:] = [0, 0, 0, 1, 0, 0]  # cabinet collision geoms + handles only
        with RGBDCamera(physics, task.camera.full_identifier, cfg.image_size, cfg.image_size) as cam:
            for k in range(job.n_views):
                image_id = job.first_id + k
                shift = rng.uniform(-cfg.max_shift, cfg.max_shift, size=3)
                model.cam_pos[cam_id] = base_pos + shift
                physics.forward()
                # mask first, with the handles in their own (collision) group
                model.geom_group[all_ids] = group0
                model.geom_rgba[all_ids] = rgba0
                seg = cam.render_segmentation(seg_option)
                mask = np.zeros(seg.shape[:2], np.uint8)
                is_geom = seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM)
                for i, ids in enumerate(geom_ids):
                    mask[is_geom & np.isin(seg[..., 0], ids)] = i + 1
                model.geom_rgba[visual_ids] = visual_rgba0
                plain = None
                if cfg.plain_prob > 0 and rng.random() < cfg.plain_prob:  # (no draw when off: same data as before)
                    plain = round(float(rng.uniform(*cfg.plain_grey)), 4)
                    model.geom_rgba[visual_ids] = [plain, plain, plain, 1.0]
                colour = None
                if rng.random() < cfg.colour_prob:
                    colour = [float(x) for x in rng.uniform(0, 1, size=3)]
                    model.geom_group[all_ids] = 2
                    model.geom_rgba[all_ids] = [*colour, 1.0]
                rgb, depth = cam.render()
                boxes = task.handle_boxes(physics)
                view = task.camera_view(physics)
                name = f"{image_id:06d}.png"
                _png(out / "rgb" / name, rgb)
                _png(out / "depth" / name, np.clip(np.nan_to_num(depth) * 1000.0, 0, 65535).astype(np.uint16))
                _png(out / "mask" / name, mask)
                k_ = view.intrinsics
                records.append({
                    "id": image_id, "subset": job.subset, "cabinet": job.cabinet_id,
                    "rgb": f"rgb/{name}", "depth": f"depth/{name}", "mask": f"mask/{name}",
                    "width": cfg.image_size, "height": cfg.image_size,
                    "room": task.arena.room, "seed": job.seed, "light_scale": round(light, 4),
                    "camera_shift": [round(float(x), 5) for x in shift], "handle_colour": colour,
                    "plain_grey": plain,
                    "camera": {"fx": k_.fx, "fy": k_.fy, "cx": k_.cx, "cy": k_.cy,
                               "pos": [float(x) for x in view.pos], "rot": np.asarray(view.rot).tolist()},
                    "targets": [{
                        "joint": t.joint, "type": t.kind, "instruction": t.instruction,
                        "vertical": t.record.get("vertical", ""), "horizontal": t.record.get("horizontal", ""),
                        "orientation": t.handle_orientation,
                        "box": None if boxes.get(t.joint) is None else [round(float(x), 3) for x in boxes[t.joint]],
                        "mask_value": i + 1, "mask_pixels": int((mask == i + 1).sum()),
                    } for i, t in enumerate(targets)],
                })
            model.geom_group[all_ids] = group0
            model.geom_rgba[all_ids] = rgba0
            model.geom_rgba[visual_ids] = visual_rgba0
    finally:
        env.close()
    return records


def make_dataset(cabinets_dir: Path, out_dir: Path, config: DataConfig = DataConfig(), workers: int = 2,
                 progress: bool = True, cabinet_ids: list[str] | None = None) -> dict:
    """Render the dataset into ``out_dir`` (see the module docstring for the format); returns info."""
    from tqdm import tqdm

    out_dir = Path(out_dir)
    for sub in ("rgb", "depth", "mask"):
        (out_dir / sub).mkdir(parents=True, exist_ok=True)
    jobs = plan_jobs(cabinets_dir, out_dir, config, cabinet_ids)
    t0 = time.time()
    records: list[dict] = []
    bar = tqdm(total=config.n_images, unit="img", disable=not progress, desc="make-data")
    if workers <= 1:
        for job in jobs:
            recs = render_scene(job)
            records += recs
            bar.update(len(recs))
    else:
        ctx = multiprocessing.get_context("spawn")  # EGL contexts do not survive fork
        with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
            futures = [pool.submit(render_scene, job) for job in jobs]
            for fut in as_completed(futures):
                recs = fut.result()
                records += recs
                bar.update(len(recs))
    bar.close()
    records.sort(key=lambda r: r["id"])
    with open(out_dir / LABELS, "w") as f:
        for r in records:
            f.write(json.dumps(r) + "\n")
    counts: dict[str, int] = {}
    for r in records:
        counts[r["subset"]] = counts.get(r["subset"], 0) + 1
    info = {"format_version": FORMAT_VERSION, "config": asdict(config), "cabinets_dir": str(cabinets_dir),
            "images": len(records), "subsets": counts,
            "cabinets": {s: sorted({r["cabinet"] for r in records if r["subset"] == s}) for s in counts},
            "targets": sum(len(r["targets"]) for r in records), "seconds": round(time.time() - t0, 1)}
    (out_dir / INFO).write_text(json.dumps(info, indent=1) + "\n")
    return info


# --------------------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------------------


def load_records(data_dir: Path, subset: str | None = None) -> list[dict]:
    """Records of labels.jsonl, optionally of one subset ("train", "val", "test")."""
    path = Path(data_dir) / LABELS
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no labels; run `opend make-data --out {data_dir}` first")
    recs = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    return [r for r in recs if subset in (None, "all", r["subset"])]


def load_images(data_dir: Path, record: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rgb uint8 HxWx3, depth float32 metres HxW, mask uint8 HxW) of one record."""
    from PIL import Image

    d = Path(data_dir)
    rgb = np.asarray(Image.open(d / record["rgb"]).convert("RGB"))
    depth = np.asarray(Image.open(d / record["depth"])).astype(np.float32) / 1000.0
    mask = np.asarray(Image.open(d / record["mask"]))
    return rgb, depth, mask


def camera_view_of(record: dict):
    """The :class:`opend_mj.sim.camera.CameraView` stored with a record."""
    from opend_mj.sim.camera import CameraIntrinsics, CameraView

    c = record["camera"]
    k = CameraIntrinsics(fx=c["fx"], fy=c["fy"], cx=c["cx"], cy=c["cy"], width=record["width"], height=record["height"])
    return CameraView(intrinsics=k, pos=np.asarray(c["pos"], float), rot=np.asarray(c["rot"], float))
