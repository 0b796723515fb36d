"""Batched simulation: the benchmark's compiled scenes in MJX (MuJoCo in JAX, CPU or GPU).

`scene_model` compiles the scene of one episode (room, cabinet, hand on its mocap weld, camera) and
returns its ``MjModel`` / ``MjData`` after the benchmark's reset; `mjx_report` says whether MJX
accepts it and what it holds that batched engines care about (collision pairs, hull sizes);
`batched_steps` puts it into MJX and steps a batch of copies with ``jax.vmap``.

Needs the optional extra ``pip install -e '.[mjx]'`` (``mujoco-mjx`` and JAX); nothing else in the
package imports JAX. ``JAX_PLATFORMS=cpu`` runs on a CPU; on a machine with a GPU and a CUDA
build of jaxlib the same calls run there.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from opend_mj.sim.task import EpisodeSpec, TaskConfig, make_environment


@dataclass(frozen=True)
class MjxReport:
    """What MJX makes of a compiled scene."""

    accepted: bool
    error: str | None
    collision_pairs: int  # geom pairs MJX collides (after contype/conaffinity and excludes)
    pair_types: dict[str, int] = field(default_factory=dict)  # "box-capsule": count
    mesh_hulls: int = 0
    max_hull_vertices: int = 0
    cone: str = ""
    integrator: str = ""


def scene_model(cabinet_dir: str | os.PathLike, joint: str, hand: str = "allegro", seed: int = 0,
                config: TaskConfig = TaskConfig(enable_rgbd=False)):
    """(MjModel, MjData) of one episode's scene after the benchmark's reset (hand at its start)."""
    env = make_environment(EpisodeSpec(Path(cabinet_dir), joint, hand, seed=seed), config, observations=False)
    env.reset()
    import mujoco

    model = env.physics.model.ptr
    data = mujoco.MjData(model)
    mujoco.mj_copyData(data, model, env.physics.data.ptr)
    env.close()
    return model, data


def mjx_report(model) -> MjxReport:
    """Try ``mjx.put_model`` on ``model``; count what its collision detection has to handle."""
    import mujoco
    from mujoco import mjx
    from mujoco.mjx._src import collision_driver

    pairs = list(collision_driver.geom_pairs(model))
    kinds: dict[str, int] = {}
    for g1, g2, _ in pairs:
        names = sorted(mujoco.mjtGeom(int(model.geom_type[g])).name[len("mjGEOM_"):].lower() for g in (g1, g2))
        key = "-".join(names)
        kinds[key] = kinds.get(key, 0) + 1
    colliding = [g for g in range(model.ngeom) if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH
                 and (model.geom_contype[g] or model.geom_conaffinity[g])]
    hull_vertices = [hull_vertex_count(model, int(model.geom_dataid[g])) for g in colliding]
    try:
        mjx.put_model(model)
        accepted, error = True, None
    except NotImplementedError as exc:  # MJX names the feature it lacks
        accepted, error = False, f"{type(exc).__name__}: {exc}"
    return MjxReport(accepted=accepted, error=error, collision_pairs=len(pairs), pair_types=kinds,
                     mesh_hulls=len(colliding), max_hull_vertices=max(hull_vertices, default=0),
                     cone=mujoco.mjtCone(model.opt.cone).name, integrator=mujoco.mjtIntegrator(model.opt.integrator).name)


def hull_vertex_count(model, mesh_id: int) -> int:
    """Vertices of a mesh's convex hull as MuJoCo computed it (its graph), else of the mesh."""
    adr = int(model.mesh_graphadr[mesh_id])
    return int(model.mesh_graph[adr]) if adr >= 0 else int(model.mesh_vertnum[mesh_id])


def batched_steps(model, data, batch: int, steps: int, jit: bool = True, noise: float = 0.0,
                  seed: int = 0) -> tuple[np.ndarray, float]:
    """Step ``batch`` copies of ``data`` ``steps`` physics steps in MJX (``jax.vmap`` of ``mjx.step``).

    ``noise``: standard deviation (rad or m) added to each copy's hinge and slide joints, so that the
    copies differ. ``jit=False`` runs op by op (no whole-step XLA compile: minutes on a CPU for a
    scene with hundreds of collision pairs; for a quick check). Returns the final qpos
    (batch, nq) and the seconds per batched step after the first (which includes compiling).
    """
    import jax
    import jax.numpy as jnp
    from mujoco import mjx

    mx = mjx.put_model(model)
    dx = mjx.put_data(model, data)
    qpos = np.tile(np.asarray(data.qpos), (batch, 1))
    if noise:
        import mujoco

        rng = np.random.default_rng(seed)
        for j in range(model.njnt):
            if model.jnt_type[j] in (mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE):
                qpos[:, model.jnt_qposadr[j]] += rng.normal(0.0, noise, batch)
    batch_data = jax.vmap(lambda q: dx.replace(qpos=q))(jnp.asarray(qpos))
    step = jax.vmap(mjx.step, in_axes=(None, 0))
    if jit:
        step = jax.jit(step)
        batch_data = step(mx, batch_data)
        jax.block_until_ready(batch_data.qpos)
        start = time.perf_counter()
        for _ in range(steps - 1):
            batch_data = step(mx, batch_data)
        jax.block_until_ready(batch_data.qpos)
    else:
        with jax.disable_jit():
            batch_data = step(mx, batch_data)
            jax.block_until_ready(batch_data.qpos)
            start = time.perf_counter()
            for _ in range(steps - 1):
                batch_data = step(mx, batch_data)
            jax.block_until_ready(batch_data.qpos)
    per_step = (time.perf_counter() - start) / max(steps - 1, 1)
    return np.asarray(batch_data.qpos), per_step
