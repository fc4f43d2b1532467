"""Seeing voxels and meshes: PNG splats, levels of detail, the browser page and its server."""
