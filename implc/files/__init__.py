"""Voxel files (npz, ply, npy, VDB, Zarr), slices and scene files: writing and validated reading."""
