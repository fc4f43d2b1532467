"""voxelize() and Voxels: the walk's tasks gathered into storage backends (octree, grid, coordinates)."""
