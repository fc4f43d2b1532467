"""A surface of your own
=====================

Define your own surface with SymPy, voxelize it and render it."""

import os

import sympy

import implc
from implc import x, y, z
from implc.view.render import render_voxels, save_png

depth = int(os.environ.get("IMPLC_EXAMPLE_DEPTH", 8))
# a wobbly sphere: F < 0 inside
surface = implc.compile(x**2 + y**2 + z**2 - sympy.Rational(1, 2) + sympy.sin(8 * x) * sympy.sin(8 * y) / 20)
voxels = implc.voxelize(surface, depth)
print(voxels, voxels.stats.summary())
save_png(render_voxels(voxels, size=512), "custom_surface.png")
