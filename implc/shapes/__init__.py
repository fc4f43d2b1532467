"""implc's modelling library: plain functions returning SymPy expressions F (F < 0 inside, F > 0 outside),
in groups:

- 2D shapes and their ways into 3D (:mod:`.sketch`): circle, rectangle, rounded_rectangle, ring,
  convex_polygon, regular_polygon, triangle; extrude, revolve, loft;
- solids (:mod:`.solids`): sphere, box, box_exact, rounded_box, torus, torus_exact, cylinder,
  capped_cylinder, capsule, cone, ellipsoid, half_space, slab, pyramid, tetrahedron, octahedron,
  dodecahedron, icosahedron; the paper's blend and blobs;
- CSG (:mod:`.csg`): union, intersection, difference, their ``smooth_`` and ``chamfer_`` variants, morph;
- offsets (:mod:`.offsets`): offset, dilate, erode, shell, inner_shell, clearance;
- deformations (:mod:`.deform`): twist, bend, taper, shear, elongate;
- repetition (:mod:`.repeat`): array_linear, array_grid, array_polar; mirror and symmetric in transforms;
- transforms (:mod:`.transforms`): translate, scale, rotate (any axis), transform (4×4), mirror, symmetric;
- lattices (:mod:`.lattices`): gyroid, schwarz_p, diamond, neovius, infill.

Each function's docstring says whether F is an exact distance (‖∇F‖ = 1) or what it is instead.

>>> import implc
>>> from implc import shapes
>>> part = shapes.difference(shapes.rounded_box((0.6, 0.4, 0.2), 0.05), shapes.capped_cylinder(0.15, 1))
>>> len(implc.voxelize(implc.compile(part), 5)) > 0
True
"""

from .csg import (
    chamfer_difference,
    chamfer_intersection,
    chamfer_union,
    difference,
    intersection,
    morph,
    smooth_difference,
    smooth_intersection,
    smooth_union,
    union,
)
from .deform import bend, elongate, shear, taper, twist
from .lattices import diamond, gyroid, infill, neovius, schwarz_p
from .offsets import clearance, dilate, erode, inner_shell, offset, shell
from .repeat import array_grid, array_linear, array_polar
from .sketch import (
    circle,
    convex_polygon,
    extrude,
    loft,
    rectangle,
    regular_polygon,
    revolve,
    ring,
    rounded_rectangle,
    triangle,
)
from .solids import (
    blend,
    blobs,
    box,
    box_exact,
    capped_cylinder,
    capsule,
    cone,
    cylinder,
    dodecahedron,
    ellipsoid,
    half_space,
    icosahedron,
    octahedron,
    pyramid,
    rounded_box,
    slab,
    sphere,
    tetrahedron,
    torus,
    torus_exact,
)
from .transforms import mirror, rotate, scale, symmetric, transform, translate
from .vectors import Number, Vec

__all__ = [
    "Number", "Vec", "array_grid", "array_linear", "array_polar", "bend", "blend", "blobs", "box", "box_exact",
    "capped_cylinder", "capsule", "chamfer_difference", "chamfer_intersection", "chamfer_union", "circle",
    "clearance", "cone", "convex_polygon", "cylinder", "diamond", "difference", "dilate", "dodecahedron",
    "elongate", "ellipsoid", "erode", "extrude", "gyroid", "half_space", "icosahedron", "infill", "inner_shell",
    "intersection", "loft", "mirror", "morph", "neovius", "octahedron", "offset", "pyramid", "rectangle",
    "regular_polygon", "revolve", "ring", "rotate", "rounded_box", "rounded_rectangle", "scale", "schwarz_p",
    "shear", "shell", "slab", "smooth_difference", "smooth_intersection", "smooth_union", "sphere", "symmetric",
    "taper", "tetrahedron", "torus", "torus_exact", "transform", "translate", "triangle", "twist", "union",
]
