"""Zarr v3 stores of voxelizations: the format, its layout and sizes, and reading (:func:`load_zarr`, a region
at a time, and :func:`describe_zarr`). :mod:`implc.files.zarr_writer` writes them, shard by shard, by tasks
that each own their shards: in this process, or on a Dask cluster with the same tasks and the same store.

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
import json
import math
import os
import stat
from collections.abc import Iterator
from contextvars import ContextVar
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..cluster.tasks import (
    task_level,
)
from ..common.bounds import usable_bounds
from ..common.context import scoped
from ..common.untrusted import printable, regular_file
from ..engines.morton import morton_codes
from ..errors import StoreError
from ..native import abi
from ..voxelizer.voxelize import (
    Voxels,
    paint_cubes,
    volume_bounds,
)
from .store_place import is_url, place_of

FORMAT = 2
"""The store's layout version (1: implc 0.2's single occupancy array)."""
CHUNK = 128
"""The occupancy's chunk edge (2 MiB of bool: zarr recommends chunks of 1 MB or more, and smaller chunks
write more slowly: ``implc bench --sections writers`` measures the writers)."""
SHARD = 256
"""A brick: the occupancy's shard edge, the unit the voxel rows are indexed by."""
ROW_CHUNK = 1 << 16
"""Rows per chunk of the voxel and octant lists."""
ROW_SHARD = 1 << 20
"""Rows per shard of those lists: each written by one task."""
CLIENT_LEVELS = 3
"""The levels of detail up to three below the task level are small (8³ cells per task at most) and
written whole by the caller from each task's block; finer ones by the tasks, shard by shard."""


STORE_KIND = "zarr store"
"""The kind of output a store is (:data:`implc.common.atomic_file.MARKER`)."""
STORE_ENTRIES = {"zarr.json", "occupancy", "lod", "voxels", "inside", "bricks", "_parts"}
"""What a store's folder holds."""


def is_store_folder(folder: Path) -> bool:
    """Whether ``folder`` is a store implc wrote (whole or a run's partial one): its entries are a store's
    and its ``zarr.json`` carries implc's attributes. (A store holds no marker file: zarr would take it for
    a member.)"""
    try:
        if not {p.name for p in folder.iterdir()} <= STORE_ENTRIES:
            return False
        regular_file(folder / "zarr.json", StoreError, "store metadata")
        with open(folder / "zarr.json", "rb") as f:
            meta = json.loads(f.read(1 << 20))
        return isinstance(meta, dict) and "implc" in meta.get("attributes", {})
    except (OSError, ValueError):
        return False


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
    with scoped(SIZES, chosen):
        yield


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


def first_cells(rows: np.ndarray, depth: int) -> np.ndarray:
    """The first cell (at ``depth``) of octant rows (i, j, k, level), int64."""
    return rows[:, :3].astype(np.int64) << (depth - rows[:, 3].astype(np.int64))[:, None]


def octant_keys(rows: np.ndarray, depth: int) -> np.ndarray:
    """Morton codes of the octants' first cells: their order in the store."""
    return morton_codes(first_cells(rows, depth)) if len(rows) else np.empty(0, np.uint64)


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


def compressors() -> Any:
    """Every array's codec: zstd at level 1 (about as small as zarr's default level 3 on these arrays, and
    faster: ``implc bench --sections writers``), with the frame's checksum, so that a damaged chunk is an
    error when it is read rather than other data (without it, damage inside a chunk decoded to rows in
    the wrong places)."""
    from zarr.codecs import ZstdCodec
    return ZstdCodec(level=1, checksum=True)


def create_store(url: str, layout: Layout, plan: dict) -> Any:
    """The group with its occupancy and level-of-detail arrays (rows come once their lengths are known), at
    ``url`` (a folder's path, or an object store's URL)."""
    import zarr
    n = 1 << layout.depth
    about: dict[str, Any] = {"format": FORMAT, "depth": layout.depth, "bounds": [list(b) for b in layout.bounds],
                             "solid": layout.solid, "layout": layout.describe(), "plan": plan,
                             "index": "[i, j, k]: cell (i, j, k) of the grid"}
    group = zarr.open_group(url, mode="w", zarr_format=3, attributes={"implc": about})
    group.create_array("occupancy", shape=(n, n, n), chunks=(layout.chunk,) * 3, shards=(layout.brick,) * 3,
                       dtype="bool", fill_value=False, compressors=compressors())
    for level in range(1, layout.depth):
        edge = 1 << level
        if level <= layout.client_level:
            group.create_array(f"lod/{level}", shape=(edge,) * 3, chunks=(min(layout.chunk, edge),) * 3, dtype="bool",
                               fill_value=False, compressors=compressors())
        else:
            shard = layout.lod_shard(level)
            group.create_array(f"lod/{level}", shape=(edge,) * 3, chunks=(min(layout.chunk, shard),) * 3,
                               shards=(shard,) * 3, dtype="bool", fill_value=False, compressors=compressors())
    return group


def small_array(group: Any, layout: Layout, name: str, array: np.ndarray) -> None:
    """A small array written whole by the caller."""
    group.create_array(name, shape=array.shape, chunks=(max(1, min(len(array), layout.row_shard)),) + array.shape[1:],
                       dtype=array.dtype, fill_value=0, overwrite=True, compressors=compressors())[...] = array


def pooled(grid: np.ndarray) -> np.ndarray:
    """The occupancy of the grid of half the edge: a cell is set where any of its eight is (pairs along
    k read as one uint16, then halves of rows and of layers OR-ed: contiguous, unlike strided views)."""
    n = grid.shape[0]
    half = n // 2
    k = np.ascontiguousarray(grid).view(np.uint16) != 0  # (n, n, n/2)
    j = k.reshape(n, half, 2, half)
    jk = j[:, :, 0, :] | j[:, :, 1, :]
    i = jk.reshape(half, 2, half, half)
    return i[:, 0] | i[:, 1]


MAX_STORE_FILE = 1 << 31
"""The largest file a store may hold (a shard of a brick is at most a few tens of MiB)."""


def _scan(path) -> None:
    """Every entry of the store a regular file or a folder, none a link, a FIFO or a device, and none
    larger than :data:`MAX_STORE_FILE`: zarr then reads nothing that blocks or never ends."""
    root = Path(path)
    if root.is_symlink() or not root.is_dir():
        regular_file(root, StoreError, "Zarr store")  # says what it is instead
        raise StoreError(f"cannot read {root} as a Zarr store: it is a file, not a store's folder")
    for folder, dirs, files in os.walk(root, followlinks=False):
        for name in dirs + files:
            entry = Path(folder) / name
            info = os.lstat(entry)
            if stat.S_ISDIR(info.st_mode):
                continue
            if not stat.S_ISREG(info.st_mode):
                kind = "a link" if stat.S_ISLNK(info.st_mode) else "a FIFO" if stat.S_ISFIFO(info.st_mode) \
                    else "not a regular file"
                raise StoreError(f"cannot read {root}: {entry.relative_to(root)} is {kind} (a store holds regular "
                                 "files only)")
            if info.st_size > MAX_STORE_FILE:
                raise StoreError(f"cannot read {root}: {entry.relative_to(root)} is larger than any file of a store")


def _open(path: str | os.PathLike[str]) -> tuple[Any, dict]:
    """The store's group and its checked ``implc`` attributes; :class:`StoreError` otherwise. A folder is
    scanned first (:func:`_scan`); an object store's objects are plain bytes, read by range."""
    import zarr
    url = place_of(path).url
    if not is_url(path):
        _scan(url)
    try:
        group = zarr.open_group(url, mode="r")
    except StoreError:
        raise
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
    try:
        sound = isinstance(bounds, list) and len(bounds) == 3 and all(
            isinstance(b, list) and len(b) == 2 and all(type(v) in (int, float) and math.isfinite(v) for v in b)
            and b[0] < b[1] for b in bounds) and usable_bounds(bounds, abi.MAX_DEPTH)
    except OverflowError:  # an integer beyond the doubles
        sound = False
    if not sound:
        raise StoreError(f"{path}: damaged implc Zarr store (bounds {printable(repr(bounds), 60)})")
    if type(solid) is not bool:
        raise StoreError(f"{path}: damaged implc Zarr store (solid {printable(repr(solid), 40)})")
    manifest = about.get("manifest")
    if not isinstance(manifest, dict) or manifest.get("complete") is not True:
        raise StoreError(f"{path}: an incomplete implc Zarr store (no manifest: the run that wrote it stopped; "
                         "'implc voxelize ... --resume' finishes it: from NAME.partial, or under its URL)")
    counts = ("tasks", "voxels", "inside_octants", "inside_voxels", "bricks", "shards")
    n = 1 << depth
    if not all(type(manifest.get(name)) is int and 0 <= manifest[name] <= n**3 for name in counts):
        raise StoreError(f"{path}: damaged implc Zarr store (manifest {printable(repr(manifest), 80)})")
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
    need = about["manifest"]["voxels"] * ROW_BYTES + about["manifest"]["inside_octants"] * 16
    available = _available_memory()
    if box is None and need > 0.8 * available:
        raise MemoryError(f"{path}: its {about['manifest']['voxels']} voxels need about {need / 2**30:.1f} GiB, more "
                          f"than this machine has free ({available / 2**30:.1f} GiB): read a region of it")
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
    if len(bricks) and (bricks.min() < 0 or bricks.max() >= (1 << depth) >> shift
                        or len(np.unique(bricks, axis=0)) != len(bricks)):
        raise ValueError("bricks outside the grid, or listed twice")
    starts = _starts(group["voxels/rows"][...], len(bricks), group["voxels/coords"].shape[0])
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
        starts = _starts(group["inside/rows"][...], len(bricks), group["inside/octants"].shape[0])
        (fine,) = _rows(group, starts, chosen, ("inside/octants",))
        coarse = group["inside/coarse"][...]
        rows = np.concatenate([coarse, fine]) if len(coarse) or len(fine) else np.empty((0, 4), np.int32)
        levels = rows[:, 3].astype(np.int64)
        if len(rows) and (levels.min() < 0 or levels.max() > depth or (rows[:, :3] < 0).any()
                          or (rows[:, :3].astype(np.int64) >= np.left_shift(1, levels)[:, None]).any()):
            raise ValueError("inside octants at a level or place outside the grid")
        if len(np.unique(rows, axis=0)) != len(rows):
            raise ValueError("an inside octant listed twice")
        size = np.left_shift(np.int64(1), depth - rows[:, 3].astype(np.int64))[:, None]
        first = rows[:, :3].astype(np.int64) * size
        rows = rows[np.all((first < hi) & (first + size > lo), axis=1)]
        inside = rows[np.argsort(octant_keys(rows, depth), kind="stable")].astype(np.int32)
    return Voxels(coords[keep], normals[keep], depth, bounds, None, inside=inside)


ROW_BYTES = 40
"""Memory per voxel read: its coordinates and normal, and the copies a region's filter makes."""


def _available_memory() -> int:
    from ..voxelizer.voxelize import available_memory
    return available_memory()


def _starts(rows: np.ndarray, bricks: int, total: int) -> np.ndarray:
    """Where each brick's rows start (and the end): from 0, never decreasing, ending at the rows there are."""
    starts = np.asarray(rows).astype(np.int64)
    if starts.shape != (bricks + 1,) or (len(starts) and (starts[0] != 0 or starts[-1] != total)) \
            or (np.diff(starts) < 0).any():
        raise ValueError("the row index does not match the rows")
    return starts


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
