"""Zarr v3 export: the dense occupancy of voxels (the solid where the inside is classified), written
shard by shard, never as one dense array.

The array is bool, indexed [i, j, k] like :meth:`implc.voxelization.Voxels.to_dense`, in chunks of
:data:`CHUNK`³ cells gathered into shards of :data:`SHARD`³ (Zarr v3 sharding: few files, each read in
parts). Attributes record the grid depth, the bounds and whether the inside is included. The store is
written under a temporary name beside the target and renamed into place.

Two ways in: :func:`save_zarr` writes a voxelization held in memory; :func:`write_zarr` voxelizes
straight into the store, the voxelizer handing each task's voxels and inside octants (in Morton order) to
a :class:`ShardWriter` as the tasks finish, which writes every shard no later task can touch. Nothing
then holds all the voxels: the peak memory is the tasks in flight, the pending shards' voxels and one
shard.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .atomic_file import replacing_folder
from .morton import morton_codes
from .subdivide import Subdivider, SubdivisionStats, default_workers
from .surface import usable_bounds
from .untrusted import printable
from .voxelization import _check_count, _check_depth, _check_leaf_options, paint_cubes, volume_bounds

if TYPE_CHECKING:
    from .surface import Surface
    from .voxelization import Voxels

CHUNK = 128  # 2 MiB of bool: zarr recommends chunks of 1 MB or more; 64³ made writing twice as slow
SHARD = 256


def _create(path: Path, depth: int, bounds, solid: bool):
    import zarr
    n = 1 << depth
    shard = min(SHARD, n)
    about: dict[str, Any] = {"depth": depth, "bounds": [list(b) for b in bounds], "solid": solid,
             "index": "[i, j, k]: cell (i, j, k) of the grid"}
    return zarr.create_array(store=str(path), shape=(n, n, n), chunks=(min(CHUNK, shard),) * 3, shards=(shard,) * 3,
                             dtype="bool", fill_value=False, zarr_format=3, overwrite=True, attributes={"implc": about})


class ShardWriter:
    """Fills the shards of a bool Zarr array from voxels and inside octants added in any order, writing a
    shard when :meth:`flush` is told no later addition touches it. Octants larger than a shard cover
    whole shards and are written at once; empty shards are never written (they read as False)."""

    def __init__(self, array, depth: int):
        self.array, self.depth = array, depth
        self.shard = array.shards[0]
        self.shift = self.shard.bit_length() - 1
        self.coords: list[np.ndarray] = []
        self.cubes: list[tuple[np.ndarray, np.ndarray]] = []  # (first cells, edges) of octants within a shard
        self.shards_written = 0

    def add(self, coords: np.ndarray, inside: np.ndarray | None = None) -> None:
        """Voxels (n, 3) and inside octants (m, 4) rows (i, j, k, level); both are copied."""
        if len(coords):
            self.coords.append(np.array(coords, dtype=np.uint32))
        if inside is None or not len(inside):
            return
        sizes = np.left_shift(np.int64(1), self.depth - inside[:, 3].astype(np.int64))
        firsts = inside[:, :3].astype(np.int64) * sizes[:, None]
        big = sizes > self.shard
        full = np.ones((self.shard,) * 3, dtype=bool) if np.any(big) else None
        for first, size in zip(firsts[big], sizes[big]):
            per = int(size) >> self.shift
            for step in np.ndindex(per, per, per):  # the whole shards the octant covers
                self._write(first + np.array(step) * self.shard, full)
        if not np.all(big):
            self.cubes.append((firsts[~big], sizes[~big]))

    def _write(self, origin, block):
        i, j, k = map(int, origin)
        s = self.shard
        self.array[i:i + s, j:j + s, k:k + s] = block
        self.shards_written += 1

    def flush(self, before: int | None = None) -> None:
        """Write every pending shard whose Morton code (in shards) is below ``before`` (None: all)."""
        coords = np.concatenate(self.coords) if self.coords else np.empty((0, 3), np.uint32)
        firsts = np.concatenate([f for f, _ in self.cubes]) if self.cubes else np.empty((0, 3), np.int64)
        sizes = np.concatenate([s for _, s in self.cubes]) if self.cubes else np.empty(0, np.int64)
        vkey = morton_codes(coords >> np.uint32(self.shift))
        ckey = morton_codes(firsts >> self.shift)
        done_v = np.ones(len(vkey), bool) if before is None else vkey < np.uint64(before)
        done_c = np.ones(len(ckey), bool) if before is None else ckey < np.uint64(before)
        self.coords = [coords[~done_v]] if not np.all(done_v) else []
        self.cubes = [(firsts[~done_c], sizes[~done_c])] if not np.all(done_c) else []
        coords, vkey, firsts, sizes, ckey = coords[done_v], vkey[done_v], firsts[done_c], sizes[done_c], ckey[done_c]
        vorder, corder = np.argsort(vkey, kind="stable"), np.argsort(ckey, kind="stable")
        coords, vkey, firsts, sizes, ckey = coords[vorder], vkey[vorder], firsts[corder], sizes[corder], ckey[corder]
        for key in np.unique(np.concatenate([vkey, ckey])):
            v0, v1 = np.searchsorted(vkey, [key, key + np.uint64(1)])
            c0, c1 = np.searchsorted(ckey, [key, key + np.uint64(1)])
            sample = coords[v0].astype(np.int64) if v1 > v0 else firsts[c0]
            origin = (sample >> self.shift) << self.shift
            block = np.zeros((self.shard,) * 3, dtype=bool)
            cells = coords[v0:v1].astype(np.int64) - origin
            block[cells[:, 0], cells[:, 1], cells[:, 2]] = True
            paint_cubes(block, firsts[c0:c1] - origin, sizes[c0:c1])
            self._write(origin, block)


def save_zarr(voxels: Voxels, path: str | os.PathLike[str]) -> Path:
    """Write the occupancy of ``voxels`` (with the inside octants, for a solid) as a Zarr v3 array at
    ``path`` (a folder, conventionally ending in .zarr), readable by ``zarr.open``."""
    path = Path(path)
    with replacing_folder(path) as tmp:
        writer = ShardWriter(_create(tmp, voxels.depth, voxels.bounds, voxels.inside is not None), voxels.depth)
        writer.add(voxels.coords, voxels.inside)
        writer.flush()
    return path


@dataclass
class ZarrWrite:
    """What :func:`write_zarr` wrote: counts, the subdivider's statistics and the volume bounds."""
    path: Path
    depth: int
    bounds: tuple
    voxels: int
    inside_octants: int
    inside_voxels: int
    shards: int
    stats: SubdivisionStats
    seconds: float
    solid: bool

    def volume_bounds(self) -> tuple[float, float]:
        """As :meth:`implc.voxelization.Voxels.volume_bounds` (a solid only)."""
        if not self.solid:
            raise ValueError("a shell was written: write_zarr(..., solid=True) classifies the inside")
        return volume_bounds(self.bounds, self.depth, self.inside_voxels, self.voxels)


def write_zarr(surface: Surface, depth: int, path: str | os.PathLike[str], *, solid: bool = True,
               workers: int | None = None, progress: bool = False, mean_value_levels: int = 0,
               refine_leaves: bool | str = "auto") -> ZarrWrite:
    """Voxelize ``surface`` at ``depth`` straight into a Zarr v3 array at ``path`` (the occupancy of
    :func:`save_zarr`), in memory bounded by the tasks in flight rather than the voxel count
    (``mean_value_levels``, ``refine_leaves``: as :func:`implc.voxelize`'s)."""
    depth = _check_depth(depth)
    workers = default_workers() if workers is None else _check_count("workers", workers)
    mean_value_levels, refine_leaves = _check_leaf_options(mean_value_levels, refine_leaves)
    path = Path(path)
    t0 = time.perf_counter()
    subdivider = Subdivider(surface, depth, workers, surface.runtime, solid=solid,
                            mean_value_levels=min(mean_value_levels, depth), refine_leaves=refine_leaves)
    cells, level = subdivider.plan()
    task_keys = morton_codes(cells.astype(np.int64) << (depth - level)) if len(cells) else np.empty(0, np.uint64)
    counts = {"voxels": 0, "inside": 0, "inside_voxels": 0, "tasks": 0}
    bar = None
    with replacing_folder(path) as tmp:
        writer = ShardWriter(_create(tmp, depth, surface.bounds, solid), depth)
        shard_shift = np.uint64(3 * writer.shift)

        def task_done():
            t = counts["tasks"] = counts["tasks"] + 1
            writer.flush(int(task_keys[t] >> shard_shift) if t < len(task_keys) else None)

        def count_inside(rows):
            counts["inside"] += len(rows)
            edges_log2 = depth - rows[:, 3].astype(np.int64)
            counts["inside_voxels"] += int(np.sum(np.left_shift(np.int64(1), 3 * edges_log2)))

        def emit(coords, _normals):
            counts["voxels"] += len(coords)
            writer.add(coords)
            if not solid:
                task_done()

        def emit_inside(rows):
            count_inside(rows)
            writer.add(np.empty((0, 3), np.uint32), rows)
            task_done()

        plan_inside = subdivider.inside
        if solid:
            count_inside(plan_inside)
            writer.add(np.empty((0, 3), np.uint32), plan_inside)
        if progress:
            from tqdm import tqdm
            bar = tqdm(total=len(cells), unit="octant", desc=f"voxelize {1 << depth}³ to Zarr", leave=False)
        try:
            stats = subdivider.run(emit, progress=bar, plan=(cells, level), emit_inside=emit_inside)
        finally:
            if bar is not None:
                bar.close()
        writer.flush()
    return ZarrWrite(path, depth, surface.bounds, counts["voxels"], counts["inside"], counts["inside_voxels"],
                     writer.shards_written, stats, time.perf_counter() - t0, solid)


def describe_zarr(path: str | os.PathLike[str]) -> list[str]:
    """Lines describing a Zarr store this module wrote (for ``implc info``); ValueError if it is not one."""
    import zarr
    try:
        array = zarr.open_array(str(path), mode="r")
    except Exception as exc:  # zarr raises several kinds for a folder that is not an array
        raise ValueError(f"cannot read {path} as a Zarr array: {type(exc).__name__}: {exc}") from None
    about = array.attrs.get("implc")
    if not isinstance(about, dict):
        raise ValueError(f"{path} is a Zarr array but not one implc wrote (no 'implc' attribute)")
    depth, bounds, solid = about.get("depth"), about.get("bounds"), about.get("solid")
    if type(depth) is not int or not 1 <= depth <= 21:
        raise ValueError(f"{path}: damaged implc Zarr store (depth {printable(repr(depth), 40)})")
    n = 1 << depth
    if tuple(array.shape) != (n, n, n) or str(array.dtype) != "bool":
        raise ValueError(f"{path}: damaged implc Zarr store (a {printable(str(array.dtype), 20)} array "
                         f"{'x'.join(map(str, array.shape))}, where depth {depth} means bool {n}³)")
    if not (isinstance(bounds, list) and len(bounds) == 3 and all(
            isinstance(b, list) and len(b) == 2 and all(type(v) in (int, float) and math.isfinite(v) for v in b)
            and b[0] < b[1] for b in bounds)) or not usable_bounds(bounds):
        raise ValueError(f"{path}: damaged implc Zarr store (bounds {printable(repr(bounds), 60)})")
    if type(solid) is not bool:
        raise ValueError(f"{path}: damaged implc Zarr store (solid {printable(repr(solid), 40)})")
    return [f"file     {path}, Zarr v{array.metadata.zarr_format} {array.dtype} array "
            f"{'x'.join(map(str, array.shape))}, chunks {array.chunks}, shards {array.shards}",
            f"grid     {n}³ (depth {depth}) over {tuple(tuple(b) for b in bounds)}",
            f"content  {'the solid (inside and boundary)' if solid else 'the boundary voxels'}, "
            f"indexed {printable(str(about.get('index', '?')), 80)}"]
