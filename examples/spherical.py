"""A surface in spherical coordinates
==================================

A surface given in spherical coordinates: r, theta (polar) and phi (azimuth) are ready-made symbols."""

import os

import sympy

import implc
from implc import phi, r, theta
from implc.view.render import View, render_voxels, save_png

depth = int(os.environ.get("IMPLC_EXAMPLE_DEPTH", 9))
surface = implc.compile(sympy.sin(4 * theta) * sympy.sin(8 * phi) - r)  # the paper's Scene 2
voxels = implc.voxelize(surface, depth, progress=True)
print(f"{len(voxels)} voxels, {voxels.stats.interval_evaluations} interval evaluations")
save_png(render_voxels(voxels, size=768, view=View(azimuth=20, elevation=40)), "spherical.png")
