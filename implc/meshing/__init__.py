"""mesh() and Mesh: contouring the voxelized cells, simplification, mesh files."""
