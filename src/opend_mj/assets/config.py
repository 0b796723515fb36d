"""Configuration of the asset pipeline (compiler, dataset) as dataclasses.

Every number the compiler uses lives here, so that a build is described by one object whose hash is
part of the cache key: change a setting and the affected cabinets are rebuilt, nothing else.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import dataclass

from opend_mj.assets.layout import PARTNET_SCALE


@dataclass(frozen=True)
class JointPhysics:
    """Joint dynamics the compiler adds (PartNet-Mobility URDFs carry none)."""

    damping: float
    frictionloss: float
    armature: float
    #: Limit softness (MuJoCo solref timeconst, dampratio): stiff so that a pull cannot overshoot.
    limit_solref: tuple[float, float] = (0.005, 1.0)


@dataclass(frozen=True)
class CoacdParams:
    """CoACD convex decomposition parameters for non-convex pieces (real PartNet meshes)."""

    threshold: float = 0.08
    max_convex_hull: int = 16
    preprocess_mode: str = "auto"
    preprocess_resolution: int = 40
    resolution: int = 1000
    mcts_nodes: int = 15
    mcts_iterations: int = 80
    mcts_max_depth: int = 2
    seed: int = 0


@dataclass(frozen=True)
class CompilerConfig:
    """How a PartNet-Mobility source becomes an MJCF cabinet."""

    #: Uniform scale from PartNet's normalised units to metres (the OpenD paper used 0.7).
    scale: float = PARTNET_SCALE
    drawer: JointPhysics = JointPhysics(damping=8.0, frictionloss=2.0, armature=0.05)
    door: JointPhysics = JointPhysics(damping=1.5, frictionloss=0.5, armature=0.02)
    #: Density of carcass, door and drawer material (kg/m^3, particle board is about 650).
    density: float = 600.0
    #: Mass floor and ceiling for a movable part (kg).
    min_link_mass: float = 0.3
    max_link_mass: float = 15.0
    #: A piece whose hull volume is within this fraction of its own volume is kept as it is.
    convex_tolerance: float = 0.01
    #: Hulls thinner than this (m, after scaling) are thickened to it: MuJoCo rejects flat meshes.
    min_thickness: float = 0.004
    #: Pieces smaller than this (bounding-box diagonal, m) carry no collision geometry.
    min_piece_size: float = 0.004
    #: A convex piece whose oriented box volume is within this fraction of its hull becomes a box geom.
    box_tolerance: float = 0.01
    #: How non-convex pieces become hulls: "split" (plane cuts per piece until every hull follows the
    #: surface within a tolerance) or "coacd" (one CoACD run over a link's non-convex pieces).
    decomposer: str = "split"
    #: Largest distance (m) of a split hull from the visual surface: handles, everything else.
    handle_tolerance: float = 0.001
    surface_tolerance: float = 0.002
    #: Flat handle pieces (one hull) are thickened to this (m). It stays at min_thickness so that
    #: procedural cabinets (flat knob faces) compile as before.
    handle_min_thickness: float = 0.004
    #: Hulls that the splitter cuts out of a non-convex handle piece are thickened to this (m): a thin
    #: flange or slice then stands at most half of it off its surface (the 4 mm of min_thickness put
    #: 2 mm on each side, twice handle_tolerance). MuJoCo accepts hulls of this thickness.
    handle_split_thickness: float = 0.001
    #: Hull budget per non-convex piece (a piece that needs more keeps its last, larger hulls).
    handle_max_hulls: int = 24
    max_hulls_per_piece: int = 6
    #: A body piece no thicker than this (m) whose vertices all lie on its hull is one solid panel
    #: (PartNet often models a board by its visible faces only).
    fill_panels: float = 0.03
    #: Mesh files with more faces than this are rejected (they would stall a worker).
    max_mesh_faces: int = 200000
    coacd: CoacdParams = CoacdParams()
    #: Doors on a non-vertical hinge (flaps, lift-up doors) and vertical sliders are counterbalanced
    #: (MuJoCo gravcomp on their body, as a gas strut or a stay holds a real one): otherwise a flap falls
    #: open under gravity and a lift-up door cannot be held open.
    counterbalance: bool = True
    #: Friction of cabinet and handle geoms (sliding, torsional, rolling).
    friction: tuple[float, float, float] = (1.0, 0.01, 0.0001)
    handle_condim: int = 4
    #: Largest vertex count of a collision hull (MJCF ``maxhullvert`` on hulls whose vertex cloud is
    #: larger). Batched simulators (MJX, MuJoCo Warp) collide convex meshes in fixed-size kernels
    #: whose cost grows with the hull's vertices and faces; 64 leaves every procedural hull (32 at
    #: most) as it is. -1: no cap.
    max_hull_vertices: int = 64
    #: Decimals kept for vertex coordinates written to MJCF.
    precision: int = 6

    def digest(self) -> str:
        """A short stable hash of every setting (part of the cache key)."""
        blob = json.dumps(dataclasses.asdict(self), sort_keys=True).encode()
        return hashlib.sha256(blob).hexdigest()[:16]


@dataclass(frozen=True)
class DatasetConfig:
    """The default dataset: procedural sources, filtered and split by cabinet."""

    count: int = 346
    seed: int = 0
    #: Fraction of valid cabinets in the test split (the paper: 39 of 174, 22 %).
    test_fraction: float = 0.224
    split_seed: int = 0
