"""Procedural cabinets written in SAPIEN PartNet-Mobility format.

Each cabinet is a folder ``proc_NNNN/`` with ``mobility.urdf``, ``semantics.txt``, ``meta.json`` and
``textured_objs/original-K.obj`` (+ ``.mtl``), laid out exactly like a real PartNet-Mobility object so
that one compiler handles both.

Conventions (the same as PartNet-Mobility):

* Mesh frame: y up, the cabinet front faces +z, +x is to the right seen from the front. Vertices are
  object coordinates in PartNet's normalised units: real metres divided by ``PARTNET_SCALE``.
* ``base`` is an empty link; the carcass ``link_N`` (N = number of movable parts) hangs off it with a
  fixed joint rotated ``rpy="pi/2 0 -pi/2"`` (y-up to z-up, front to world -x). Every movable link is a
  child of the carcass; its joint origin is the axis point P and its visuals/collisions are offset by -P.
* Drawers are prismatic along +z; doors are revolute about the vertical edge at the front face (axis
  ``0 -1 0`` for a left hinge, ``0 1 0`` for a right hinge: both open outward for positive angles).

Every convex piece (panel box, handle cylinder) is its own closed, outward-oriented connected component
in its OBJ, so the compiler can keep pieces as convex collision geoms without decomposition. Closed
cabinets have at least ``clearance`` (4 mm) between parts of different links.

About half of the cabinets are deliberately not describable by the language rule of OpenD's
Algorithm 1 (e.g. stacks of 6-8 drawers: more than five vertical levels); ``meta.json`` records this
under ``procedural.describable`` together with the handle centres that decide it.

Sampling and writing are apart: `model.sample_cabinet` draws a cabinet from the random stream
``(seed, index)`` (`layouts`, `handles` and `materials` sample its parts, every probability in
`config.GeneratorConfig`), and `writer.write_source` writes it; `generate_source` does both.
"""

from opend_mj.assets.layout import PARTNET_SCALE
from opend_mj.assets.procedural.config import GENERATOR_VERSION, HANDLE_KINDS, GeneratorConfig
from opend_mj.assets.procedural.model import SampledCabinet, sample_cabinet
from opend_mj.assets.procedural.pieces import Box, Cylinder, piece_bounds, piece_mesh
from opend_mj.assets.procedural.writer import (describable, find_cabinets, generate_source, generate_sources,
                                               write_source)

__all__ = [
    "GENERATOR_VERSION", "HANDLE_KINDS", "PARTNET_SCALE", "Box", "Cylinder", "GeneratorConfig", "SampledCabinet",
    "describable", "find_cabinets", "generate_source", "generate_sources", "piece_bounds", "piece_mesh",
    "sample_cabinet", "write_source",
]
