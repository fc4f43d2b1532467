"""Exporting a point cloud
=======================

Voxelize a torus and export it as a binary PLY point cloud with normals (and as .npz)."""

import os

import implc
from implc import shapes
from implc.files import voxel_files
from implc.view.render import render_voxels, save_png

depth = int(os.environ.get("IMPLC_EXAMPLE_DEPTH", 8))
voxels = implc.voxelize(implc.compile(shapes.torus(0.6, 0.25)), depth)
voxel_files.save(voxels, "torus.ply")  # x y z nx ny nz per voxel centre: opens in MeshLab, CloudCompare, Open3D
voxel_files.save(voxels, "torus.npz")  # exact: coords, normals, depth, bounds
print(f"wrote {len(voxels)} points to torus.ply and torus.npz")
save_png(render_voxels(voxels, size=512), "torus.png")  # what the points show, shaded by their normals
