"""Blended blobs
=============

Blended blobs with the paper's polynomial g(d) = (d² − R²)⁴ / R⁸."""

import os

import implc
from implc import shapes
from implc.view.render import render_voxels, save_png

depth = int(os.environ.get("IMPLC_EXAMPLE_DEPTH", 8))
centers = [(-0.4, 0, 0), (0.4, 0, 0), (0, 0.45, 0.1), (0, -0.3, 0.35)]
field = shapes.blobs(centers, radius=0.6, threshold=0.2, weights=[1, 1, 0.8, 1.2])
voxels = implc.voxelize(implc.compile(field), depth)
print(voxels)
save_png(render_voxels(voxels, size=512), "blobs.png")
