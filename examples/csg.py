"""CSG and levels of detail
========================

Constructive solid geometry with Min/Max: a box, minus a sphere, plus a torus, then its octree LOD."""

import os

import sympy

import implc
from implc import shapes
from implc.view.render import render_voxels, save_png

depth = int(os.environ.get("IMPLC_EXAMPLE_DEPTH", 8))
part = shapes.union(shapes.difference(shapes.box((0.6, 0.6, 0.6)), shapes.sphere(0.75)),
                    shapes.rotate(shapes.torus(0.8, 0.1), sympy.pi / 2, "x"))
voxels = implc.voxelize(implc.compile(part), depth)
coarse_coords, coarse_normals = voxels.octree.level(depth - 2)  # level of detail: 4x fewer cells per axis
print(f"{len(voxels)} voxels; {len(coarse_coords)} nodes two levels up")
save_png(render_voxels(voxels, size=512, lod=depth - 2), "csg_lod.png")
