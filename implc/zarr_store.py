"""Zarr v3 export: the dense occupancy of voxels (the solid where the inside is classified), written
shard by shard from the voxels and the inside octants, never as one dense array.

The array is bool, indexed [i, j, k] like :meth:`implc.voxelization.Voxels.to_dense`, in chunks of
:data:`CHUNK`³ cells gathered into shards of :data:`SHARD`³ (Zarr v3 sharding: few files, each read in
parts). Each shard is filled from the voxels and octants inside it (both bucketed once by shard), so the
peak memory is one shard plus the bucketing arrays (a few bytes per voxel and octant). Attributes record
the grid depth, the bounds and whether the inside is included. The store is written under a temporary
name beside the target and renamed into place.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .atomic_file import replacing_folder
from .voxelization import paint_cubes

CHUNK = 64
SHARD = 256


def _shard_keys(cells: np.ndarray, shift: int, per_axis: int) -> np.ndarray:
    blocks = cells.astype(np.int64) >> shift
    return (blocks[:, 0] * per_axis + blocks[:, 1]) * per_axis + blocks[:, 2]


def save_zarr(voxels, path) -> Path:
    """Write the occupancy of ``voxels`` (with the inside octants, for a solid) as a Zarr v3 array at
    ``path`` (a folder, conventionally ending in .zarr), readable by ``zarr.open``."""
    import zarr
    path = Path(path)
    n = 1 << voxels.depth
    shard = min(SHARD, n)
    chunk = min(CHUNK, shard)
    per_axis = n // shard
    shift = shard.bit_length() - 1
    inside = voxels.inside if voxels.inside is not None else np.empty((0, 4), dtype=np.int32)
    sizes = np.left_shift(1, voxels.depth - inside[:, 3].astype(np.int64))
    big = sizes > shard  # octants larger than a shard cover whole shards: few, painted shard by shard
    small = inside[~big]
    small_sizes = sizes[~big]
    small_first = small[:, :3].astype(np.int64) * small_sizes[:, None]  # their first cell
    voxel_keys = _shard_keys(voxels.coords, shift, per_axis)
    voxel_order = np.argsort(voxel_keys, kind="stable")
    voxel_keys = voxel_keys[voxel_order]
    small_keys = _shard_keys(small_first, shift, per_axis)
    small_order = np.argsort(small_keys, kind="stable")
    small_keys = small_keys[small_order]

    with replacing_folder(path) as tmp:
        about = {"depth": voxels.depth, "bounds": [list(b) for b in voxels.bounds], "solid": voxels.inside is not None,
                 "index": "[i, j, k]: cell (i, j, k) of the grid"}
        array = zarr.create_array(store=str(tmp), shape=(n, n, n), chunks=(chunk,) * 3, shards=(shard,) * 3,
                                  dtype="bool", fill_value=False, zarr_format=3, overwrite=True,
                                  attributes={"implc": about})
        big_rows = inside[big]
        for key in range(per_axis ** 3):
            block = np.zeros((shard,) * 3, dtype=bool)
            origin = np.array([key // per_axis**2, key // per_axis % per_axis, key % per_axis]) * shard
            lo, hi = np.searchsorted(voxel_keys, [key, key + 1])
            cells = voxels.coords[voxel_order[lo:hi]].astype(np.int64) - origin
            block[cells[:, 0], cells[:, 1], cells[:, 2]] = True
            lo, hi = np.searchsorted(small_keys, [key, key + 1])
            here = small_order[lo:hi]
            paint_cubes(block, small_first[here] - origin, small_sizes[here])
            for i, j, k, level in big_rows:  # whole shards inside an octant
                size = 1 << (voxels.depth - int(level))
                first = np.array([i, j, k], dtype=np.int64) * size
                if np.all(first <= origin) and np.all(origin < first + size):
                    block[...] = True
            if block.any():
                array[origin[0]:origin[0] + shard, origin[1]:origin[1] + shard, origin[2]:origin[2] + shard] = block
    return path


def describe_zarr(path) -> list[str]:
    """Lines describing a Zarr store this module wrote (for ``implc info``); ValueError if it is not one."""
    import zarr
    try:
        array = zarr.open_array(str(path), mode="r")
    except Exception as exc:  # zarr raises several kinds for a folder that is not an array
        raise ValueError(f"cannot read {path} as a Zarr array: {type(exc).__name__}: {exc}") from None
    about = array.attrs.get("implc")
    if not isinstance(about, dict):
        raise ValueError(f"{path} is a Zarr array but not one implc wrote (no 'implc' attribute)")
    n = array.shape[0]
    return [f"file     {path}, Zarr v{array.metadata.zarr_format} {array.dtype} array "
            f"{'x'.join(map(str, array.shape))}, chunks {array.chunks}, shards {array.shards}",
            f"grid     {n}³ (depth {about['depth']}) over {tuple(tuple(b) for b in about['bounds'])}",
            f"content  {'the solid (inside and boundary)' if about['solid'] else 'the boundary voxels'}, "
            f"indexed {about['index']}"]
