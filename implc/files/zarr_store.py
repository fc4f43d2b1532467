"""Zarr v3 stores of voxelizations, written shard by shard by tasks that each own their shards: in this
process, or on a Dask cluster (:mod:`implc.cluster.tasks`) with the same tasks and the same store.

A store is a group (``zarr.open_group``):

- ``occupancy``: bool (n, n, n) indexed [i, j, k] like :meth:`implc.voxelizer.voxelize.Voxels.to_dense`, the
  boundary voxels (and a solid's inside octants painted), in chunks of :data:`CHUNK`³ gathered into shards
  of :data:`SHARD`³: the *bricks*.
- ``lod/K`` for K = 1 … depth − 1: the occupancy of the 2^K grid (a cell is set where any cell below it
  is): a level of detail read on its own.
- ``voxels/coords`` (N, 3) uint32 and ``voxels/normals`` (N, 3) float32: the boundary voxels and their
  unit normals in Morton order, in chunks of :data:`ROW_CHUNK` rows; ``bricks`` (B, 3) int32: the bricks
  holding voxels or inside octants, in Morton order, and ``voxels/rows`` (B + 1) int64: where each
  brick's voxels start, so that a region is read without the rest (:func:`load_zarr`).
- a solid: ``inside/octants`` (M, 4) int32 rows (i, j, k, level) finer than a brick, in Morton order, with
  ``inside/rows`` (B + 1), and ``inside/coarse`` (K, 4): the octants of a brick or larger.
- the group's ``implc`` attributes: depth, bounds, solid, the layout, and ``manifest`` — written last, so
  a store without it is incomplete (a run that stopped) and readers say so.

Every shard has exactly one writer. A *task* is an octant at the task level
(:func:`implc.cluster.tasks.task_level`); it holds whole bricks, and at every level of detail its own shards,
and writes them. Its voxels, normals and inside octants go to a part file of its own (``_parts/``,
written under a temporary name and renamed: a finished task is a part on disk, which ``resume`` skips).
Once every task is done, the row arrays are written shard by shard, each shard by one task reading the
parts it spans, and the small arrays and the manifest by the caller. The store is built under
``NAME.partial`` beside the target and renamed into place when complete; an interrupted run leaves the
``.partial`` folder, which ``resume=True`` finishes.
"""

from __future__ import annotations

import contextlib
import functools
import json
import math
import os
import re
import shutil
import tempfile
import time
from collections.abc import Iterator
from contextvars import ContextVar
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..cluster.recipe import SurfaceRecipe, build, recipe_of, software
from ..cluster.tasks import (
    TaskVoxels,
    cell_level,
    connect,
    peak_memory,
    plan_tasks,
    run_stats,
    run_tasks,
    task_level,
    task_progress,
    task_voxels,
    worker_threads,
)
from ..common.atomic_file import replacing_folder, resumable_folder
from ..common.bounds import usable_bounds
from ..common.threads import default_workers
from ..common.untrusted import printable
from ..engines.morton import morton_codes
from ..engines.walk import SubdivisionStats
from ..errors import StoreError
from ..native import abi
from ..voxelizer.voxelize import (
    Voxels,
    _check_count,
    _check_depth,
    _check_leaf_options,
    inside_voxel_count,
    paint_cubes,
    volume_bounds,
)

if TYPE_CHECKING:
    from ..engines.surface import Surface

FORMAT = 2
"""The store's layout version (1: implc 0.2's single occupancy array)."""
CHUNK = 128
"""The occupancy's chunk edge (2 MiB of bool: zarr recommends chunks of 1 MB or more, and smaller chunks
write more slowly: ``implc bench --sections files`` measures the writers)."""
SHARD = 256
"""A brick: the occupancy's shard edge, the unit the voxel rows are indexed by."""
ROW_CHUNK = 1 << 16
"""Rows per chunk of the voxel and octant lists."""
ROW_SHARD = 1 << 20
"""Rows per shard of those lists: each written by one task."""
CLIENT_LEVELS = 3
"""The levels of detail up to three below the task level are small (8³ cells per task at most) and
written whole by the caller from each task's block; finer ones by the tasks, shard by shard."""


@dataclass(frozen=True)
class Sizes:
    """A store's chunk and shard sizes (the defaults above); the store holds the same voxels for every
    value, and records its own (tests make them small, so that one grid has many bricks and shards)."""

    shard: int = SHARD
    chunk: int = CHUNK
    row_chunk: int = ROW_CHUNK
    row_shard: int = ROW_SHARD
    client_levels: int = CLIENT_LEVELS


SIZES: ContextVar[Sizes] = ContextVar("implc_zarr_sizes", default=Sizes())
"""The :class:`Sizes` a store written in this context takes (:func:`sizes` sets them)."""


@contextlib.contextmanager
def sizes(chosen: Sizes) -> Iterator[None]:
    """Within the block, stores are written with the chunk and shard sizes ``chosen``."""
    token = SIZES.set(chosen)
    try:
        yield
    finally:
        SIZES.reset(token)


@dataclass(frozen=True)
class Layout:
    """Where everything of a store goes: the grid, the bricks, the tasks, the levels of detail."""
    depth: int
    bounds: tuple
    solid: bool
    brick: int
    chunk: int
    row_chunk: int = ROW_CHUNK
    row_shard: int = ROW_SHARD
    client_levels: int = CLIENT_LEVELS

    @property
    def brick_level(self) -> int:
        """The level whose cells are the bricks."""
        return self.depth - (self.brick.bit_length() - 1)

    @property
    def task_level(self) -> int:
        """The level whose octants are the tasks (:func:`implc.cluster.tasks.task_level`)."""
        return task_level(self.depth, self.brick_level)

    @property
    def client_level(self) -> int:
        """The finest level of detail the caller writes (0: none)."""
        return min(self.task_level + self.client_levels, self.depth - 1)

    def lod_shard(self, level: int) -> int:
        """The shard edge of level of detail ``level`` (> :attr:`client_level`): one task's at most."""
        return min(self.brick, 1 << (level - self.task_level))

    @classmethod
    def of(cls, depth: int, bounds, solid: bool) -> Layout:
        chosen = SIZES.get()
        brick = min(chosen.shard, 1 << depth)
        return cls(depth, tuple(tuple(map(float, b)) for b in bounds), bool(solid), brick, min(chosen.chunk, brick),
                   chosen.row_chunk, chosen.row_shard, chosen.client_levels)

    def describe(self) -> dict:
        """What the store's attributes record of the layout."""
        return {"brick": self.brick, "chunk": self.chunk, "task_level": self.task_level}


def _first_cells(rows: np.ndarray, depth: int) -> np.ndarray:
    """The first cell (at ``depth``) of octant rows (i, j, k, level), int64."""
    return rows[:, :3].astype(np.int64) << (depth - rows[:, 3].astype(np.int64))[:, None]


def _octant_keys(rows: np.ndarray, depth: int) -> np.ndarray:
    """Morton codes of the octants' first cells: their order in the store."""
    return morton_codes(_first_cells(rows, depth)) if len(rows) else np.empty(0, np.uint64)


def paint(block: np.ndarray, origin: np.ndarray, level: int, depth: int, coords: np.ndarray,
          octants: np.ndarray) -> None:
    """Set, in ``block`` (a cube of cells of the 2^level grid whose first cell is ``origin``), the cells
    holding any of ``coords`` (voxels of the 2^depth grid) or meeting any of ``octants`` (rows i, j, k,
    octant level): the occupancy at ``level`` of what lies in the block."""
    shift = depth - level
    n = block.shape[0]
    if len(coords):  # one flat index per voxel: a third of the work of indexing by three arrays
        cells = (coords.astype(np.int64) >> shift) - origin
        block.reshape(-1)[(cells[:, 0] * n + cells[:, 1]) * n + cells[:, 2]] = True
    if len(octants):
        levels = octants[:, 3].astype(np.int64)
        coarse = levels <= level  # a cube of cells at this level
        if np.any(coarse):
            sizes = np.left_shift(np.int64(1), level - levels[coarse])
            paint_cubes(block, octants[coarse, :3].astype(np.int64) * sizes[:, None] - origin, sizes)
        if not np.all(coarse):  # inside one cell at this level
            cells = (octants[~coarse, :3].astype(np.int64) >> (levels[~coarse] - level)[:, None]) - origin
            block[cells[:, 0], cells[:, 1], cells[:, 2]] = True


def _compressors() -> Any:
    """Every array's codec: zarr's default zstd, with the frame's checksum, so that a damaged chunk is an
    error when it is read rather than other data (without it, damage inside a chunk decoded to rows in
    the wrong places)."""
    from zarr.codecs import ZstdCodec
    return ZstdCodec(level=0, checksum=True)


def _create(folder: Path, layout: Layout, plan: dict) -> Any:
    """The group with its occupancy and level-of-detail arrays (rows come once their lengths are known)."""
    import zarr
    n = 1 << layout.depth
    about: dict[str, Any] = {"format": FORMAT, "depth": layout.depth, "bounds": [list(b) for b in layout.bounds],
                             "solid": layout.solid, "layout": layout.describe(), "plan": plan,
                             "index": "[i, j, k]: cell (i, j, k) of the grid"}
    group = zarr.open_group(str(folder), mode="w", zarr_format=3, attributes={"implc": about})
    group.create_array("occupancy", shape=(n, n, n), chunks=(layout.chunk,) * 3, shards=(layout.brick,) * 3,
                       dtype="bool", fill_value=False, compressors=_compressors())
    for level in range(1, layout.depth):
        edge = 1 << level
        if level <= layout.client_level:
            group.create_array(f"lod/{level}", shape=(edge,) * 3, chunks=(min(layout.chunk, edge),) * 3, dtype="bool",
                               fill_value=False, compressors=_compressors())
        else:
            shard = layout.lod_shard(level)
            group.create_array(f"lod/{level}", shape=(edge,) * 3, chunks=(min(layout.chunk, shard),) * 3,
                               shards=(shard,) * 3, dtype="bool", fill_value=False, compressors=_compressors())
    return group


class _FullShards:
    """The encoded bytes of an all-True shard, made once per shard shape and copied to each full shard's
    key: every shard of a solid's inside is the same file (compressing 16 MiB of True each time cost
    14 ms a shard)."""

    def __init__(self):
        self.encoded: dict[tuple, bytes] = {}

    def write(self, array, origin: np.ndarray, folder: Path) -> None:
        import zarr
        shard, chunk = array.shards[0], array.chunks[0]
        if (shard, chunk) not in self.encoded:
            with tempfile.TemporaryDirectory() as scratch:
                template = zarr.create_array(store=scratch, shape=(shard,) * 3, chunks=(chunk,) * 3,
                                             shards=(shard,) * 3, dtype="bool", fill_value=False, zarr_format=3,
                                             compressors=_compressors())
                template[...] = True
                self.encoded[(shard, chunk)] = (Path(scratch) / "c" / "0" / "0" / "0").read_bytes()
        index = (origin // shard).astype(int)
        key = folder / array.path / "c" / str(index[0]) / str(index[1]) / str(index[2])
        key.parent.mkdir(parents=True, exist_ok=True)
        tmp = key.with_name(f".{key.name}.{os.getpid()}.tmp")
        tmp.write_bytes(self.encoded[(shard, chunk)])
        os.replace(tmp, key)


@dataclass
class _Level:
    """One level's shard being filled by a task (bricks arrive in Morton order, so a shard is complete
    when a brick outside it arrives)."""
    array: Any
    level: int
    edge: int
    origin: np.ndarray | None = None
    block: np.ndarray | None = None
    full: bool = True


class _TaskWriter:
    """Writes one task's bricks and level-of-detail shards, and records the shard keys it wrote."""

    def __init__(self, group, layout: Layout, folder: Path, full_shards: _FullShards):
        self.layout, self.folder, self.full_shards = layout, folder, full_shards
        self.levels: list[_Level] = []
        for level in range(max(layout.client_level, 1), layout.depth + 1):
            array = group["occupancy"] if level == layout.depth else group[f"lod/{level}"]
            edge = (layout.brick if level == layout.depth else layout.lod_shard(level)) \
                if level > layout.client_level else 1 << (level - layout.task_level)
            self.levels.append(_Level(array, level, edge))
        self.written: list[str] = []
        self.client_block: np.ndarray | None = None

    def brick(self, origin: np.ndarray, coords: np.ndarray, octants: np.ndarray, full: bool) -> None:
        """Add one brick (its first cell ``origin``): its voxels and finer octants, or ``full`` (all
        inside). Its occupancy is painted once, then halved level by level into each level's shard."""
        depth, edge = self.layout.depth, self.layout.brick
        block = None
        if not full:
            block = np.zeros((edge,) * 3, bool)
            paint(block, origin, depth, depth, coords, octants)
        for lv in reversed(self.levels):
            shard_origin = ((origin >> (depth - lv.level)) // lv.edge) * lv.edge
            if lv.origin is None or np.any(shard_origin != lv.origin):
                self._flush(lv)
                lv.origin, lv.block, lv.full = shard_origin, np.zeros((lv.edge,) * 3, bool), True
            lo = (origin >> (depth - lv.level)) - shard_origin
            size = max(1, edge >> (depth - lv.level))
            assert lv.block is not None
            target = lv.block[lo[0]:lo[0] + size, lo[1]:lo[1] + size, lo[2]:lo[2] + size]
            if full:
                target[...] = True
                continue
            lv.full = False
            if block is not None and block.shape[0] > size:  # the brick spans less than a cell here
                block = np.array([[[block.any()]]])
            if block is not None:
                target |= block
                block = _pooled(block) if block.shape[0] > 1 else block

    def _flush(self, lv: _Level) -> None:
        if lv.block is None or lv.origin is None:
            return
        block, origin = lv.block, lv.origin
        lv.block = None
        if lv.level <= self.layout.client_level:  # the caller writes this level: kept for the part
            self.client_block = block
            return
        full = lv.full and block.all()
        if not full and not block.any():
            return
        if full:
            self.full_shards.write(lv.array, origin, self.folder)
        else:
            e = lv.edge
            lv.array[origin[0]:origin[0] + e, origin[1]:origin[1] + e, origin[2]:origin[2] + e] = block
        self.written.append(f"{lv.array.path}/{'/'.join(map(str, (origin // lv.edge).tolist()))}")

    def finish(self) -> None:
        for lv in self.levels:
            self._flush(lv)


def _part_path(folder: Path, task: int) -> Path:
    return folder / "_parts" / f"{task:08d}.npz"


def _has_parts(folder: Path) -> bool:
    """Whether a stopped run left finished tasks in ``folder`` (worth keeping for ``resume``)."""
    parts = folder / "_parts"
    return parts.is_dir() and any(p.suffix == ".npz" and not p.name.startswith(".") for p in parts.iterdir())


def store_task(folder: Path, layout: Layout, task: int, cell: Any, voxels: TaskVoxels, plan_octants: np.ndarray,
               full: bool) -> dict:
    """Write one task's shards from what it found (``voxels``; ``full``: its octant lies inside, every
    brick full) and its part file; the summary the caller assembles the store from."""
    import zarr
    t0 = time.perf_counter()
    depth, shift = layout.depth, layout.depth - layout.brick_level
    group = zarr.open_group(str(folder), mode="r+")
    writer = _TaskWriter(group, layout, folder, _FULL_SHARDS)
    coords, normals, inside = voxels.coords, voxels.normals, voxels.inside
    fine = inside[inside[:, 3] > layout.brick_level] if len(inside) else inside
    coarse = inside[inside[:, 3] <= layout.brick_level] if len(inside) else inside
    coarse = np.concatenate([plan_octants.astype(np.int32).reshape(-1, 4), coarse])
    fine = fine[np.argsort(_octant_keys(fine, depth), kind="stable")]
    # the bricks: of the voxels, of the fine octants, and the full ones (inside octants of a brick or larger)
    task_edge = 1 << (layout.brick_level - layout.task_level)  # bricks per axis in the task
    if full:
        steps = np.array(list(np.ndindex(task_edge, task_edge, task_edge)), np.int64).reshape(-1, 3)
        full_bricks = np.asarray(cell, np.int64) * task_edge + steps
    else:
        full_bricks = np.empty((0, 3), np.int64)
        for row in coarse[coarse[:, 3] > layout.task_level] if len(coarse) else coarse:
            per = 1 << (layout.brick_level - int(row[3]))
            steps = np.array(list(np.ndindex(per, per, per)), np.int64).reshape(-1, 3)
            full_bricks = np.concatenate([full_bricks, row[:3].astype(np.int64) * per + steps])
    voxel_bricks = coords.astype(np.int64) >> shift
    fine_bricks = _first_cells(fine, depth) >> shift if len(fine) else np.empty((0, 3), np.int64)
    all_bricks = np.concatenate([voxel_bricks, fine_bricks, full_bricks])
    keys = morton_codes(all_bricks) if len(all_bricks) else np.empty(0, np.uint64)
    unique_keys, first = np.unique(keys, return_index=True)
    bricks = all_bricks[first]
    vkeys = keys[:len(voxel_bricks)]
    fkeys = keys[len(voxel_bricks):len(voxel_bricks) + len(fine_bricks)]
    full_keys = set(keys[len(voxel_bricks) + len(fine_bricks):].tolist())
    v_rows = np.searchsorted(vkeys, unique_keys, side="left"), np.searchsorted(vkeys, unique_keys, side="right")
    f_rows = np.searchsorted(fkeys, unique_keys, side="left"), np.searchsorted(fkeys, unique_keys, side="right")
    listed = []  # bricks holding rows (voxels or fine octants), with their row counts
    for b, key in enumerate(unique_keys.tolist()):
        v0, v1, f0, f1 = v_rows[0][b], v_rows[1][b], f_rows[0][b], f_rows[1][b]
        writer.brick(bricks[b] * layout.brick, coords[v0:v1], fine[f0:f1], key in full_keys)
        if v1 > v0 or f1 > f0:
            listed.append((b, v1 - v0, f1 - f0))
    writer.finish()
    client_edge = 1 << max(layout.client_level - layout.task_level, 0)
    client_block = writer.client_block if writer.client_block is not None else np.zeros((client_edge,) * 3, bool)
    summary = {"task": task, "cell": [int(c) for c in cell], "voxels": len(coords), "octants": len(fine),
               "coarse": len(coarse), "bricks": len(listed), "shards": writer.written,
               "evaluations": voxels.evaluations, "tightened": voxels.tightened,
               "seconds": voxels.seconds + time.perf_counter() - t0,
               "peak_memory": peak_memory(),
               "inside_voxels": inside_voxel_count(np.concatenate([coarse, fine]), depth)}
    part = _part_path(folder, task)
    part.parent.mkdir(exist_ok=True)
    tmp = part.with_name(f".{part.stem}.{os.getpid()}.tmp.npz")
    listed_rows = np.array(listed, np.int64).reshape(-1, 3)
    np.savez(tmp, coords=coords, normals=normals, octants=fine, coarse=coarse,
             bricks=bricks[listed_rows[:, 0]].astype(np.int32), voxel_counts=listed_rows[:, 1],
             octant_counts=listed_rows[:, 2], lod=client_block, summary=np.array(json.dumps(summary)))
    os.replace(tmp, part)
    return summary


_FULL_SHARDS = _FullShards()  # per process: the encoded full shard of each shape, made on first use


def _write_task(recipe: SurfaceRecipe, folder: str, layout: Layout, options: dict, task: int, cell, full: bool,
                plan_octants: np.ndarray, workers: int = 1, surface=None) -> dict:
    """A task of :func:`write_zarr`: its part if it finished before (a retry, a resumed run), else its
    voxels found and stored."""
    done = _part_path(Path(folder), task)
    if done.exists():
        with np.load(done) as part:
            return json.loads(str(part["summary"]))
    if full:
        voxels = TaskVoxels(np.empty((0, 3), np.uint32), np.empty((0, 3), np.float32),
                            np.empty((0, abi.INSIDE_WORDS), np.int32), 0, [0] * abi.TIGHTEN_STATS_WORDS, 0.0)
    else:
        surface = build(recipe) if surface is None else surface
        voxels = task_voxels(surface, layout.depth, cell, layout.task_level, solid=layout.solid, options=options,
                             workers=workers, to_level=cell_level(layout.depth, layout.brick_level, layout.task_level))
    return store_task(Path(folder), layout, task, cell, voxels, plan_octants, full)


def _write_rows(folder: str, family: str, shard: int, spans: list) -> int:
    """One shard of the row arrays of ``family`` ("voxels": coords and normals; "octants": the solid's
    fine inside octants) from the parts it spans: (task, first row of the task, rows)."""
    import zarr
    group = zarr.open_group(folder, mode="r+")
    names = ("voxels/coords", "voxels/normals") if family == "voxels" else ("inside/octants",)
    members = ("coords", "normals") if family == "voxels" else ("octants",)
    arrays: list[Any] = [group[name] for name in names]
    rows = arrays[0].shards[0]  # the layout's row shard, as the array records it
    lo = shard * rows
    hi = min(lo + rows, arrays[0].shape[0])
    blocks = [np.empty((hi - lo,) + a.shape[1:], a.dtype) for a in arrays]
    for task, start, count in spans:
        a, b = max(lo, start), min(hi, start + count)
        with np.load(_part_path(Path(folder), task)) as part:
            for block, member in zip(blocks, members):
                block[a - lo:b - lo] = part[member][a - start:b - start]
    for array, block in zip(arrays, blocks):
        array[lo:hi] = block
    return hi - lo


@dataclass
class ZarrWrite:
    """What :func:`write_zarr` wrote: counts, statistics, the volume bounds."""
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
    tasks: int = 0
    resumed: int = 0
    """Tasks found finished in the ``.partial`` folder (a resumed run) and not run again."""
    peak_memory: list = field(default_factory=list)
    """Each task's worker process's peak resident memory when the task ended, in bytes."""
    shard_writers: list = field(default_factory=list)
    """Per task, the shards it wrote (``occupancy/i/j/k``, ``lod/K/i/j/k``): no shard twice."""

    def volume_bounds(self) -> tuple[float, float]:
        """As :meth:`implc.voxelizer.voxelize.Voxels.volume_bounds` (a solid only)."""
        if not self.solid:
            raise ValueError("a shell was written: write_zarr(..., solid=True) classifies the inside")
        return volume_bounds(self.bounds, self.depth, self.inside_voxels, self.voxels)


def write_zarr(surface: Surface, depth: int, path: str | os.PathLike[str], *, solid: bool = True,
               workers: int | None = None, progress: bool = False, mean_value_levels: int = 0,
               refine_leaves: bool | str = "auto", cluster: Any = None, resume: bool = False,
               say: Any = None) -> ZarrWrite:
    """Voxelize ``surface`` at ``depth`` straight into the Zarr v3 store at ``path`` (see the module),
    in memory bounded by the tasks in flight rather than the voxel count.

    ``cluster``: run the tasks on a Dask cluster: ``"local:N"`` (N worker processes started here),
    a scheduler's address (``"tcp://host:8786"``) or a ``distributed.Client``; the workers must see
    ``path`` (a shared file system). None: in this process, ``workers`` threads per task. ``resume``:
    finish the run that ``NAME.partial`` holds (the same surface and options), skipping its finished
    tasks. ``mean_value_levels``, ``refine_leaves``: as :func:`implc.voxelize`'s. ``say``: receives
    one-line reports (the dashboard's address)."""
    depth = _check_depth(depth)
    workers = default_workers() if workers is None else _check_count("workers", workers)
    mean_value_levels, refine_leaves = _check_leaf_options(mean_value_levels, refine_leaves)
    options = {"mean_value_levels": mean_value_levels, "refine_leaves": refine_leaves}
    recipe = recipe_of(surface) if cluster is not None else None
    layout = Layout.of(depth, surface.bounds, solid)
    plan_about = json.loads(json.dumps({"surface": _surface_key(surface), "software": software(), "options": options,
                                        "depth": depth, "solid": layout.solid, "bounds": layout.bounds,
                                        "layout": layout.describe()}))
    t0 = time.perf_counter()
    path = Path(path)
    with resumable_folder(path, resume=resume, matches=lambda folder: _plan_of(folder) == plan_about,
                          keep=_has_parts) as folder:
        if not (folder / "zarr.json").exists():
            _create(folder, layout, plan_about)
        cells, plan_inside = plan_tasks(surface, depth, layout.task_level, solid=solid, options=options)
        tasks = _task_list(layout, cells, plan_inside)
        done = sum(_part_path(folder, t).exists() for t in range(len(tasks)))
        with contextlib.nullcontext() if cluster is None else connect(cluster, say=say) as client:
            threads = workers if client is None else worker_threads(client)
            # here: the surface itself, the tasks on this process's threads; there: the recipe travels
            function = _write_task if client is not None else functools.partial(_write_task, surface=surface)
            t_start = time.perf_counter()
            with task_progress(progress, len(tasks), f"voxelize {1 << depth}³ to Zarr") as advance:
                summaries = run_tasks(client, function, [(t, *task) for t, task in enumerate(tasks)],
                                      shared=(recipe, str(folder), layout, options), name="implc-zarr",
                                      on_result=lambda s: advance(s["voxels"]), threads=threads)
            t_tasks = time.perf_counter()
            _finish(folder, layout, summaries, client, threads)
        stats = run_stats(depth, threads, t_tasks - t_start,
                          ((s["evaluations"], s["tightened"], s["seconds"]) for s in summaries))
        stats.task_level, stats.tasks = layout.task_level, len(tasks)
    shards = sum(len(s["shards"]) for s in summaries)
    return ZarrWrite(path, depth, surface.bounds, sum(s["voxels"] for s in summaries),
                     sum(s["octants"] + s["coarse"] for s in summaries), sum(s["inside_voxels"] for s in summaries),
                     shards, stats, time.perf_counter() - t0, solid, len(tasks), done,
                     [s["peak_memory"] for s in summaries], [s["shards"] for s in summaries])


def _surface_key(surface: Surface) -> str:
    """What identifies a surface across processes (a resumed run must be the same surface)."""
    from ..cluster.recipe import TravelError
    try:
        return recipe_of(surface).key
    except TravelError:  # not printable as text: its tape identifies it
        return f"tape-{surface.tape.fingerprint()}-{surface.engine}-{surface.directed}-{surface.width}"


def _plan_of(folder: Path) -> Any:
    try:
        about = json.loads((folder / "zarr.json").read_text())["attributes"]["implc"]
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return about.get("plan")


def _task_list(layout: Layout, cells: np.ndarray, plan_inside: np.ndarray) -> list[tuple]:
    """The tasks in Morton order, each (cell, full, the plan's octants it writes): the octants at the task
    level that may meet the surface, and those inside an octant of the plan (full: every brick inside);
    each plan octant belongs to the task holding its first cell."""
    level = layout.task_level
    entries: dict[int, list] = {}
    for cell in np.asarray(cells, np.int64).reshape(-1, 3):
        entries[int(morton_codes(cell[None])[0])] = [tuple(map(int, cell)), False, []]
    for row in np.asarray(plan_inside, np.int64).reshape(-1, 4):
        per = 1 << (level - int(row[3]))
        first = row[:3] * per
        for step in np.ndindex(per, per, per):
            cell = first + np.array(step)
            entries.setdefault(int(morton_codes(cell[None])[0]), [tuple(map(int, cell)), True, []])
        entries[int(morton_codes(first[None])[0])][2].append(row)
    return [(cell, full, np.array(rows, np.int32).reshape(-1, 4)) for _, (cell, full, rows) in sorted(entries.items())]


def _finish(folder: Path, layout: Layout, summaries: list[dict], client: Any, threads: int = 1) -> None:
    """After the tasks: the row arrays (shard by shard, one task each), the brick index, the coarse
    octants, the coarse levels of detail, then the manifest; the parts are removed."""
    import zarr
    group = zarr.open_group(str(folder), mode="r+")
    bricks, voxel_counts, octant_counts, coarse, lods = [], [], [], [], []
    for s in summaries:
        with np.load(_part_path(folder, s["task"])) as part:
            bricks.append(part["bricks"])
            voxel_counts.append(part["voxel_counts"])
            octant_counts.append(part["octant_counts"])
            coarse.append(part["coarse"])
            lods.append(part["lod"])
    families = [("voxels", [s["voxels"] for s in summaries])]
    if layout.solid:
        families.append(("octants", [s["octants"] for s in summaries]))
    rows_tasks = []
    for family, counts in families:
        total = int(sum(counts))
        if family == "voxels":
            for name, dtype in (("voxels/coords", "uint32"), ("voxels/normals", "float32")):
                group.create_array(name, shape=(total, 3), chunks=(layout.row_chunk, 3), shards=(layout.row_shard, 3),
                                   dtype=dtype, fill_value=0, overwrite=True, compressors=_compressors())
        else:
            group.create_array("inside/octants", shape=(total, 4), chunks=(layout.row_chunk, 4),
                               shards=(layout.row_shard, 4),
                               dtype="int32", fill_value=0, overwrite=True,
                               compressors=_compressors())
        starts = np.concatenate([[0], np.cumsum(counts, dtype=np.int64)])
        for shard in range(math.ceil(total / layout.row_shard)):
            lo, hi = shard * layout.row_shard, min(total, (shard + 1) * layout.row_shard)
            spans = [(summaries[t]["task"], int(starts[t]), int(counts[t])) for t in range(len(summaries))
                     if counts[t] and starts[t] < hi and starts[t] + counts[t] > lo]
            rows_tasks.append((family, shard, spans))
    run_tasks(client, _write_rows, rows_tasks, shared=(str(folder),), name="implc-rows", threads=threads)
    bricks_all = np.concatenate(bricks) if bricks else np.empty((0, 3), np.int32)
    _small(group, layout, "bricks", bricks_all.reshape(-1, 3).astype(np.int32))
    for name, counts in (("voxels/rows", voxel_counts), ("inside/rows", octant_counts)):
        if name.startswith("inside") and not layout.solid:
            continue
        flat = np.concatenate(counts) if counts else np.empty(0, np.int64)
        _small(group, layout, name, np.concatenate([[0], np.cumsum(flat, dtype=np.int64)]).astype(np.int64))
    if layout.solid:
        rows = np.concatenate(coarse) if coarse else np.empty((0, 4), np.int32)
        _small(group, layout, "inside/coarse", rows[np.argsort(_octant_keys(rows, layout.depth), kind="stable")]
               .astype(np.int32).reshape(-1, 4))
    if layout.client_level >= 1:  # the coarse levels of detail, from each task's block
        edge = 1 << (layout.client_level - layout.task_level)
        grid = np.zeros((1 << layout.client_level,) * 3, bool)
        for s, block in zip(summaries, lods):
            cell = np.asarray(s["cell"], np.int64) * edge
            grid[cell[0]:cell[0] + edge, cell[1]:cell[1] + edge, cell[2]:cell[2] + edge] |= block
        for level in range(layout.client_level, 0, -1):
            lod: Any = group[f"lod/{level}"]
            lod[...] = grid
            grid = _pooled(grid)
    about: dict[str, Any] = dict(group.attrs["implc"])  # type: ignore[arg-type]  # written by _create
    about["manifest"] = {"complete": True, "tasks": len(summaries), "voxels": int(sum(s["voxels"] for s in summaries)),
                         "inside_octants": int(sum(s["octants"] + s["coarse"] for s in summaries)),
                         "inside_voxels": int(sum(s["inside_voxels"] for s in summaries)),
                         "bricks": int(len(bricks_all)), "shards": int(sum(len(s["shards"]) for s in summaries))}
    shutil.rmtree(folder / "_parts", ignore_errors=True)
    _remove_abandoned_writes(folder)
    group.attrs["implc"] = about  # last: the store is complete


ABANDONED_WRITE = re.compile(r"\.[0-9a-f]{32}\.partial$")
"""The name zarr's local store writes a chunk or shard under before renaming it into place (``NAME.<uuid4
hex>.partial``): a worker killed in the middle of that write leaves one behind."""


def _remove_abandoned_writes(folder: Path) -> None:
    """Delete the files that writers killed mid-write left (:data:`ABANDONED_WRITE`): every task has finished,
    so nothing writes any more, and the task of a killed worker ran again elsewhere (a killed worker at 2048³
    left ``occupancy/c/2/1/3.<uuid>.partial`` beside the shard its task's second run wrote)."""
    for path in folder.rglob("*.partial"):
        if path.is_file() and ABANDONED_WRITE.search(path.name):
            path.unlink(missing_ok=True)


def _small(group, layout: Layout, name: str, array: np.ndarray) -> None:
    """A small array written whole by the caller."""
    group.create_array(name, shape=array.shape, chunks=(max(1, min(len(array), layout.row_shard)),) + array.shape[1:],
                       dtype=array.dtype, fill_value=0, overwrite=True, compressors=_compressors())[...] = array


def _pooled(grid: np.ndarray) -> np.ndarray:
    """The occupancy of the grid of half the edge: a cell is set where any of its eight is (pairs along
    k read as one uint16, then halves of rows and of layers OR-ed: contiguous, unlike strided views)."""
    n = grid.shape[0]
    half = n // 2
    k = np.ascontiguousarray(grid).view(np.uint16) != 0  # (n, n, n/2)
    j = k.reshape(n, half, 2, half)
    jk = j[:, :, 0, :] | j[:, :, 1, :]
    i = jk.reshape(half, 2, half, half)
    return i[:, 0] | i[:, 1]


def save_zarr(voxels: Voxels, path: str | os.PathLike[str]) -> Path:
    """Write ``voxels`` (with the inside octants, for a solid) as the store :func:`write_zarr` writes at
    ``path`` (a folder, conventionally ending in .zarr)."""
    path = Path(path)
    layout = Layout.of(voxels.depth, voxels.bounds, voxels.inside is not None)
    depth, level = layout.depth, layout.task_level
    coords, normals = voxels.coords, voxels.normals
    inside = voxels.inside if voxels.inside is not None else np.empty((0, 4), np.int32)
    with replacing_folder(path) as folder:
        _create(folder, layout, {"surface": None, "options": None})
        plan_rows = inside[inside[:, 3] <= level]
        fine = inside[inside[:, 3] > level]
        voxel_cells = coords.astype(np.int64) >> (depth - level)
        voxel_tasks = morton_codes(voxel_cells) if len(coords) else np.empty(0, np.uint64)
        fine_cells = _first_cells(fine, depth) >> (depth - level) if len(fine) else np.empty((0, 3), np.int64)
        fine_tasks = morton_codes(fine_cells) if len(fine) else np.empty(0, np.uint64)
        cells = np.concatenate([voxel_cells, fine_cells]).reshape(-1, 3)
        cells = np.unique(cells, axis=0) if len(cells) else cells
        summaries = []
        for t, (cell, full, rows) in enumerate(_task_list(layout, cells, plan_rows)):
            key = morton_codes(np.array([cell], np.int64))[0]
            v0, v1 = np.searchsorted(voxel_tasks, [key, key + np.uint64(1)])
            mine = fine[fine_tasks == key]
            found = TaskVoxels(coords[v0:v1], normals[v0:v1], mine, 0, [0] * abi.TIGHTEN_STATS_WORDS, 0.0)
            summaries.append(store_task(folder, layout, t, cell, found, rows, full))
        _finish(folder, layout, summaries, None, default_workers())
    return path


def _open(path: str | os.PathLike[str]) -> tuple[Any, dict]:
    """The store's group and its checked ``implc`` attributes; :class:`StoreError` otherwise."""
    import zarr
    try:
        group = zarr.open_group(str(path), mode="r")
    except Exception as exc:  # zarr raises several kinds for a folder that is not a group
        raise StoreError(f"cannot read {path} as a Zarr store: {type(exc).__name__}: {printable(str(exc), 200)}") \
            from None
    about = group.attrs.get("implc")
    if not isinstance(about, dict):
        raise StoreError(f"{path} is a Zarr group but not a store implc wrote (no 'implc' attribute)")
    if about.get("format") != FORMAT:
        raise StoreError(f"{path}: an implc store of format {printable(repr(about.get('format')), 20)}; this implc "
                         f"reads format {FORMAT} (write it again)")
    depth, bounds, solid = about.get("depth"), about.get("bounds"), about.get("solid")
    if type(depth) is not int or not 1 <= depth <= 21:
        raise StoreError(f"{path}: damaged implc Zarr store (depth {printable(repr(depth), 40)})")
    if not (isinstance(bounds, list) and len(bounds) == 3 and all(
            isinstance(b, list) and len(b) == 2 and all(type(v) in (int, float) and math.isfinite(v) for v in b)
            and b[0] < b[1] for b in bounds)) or not usable_bounds(bounds, abi.MAX_DEPTH):
        raise StoreError(f"{path}: damaged implc Zarr store (bounds {printable(repr(bounds), 60)})")
    if type(solid) is not bool:
        raise StoreError(f"{path}: damaged implc Zarr store (solid {printable(repr(solid), 40)})")
    manifest = about.get("manifest")
    if not isinstance(manifest, dict) or manifest.get("complete") is not True:
        raise StoreError(f"{path}: an incomplete implc Zarr store (no manifest: the run that wrote it stopped; "
                         "'implc voxelize ... --resume' finishes it from NAME.partial)")
    counts = ("tasks", "voxels", "inside_octants", "inside_voxels", "bricks", "shards")
    if not all(type(manifest.get(name)) is int and manifest[name] >= 0 for name in counts):
        raise StoreError(f"{path}: damaged implc Zarr store (manifest {printable(repr(manifest), 80)})")
    n = 1 << depth
    try:
        occupancy: Any = group["occupancy"]
        rows: list[Any] = [group[name] for name in ("bricks", "voxels/rows", "voxels/coords", "voxels/normals")]
    except KeyError as exc:
        raise StoreError(f"{path}: damaged implc Zarr store (missing {printable(str(exc), 60)})") from None
    except Exception as exc:  # noqa: BLE001 - an array's damaged metadata: zarr raises TypeError and others
        raise _damaged(path, exc) from None
    if tuple(occupancy.shape) != (n, n, n) or str(occupancy.dtype) != "bool":
        raise StoreError(f"{path}: damaged implc Zarr store (a {printable(str(occupancy.dtype), 20)} occupancy "
                         f"{'x'.join(map(str, occupancy.shape))}, where depth {depth} means bool {n}³)")
    count = manifest.get("voxels")
    if rows[2].shape != (count, 3) or rows[3].shape != (count, 3) or rows[1].shape != (rows[0].shape[0] + 1,):
        raise StoreError(f"{path}: damaged implc Zarr store (the voxel arrays do not match the manifest)")
    return group, about


def describe_zarr(path: str | os.PathLike[str]) -> list[str]:
    """Lines describing a store this module wrote (for ``implc info``); ValueError if it is not one."""
    group, about = _open(path)
    depth, manifest, occupancy = about["depth"], about["manifest"], group["occupancy"]
    n = 1 << depth
    lines = [f"file     {path}, Zarr v3 group: occupancy bool {n}x{n}x{n} (chunks {occupancy.chunks}, shards "
             f"{occupancy.shards}), levels of detail 1-{depth - 1}, voxel rows with normals",
             f"grid     {n}³ (depth {depth}) over {tuple(tuple(b) for b in about['bounds'])}",
             f"voxels   {manifest['voxels']} boundary voxels in {manifest['bricks']} bricks, "
             f"{manifest['tasks']} tasks, {manifest['shards']} shards written"]
    if about["solid"]:
        lo, hi = volume_bounds(about["bounds"], depth, manifest["inside_voxels"], manifest["voxels"])
        lines.append(f"solid    {manifest['inside_octants']} inside octants ({manifest['inside_voxels']} voxels), "
                     f"volume in [{lo:.6g}, {hi:.6g}]")
    lines.append(f"content  {'the solid (inside and boundary)' if about['solid'] else 'the boundary voxels'}, "
                 f"indexed {printable(str(about.get('index', '?')), 80)}")
    return lines


def load_zarr(path: str | os.PathLike[str], region: Any = None) -> Voxels:
    """The :class:`~implc.voxelizer.voxelize.Voxels` of a store (all, or ``region``: cell ranges
    ((i0, i1), (j0, j1), (k0, k1)), half open: the voxels in it, and the inside octants that meet it,
    whole), reading only the bricks the region meets."""
    group, about = _open(path)
    box = None if region is None else _region(region, about["depth"])
    try:
        return _read(group, about, box)
    except (StoreError, MemoryError):  # a store too large for this machine is not a damaged one
        raise
    except Exception as exc:  # noqa: BLE001 - a damaged chunk: zarr's codecs raise RuntimeError and others
        raise _damaged(path, exc) from None


def _damaged(path, exc: Exception) -> StoreError:
    """The error for a store that zarr, or the check of its rows, could not read: what went wrong, named."""
    return StoreError(f"{path}: damaged implc Zarr store ({type(exc).__name__}: {printable(str(exc), 120)})")


def _region(region: Any, depth: int) -> np.ndarray:
    """``region`` as a (3, 2) array of cell ranges within the grid; ValueError otherwise."""
    box = np.asarray(region, dtype=np.int64)
    if box.shape != (3, 2) or np.any(box[:, 0] >= box[:, 1]) or np.any(box[:, 0] < 0) \
            or np.any(box[:, 1] > 1 << depth):
        raise ValueError(f"region must be three cell ranges (lo, hi) with 0 <= lo < hi <= {1 << depth}, "
                         f"got {region!r}")
    return box


def _read(group: Any, about: dict, box: np.ndarray | None) -> Voxels:
    """:func:`load_zarr`'s reading, once the store is open (``box``: the region's cell ranges, or None)."""
    depth, solid = about["depth"], about["solid"]
    bounds = tuple(tuple(map(float, b)) for b in about["bounds"])
    brick = group["occupancy"].shards[0]
    shift = brick.bit_length() - 1
    bricks = group["bricks"][...].astype(np.int64)
    if box is None:
        lo, hi = np.zeros(3, np.int64), np.full(3, 1 << depth, np.int64)
        chosen = np.arange(len(bricks))
    else:
        lo, hi = box[:, 0], box[:, 1]
        first, last = bricks << shift, (bricks + 1) << shift
        chosen = np.flatnonzero(np.all((first < hi) & (last > lo), axis=1))
    starts = group["voxels/rows"][...].astype(np.int64)
    coords, normals = _rows(group, starts, chosen, ("voxels/coords", "voxels/normals"))
    # each row lies in the brick that lists it: a damaged chunk that still decompresses (a store written
    # before its chunks had zstd's checksum) gives rows elsewhere, which the region's filter below would
    # otherwise drop in silence
    owner = np.repeat(bricks[chosen], np.diff(starts)[chosen], axis=0)
    if owner.shape != coords.shape or np.any((coords.astype(np.int64) >> shift) != owner):
        raise ValueError("voxel rows lie outside the bricks that list them")
    keep = np.all((coords >= lo) & (coords < hi), axis=1)
    inside = None
    if solid:
        (fine,) = _rows(group, group["inside/rows"][...].astype(np.int64), chosen, ("inside/octants",))
        coarse = group["inside/coarse"][...]
        rows = np.concatenate([coarse, fine]) if len(coarse) or len(fine) else np.empty((0, 4), np.int32)
        size = np.left_shift(np.int64(1), depth - rows[:, 3].astype(np.int64))[:, None]
        first = rows[:, :3].astype(np.int64) * size
        rows = rows[np.all((first < hi) & (first + size > lo), axis=1)]
        inside = rows[np.argsort(_octant_keys(rows, depth), kind="stable")].astype(np.int32)
    return Voxels(coords[keep], normals[keep], depth, bounds, None, inside=inside)


def _rows(group, starts: np.ndarray, chosen: np.ndarray, names: tuple) -> list[np.ndarray]:
    """The rows of the chosen bricks (``starts``: where each brick's rows start in the arrays ``names``;
    consecutive bricks read as one range)."""
    arrays = [group[name] for name in names]
    pieces: list[list[np.ndarray]] = [[] for _ in arrays]
    if len(chosen):
        breaks = np.flatnonzero(np.diff(chosen) != 1) + 1
        for run in np.split(chosen, breaks):
            a, b = int(starts[run[0]]), int(starts[run[-1] + 1])
            for piece, array in zip(pieces, arrays):
                piece.append(array[a:b])
    return [np.concatenate(p) if p else np.empty((0,) + a.shape[1:], a.dtype) for p, a in zip(pieces, arrays)]
