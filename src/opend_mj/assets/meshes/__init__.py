"""Mesh processing for the compiler: pieces, convexity, decomposition, thin hulls and boxes.

Real PartNet-Mobility meshes are surface soups: faces stored twice (double-sided), many disconnected
pieces, flat panels of zero thickness. The pipeline here turns any such soup into a list of convex
hulls that MuJoCo accepts (`collision_hulls`):

1. weld vertices by position and split into vertex-connected pieces;
2. keep a piece that is already convex as one hull (procedural cabinets are all convex pieces);
3. cut what is left into hulls that follow its surface with the plane splitter (`splitter`, the
   default, cached by content hash in `cache`), or with CoACD when ``CompilerConfig.decomposer`` is
   ``"coacd"`` (`coacd_adapter`);
4. thicken hulls thinner than a few millimetres, and turn box-shaped hulls into box primitives.

Modules, one job each: `files` (reading mesh files), `geometry` (hull primitives: welding, pieces,
qhull hulls, oriented boxes, `Hull`), `splitter`, `cache`, `coacd_adapter`, `collision` (the pipeline
above) and `mass` (mass properties of a union of hulls). Everything public is importable from here.
"""

from opend_mj.assets.meshes.cache import SPLIT_VERSION, DecompositionStats, cached_split
from opend_mj.assets.meshes.coacd_adapter import coacd_decompose
from opend_mj.assets.meshes.collision import collision_hulls
from opend_mj.assets.meshes.files import MeshError, load_mesh_file
from opend_mj.assets.meshes.geometry import (
    Hull,
    QHull,
    fast_box,
    is_convex_piece,
    oriented_box,
    pieces,
    thicken,
    to_hull,
    weld,
)
from opend_mj.assets.meshes.mass import mass_properties
from opend_mj.assets.meshes.splitter import split_decompose

__all__ = [
    "SPLIT_VERSION", "DecompositionStats", "Hull", "MeshError", "QHull", "cached_split", "coacd_decompose",
    "collision_hulls", "fast_box", "is_convex_piece", "load_mesh_file", "mass_properties", "oriented_box",
    "pieces", "split_decompose", "thicken", "to_hull", "weld",
]
