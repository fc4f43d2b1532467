"""Writing Zarr stores (:mod:`implc.files.zarr_store` is the format): tasks that each own their shards,
run here on a pool of threads or on a Dask cluster, each task's voxels written straight into the shards of
its octant, and the manifest written last (the commit point: a reader refuses a store without it).

``write_zarr`` voxelizes into a store; ``save_zarr`` writes a :class:`implc.Voxels` the same way; either
writes to a local folder or to an object store's URL (:mod:`implc.files.store_place`). A run that stops
keeps its finished tasks' parts (each with its checksum): in ``OUT.partial`` for a folder, under the URL
itself for an object store (whose store has no manifest until the run completes), and ``resume=True``
finishes it with the same surface and options.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import io
import json
import math
import os
import re
import threading
import time
from collections.abc import Iterator
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
    task_progress,
    task_voxels,
    worker_threads,
)
from ..common.atomic_file import replacing_folder, resumable_folder
from ..common.threads import check_workers, default_workers
from ..engines.morton import morton_codes
from ..engines.walk import SubdivisionStats
from ..errors import StoreError
from ..native import abi
from ..voxelizer.voxelize import (
    Voxels,
    _check_depth,
    _check_leaf_options,
    inside_voxel_count,
    volume_bounds,
)
from .store_place import FolderPlace, ObjectPlace, StorePlace, place_of, target_of
from .zarr_shards import ShardEncoder
from .zarr_store import (
    STORE_KIND,
    Layout,
    compressors,
    create_store,
    first_cells,
    is_store_folder,
    octant_keys,
    paint,
    pooled,
    small_array,
)

if TYPE_CHECKING:
    from ..engines.surface import Surface


@dataclass
class _Level:
    """One level's shard being filled by a task (bricks arrive in Morton order, so a shard is complete
    when a brick outside it arrives)."""
    array: ShardEncoder | None
    level: int
    edge: int
    origin: np.ndarray | None = None
    block: np.ndarray | None = None
    full: bool = True


class _TaskWriter:
    """Writes one task's bricks and level-of-detail shards, and records the shard keys it wrote."""

    def __init__(self, encoders: dict[str, ShardEncoder], layout: Layout, place: StorePlace):
        self.layout, self.place = layout, place
        self.levels: list[_Level] = []
        for level in range(max(layout.client_level, 1), layout.depth + 1):
            array = None if level <= layout.client_level else \
                encoders["occupancy" if level == layout.depth else f"lod/{level}"]  # the caller writes the others
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
            size = max(1, edge >> (depth - lv.level))
            if size == lv.edge and lv.level > self.layout.client_level:
                # the brick is this level's whole shard (the occupancy's): written as it is, no copy
                self._flush(lv)
                self._write(lv, shard_origin, None if full else block)
                if block is not None:
                    block = pooled(block) if block.shape[0] > 1 else block
                continue
            if lv.origin is None or np.any(shard_origin != lv.origin):
                self._flush(lv)
                lv.origin, lv.block, lv.full = shard_origin, np.zeros((lv.edge,) * 3, bool), True
            lo = (origin >> (depth - lv.level)) - shard_origin
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
                block = pooled(block) if block.shape[0] > 1 else block

    def _flush(self, lv: _Level) -> None:
        if lv.block is None or lv.origin is None:
            return
        block, origin = lv.block, lv.origin
        lv.block = None
        if lv.level <= self.layout.client_level:  # the caller writes this level: kept for the part
            self.client_block = block
            return
        self._write(lv, origin, None if lv.full and block.all() else block)

    def _write(self, lv: _Level, origin: np.ndarray, block: np.ndarray | None) -> None:
        """Write one shard of ``lv`` at ``origin``: ``block``, or all inside (None); an empty one is not
        written (it reads as the fill value)."""
        assert lv.array is not None
        data = lv.array.full() if block is None else lv.array.encode(block)
        if data is None:  # empty: not written
            return
        self.place.write(lv.array.key(origin // lv.edge), data)
        self.written.append(f"{lv.array.path}/{'/'.join(map(str, (origin // lv.edge).tolist()))}")

    def finish(self) -> None:
        for lv in self.levels:
            self._flush(lv)


def _part_name(task: int) -> str:
    return f"_parts/{task:08d}.npz"


def _sum_name(part: str) -> str:
    """Where a part's SHA-256 is recorded: written after the part is in place, so a part without it (the run
    stopped between the two) or with another is not trusted."""
    return part[:-len(".npz")] + ".sha256"


def _trusted_part(place: StorePlace, task: int) -> bytes | None:
    """Task ``task``'s part where it finished in full and is unaltered (its SHA-256 is the one recorded when
    it was written); None otherwise, the untrusted objects removed (the task runs again)."""
    part, digest = _part_name(task), _sum_name(_part_name(task))
    if not place.exists(part):
        return None
    try:
        recorded = place.read(digest)
        data = place.read(part)
        if recorded == hashlib.sha256(data).hexdigest().encode("ascii"):
            return data
    except (StoreError, OSError):
        pass
    for stale in (part, digest):
        with contextlib.suppress(OSError):
            place.remove(stale)
    return None


_MEMBER_READS = threading.Lock()
"""Held while a part's member is read: numpy parses each member's header with ``ast.literal_eval``, and
CPython 3.11's AST constructor is not safe on two threads at once (a shard written by two task threads
stopped once with "SystemError: AST constructor recursion depth mismatch")."""


class _Members:
    """An open part's members, each read under :data:`_MEMBER_READS`."""

    def __init__(self, part):
        self._part = part

    def __getitem__(self, name: str) -> np.ndarray:
        with _MEMBER_READS:
            return self._part[name]


@contextlib.contextmanager
def _part(place: StorePlace, task: int) -> Iterator[Any]:
    """A finished task's part, opened (``with _part(place, task) as part: part["coords"]``): its members are
    read as they are asked for (the caller of the small ones does not read the rows), one thread at a time
    (:data:`_MEMBER_READS`)."""
    with place.open(_part_name(task)) as f, np.load(f) as part:
        yield _Members(part)


def _has_parts(place: StorePlace) -> bool:
    """Whether a stopped run left finished tasks in the store (worth keeping for ``resume``)."""
    return any(name.endswith(".sha256") and not name.startswith(".") for name in place.names("_parts"))


def store_task(target: str, layout: Layout, task: int, cell: Any, voxels: TaskVoxels, plan_octants: np.ndarray,
               full: bool) -> dict:
    """Write one task's shards from what it found (``voxels``; ``full``: its octant lies inside, every
    brick full) and its part, into the store at ``target`` (:func:`implc.files.store_place.place_of`);
    the summary the caller assembles the store from."""
    t0 = time.perf_counter()
    place = place_of(target)
    depth, shift = layout.depth, layout.depth - layout.brick_level
    writer = _TaskWriter(_encoders(place.url, layout), layout, place)
    coords, normals, inside = voxels.coords, voxels.normals, voxels.inside
    fine = inside[inside[:, 3] > layout.brick_level] if len(inside) else inside
    coarse = inside[inside[:, 3] <= layout.brick_level] if len(inside) else inside
    coarse = np.concatenate([plan_octants.astype(np.int32).reshape(-1, 4), coarse])
    fine = fine[np.argsort(octant_keys(fine, depth), kind="stable")]
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
    # the rows come in Morton order, so each brick's rows are one run: the runs' heads name the bricks
    v_heads, v_spans = _brick_runs(coords.astype(np.int64) >> shift)
    f_heads, f_spans = _brick_runs(first_cells(fine, depth) >> shift if len(fine) else np.empty((0, 3), np.int64))
    candidates = np.concatenate([v_heads, f_heads, full_bricks])
    keys = morton_codes(candidates) if len(candidates) else np.empty(0, np.uint64)
    unique_keys, first = np.unique(keys, return_index=True)
    bricks = candidates[first]
    full_keys = set(keys[len(v_heads) + len(f_heads):].tolist())
    v_rows = _rows_of(keys[:len(v_heads)], v_spans, unique_keys)
    f_rows = _rows_of(keys[len(v_heads):len(v_heads) + len(f_heads)], f_spans, unique_keys)
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
    listed_rows = np.array(listed, np.int64).reshape(-1, 3)
    buffer = io.BytesIO()
    np.savez(buffer, coords=coords, normals=normals, octants=fine, coarse=coarse,
             bricks=bricks[listed_rows[:, 0]].astype(np.int32), voxel_counts=listed_rows[:, 1],
             octant_counts=listed_rows[:, 2], lod=client_block, summary=np.array(json.dumps(summary)))
    data = buffer.getvalue()
    place.write(_part_name(task), data)
    place.write(_sum_name(_part_name(task)), hashlib.sha256(data).hexdigest().encode("ascii"))
    return summary


@functools.lru_cache(maxsize=4)
def _encoders(url: str, layout: Layout) -> dict[str, ShardEncoder]:
    """The shard encoders of the arrays the tasks write (the occupancy and the finer levels of detail) of
    the store at ``url``, made once per process for all its tasks: their metadata, which ``layout``
    fixes, does not change during a run, and opening the arrays took as long as painting a task's bricks."""
    import zarr
    group = zarr.open_group(url, mode="r+")
    names = ["occupancy"] + [f"lod/{k}" for k in range(layout.client_level + 1, layout.depth)]
    return {name: ShardEncoder(group[name]) for name in names}


def _brick_runs(bricks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The bricks of rows in Morton order (each brick's rows one run): each run's brick and its (first,
    end) rows."""
    if not len(bricks):
        return bricks.reshape(0, 3), np.empty((0, 2), np.int64)
    change = np.flatnonzero(np.any(bricks[1:] != bricks[:-1], axis=1)) + 1
    starts = np.concatenate([[0], change])
    return bricks[starts], np.stack([starts, np.concatenate([change, [len(bricks)]])], axis=1)


def _rows_of(run_keys: np.ndarray, spans: np.ndarray, keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each brick key of ``keys``, the (first, end) rows of its run among ``run_keys`` (sorted), or an
    empty span where it has none."""
    at = np.searchsorted(run_keys, keys)
    found = at < len(run_keys)
    found[found] = run_keys[at[found]] == keys[found]
    first, end = np.zeros(len(keys), np.int64), np.zeros(len(keys), np.int64)
    first[found], end[found] = spans[at[found], 0], spans[at[found], 1]
    return first, end


def _write_task(recipe: SurfaceRecipe, folder: str, layout: Layout, options: dict, task: int, cell, full: bool,
                plan_octants: np.ndarray, workers: int = 1, surface=None) -> dict:
    """A task of :func:`write_zarr`: its part if it finished before (a retry, a resumed run), else its
    voxels found and stored."""
    done = _trusted_part(place_of(folder), task)
    if done is not None:
        with np.load(io.BytesIO(done)) as part:
            return json.loads(str(_Members(part)["summary"]))
    if full:
        voxels = TaskVoxels(np.empty((0, 3), np.uint32), np.empty((0, 3), np.float32),
                            np.empty((0, abi.INSIDE_WORDS), np.int32), 0, [0] * abi.TIGHTEN_STATS_WORDS, 0.0)
    else:
        surface = build(recipe) if surface is None else surface
        voxels = task_voxels(surface, layout.depth, cell, layout.task_level, solid=layout.solid, options=options,
                             workers=workers, to_level=cell_level(layout.depth, layout.brick_level, layout.task_level))
    return store_task(folder, layout, task, cell, voxels, plan_octants, full)


def _write_rows(folder: str, family: str, shard: int, spans: list) -> int:
    """One shard of the row arrays of ``family`` ("voxels": coords and normals; "octants": the solid's
    fine inside octants) from the parts it spans: (task, first row of the task, rows)."""
    import zarr
    place = place_of(folder)
    group = zarr.open_group(place.url, mode="r+")
    names = ("voxels/coords", "voxels/normals") if family == "voxels" else ("inside/octants",)
    members = ("coords", "normals") if family == "voxels" else ("octants",)
    arrays: list[Any] = [group[name] for name in names]
    rows = arrays[0].shards[0]  # the layout's row shard, as the array records it
    lo = shard * rows
    hi = min(lo + rows, arrays[0].shape[0])
    blocks = [np.empty((hi - lo,) + a.shape[1:], a.dtype) for a in arrays]
    for task, start, count in spans:
        a, b = max(lo, start), min(hi, start + count)
        with _part(place, task) as part:
            for block, member in zip(blocks, members):
                block[a - lo:b - lo] = part[member][a - start:b - start]
    for array, block in zip(arrays, blocks):  # encoded here: zarr's own writes take turns on one thread
        encoder = ShardEncoder(array)
        data = encoder.encode(block)
        if data is not None:
            place.write(encoder.key((shard, 0)), data)
    return hi - lo


@dataclass
class ZarrWrite:
    """What :func:`write_zarr` wrote: counts, statistics, the volume bounds."""
    path: Path | str
    """The store's folder, or its URL."""
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

    ``path``: a folder, or the URL of an object store (``s3://bucket/run.zarr``: see
    :mod:`implc.files.store_place`). ``cluster``: run the tasks on a Dask cluster: ``"local:N"`` (N worker
    processes started here), a scheduler's address (``"tcp://host:8786"``) or a ``distributed.Client``;
    the workers must reach ``path`` (a shared file system, or the object store). None: in this process,
    ``workers`` threads per task. ``resume``: finish the run that stopped (its finished tasks kept in
    ``NAME.partial``, or under the URL), skipping its finished tasks; the same surface and options.
    ``mean_value_levels``, ``refine_leaves``: as :func:`implc.voxelize`'s. ``say``: receives
    one-line reports (the dashboard's address)."""
    depth = _check_depth(depth)
    workers = default_workers() if workers is None else check_workers(workers)
    mean_value_levels, refine_leaves = _check_leaf_options(mean_value_levels, refine_leaves)
    options = {"mean_value_levels": mean_value_levels, "refine_leaves": refine_leaves}
    recipe = recipe_of(surface) if cluster is not None else None
    layout = Layout.of(depth, surface.bounds, solid)
    plan_about = json.loads(json.dumps({"surface": _surface_key(surface), "software": software(), "options": options,
                                        "depth": depth, "solid": layout.solid, "bounds": layout.bounds,
                                        "layout": layout.describe()}))
    t0 = time.perf_counter()
    target = target_of(path)
    with _writing(target, plan_about, resume=resume) as place:
        if not place.exists("zarr.json"):
            create_store(place.url, layout, plan_about)
        cells, plan_inside = plan_tasks(surface, depth, layout.task_level, solid=solid, options=options)
        tasks = _task_list(layout, cells, plan_inside)
        done = sum(_trusted_part(place, t) is not None for t in range(len(tasks)))
        with contextlib.nullcontext() if cluster is None else connect(cluster, say=say) as client:
            threads = workers if client is None else worker_threads(client)
            # here: the surface itself, the tasks on this process's threads; there: the recipe travels
            function = _write_task if client is not None else functools.partial(_write_task, surface=surface)
            t_start = time.perf_counter()
            with task_progress(progress, len(tasks), f"voxelize {1 << depth}³ to Zarr") as advance:
                summaries = run_tasks(client, function, [(t, *task) for t, task in enumerate(tasks)],
                                      shared=(recipe, place.url, layout, options), name="implc-zarr",
                                      on_result=lambda s: advance(s["voxels"]), threads=threads)
            t_tasks = time.perf_counter()
            _finish(place, layout, summaries, client, threads)
        stats = run_stats(depth, threads, t_tasks - t_start,
                          ((s["evaluations"], s["tightened"], s["seconds"]) for s in summaries))
        stats.task_level, stats.tasks = layout.task_level, len(tasks)
    shards = sum(len(s["shards"]) for s in summaries)
    return ZarrWrite(target, depth, surface.bounds, sum(s["voxels"] for s in summaries),
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


def _about_of(place: StorePlace) -> dict | None:
    """The ``implc`` attributes of the store at ``place`` (None: no store of implc's there)."""
    try:
        about = json.loads(place.read("zarr.json"))["attributes"]["implc"]
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return about if isinstance(about, dict) else None


@contextlib.contextmanager
def _writing(target: Path | str, plan: dict, *, resume: bool) -> Iterator[StorePlace]:
    """The place a run writes its store: for a folder, ``NAME.partial`` renamed into place when the block
    completes (:func:`implc.common.atomic_file.resumable_folder`); for a URL, the URL itself, which must
    hold nothing (or, to ``resume``, the unfinished store of the same run). An object store cannot replace
    a store in one step, so an existing complete store there is refused rather than destroyed before its
    successor exists. A run that fails before finishing any task leaves nothing behind."""
    if not isinstance(target, str):
        with resumable_folder(target, STORE_KIND, resume=resume,
                              matches=lambda folder: (_about_of(FolderPlace(folder)) or {}).get("plan") == plan,
                              keep=lambda folder: _has_parts(FolderPlace(folder)), recognise=is_store_folder,
                              marked=False) as folder:
            yield FolderPlace(folder)
        return
    place = ObjectPlace(target)
    place.check_bucket()
    about = _about_of(place)
    if about is None:
        if place.exists():
            raise ValueError(f"{target} holds objects that are not an implc store: implc writes a store "
                             "only where nothing is (choose another URL, or remove them first)")
        if resume:
            raise ValueError(f"nothing to resume: {target} holds nothing (a run that stops early keeps "
                             "its finished tasks there)")
    elif "manifest" in about:
        raise ValueError(f"{target} holds a complete store{': nothing to resume' if resume else ''}; an "
                         "object store cannot replace one in a single step, so implc writes a new store only "
                         "where nothing is (remove it first, or choose another URL)")
    elif not resume:
        raise ValueError(f"{target} holds an unfinished run: finish it with --resume (resume=True), or "
                         "remove it to start over")
    elif about.get("plan") != plan:
        raise ValueError(f"{target} holds another run (another surface, depth or options): remove it to "
                         "start over")
    try:
        yield place
    except BaseException:
        if not _has_parts(place):
            place.remove_all()
        raise


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


def _finish(place: StorePlace, layout: Layout, summaries: list[dict], client: Any, threads: int = 1) -> None:
    """After the tasks: the row arrays (shard by shard, one task each), the brick index, the coarse
    octants, the coarse levels of detail, then the manifest; the parts are removed."""
    import zarr
    group = zarr.open_group(place.url, mode="r+")
    bricks, voxel_counts, octant_counts, coarse, lods = [], [], [], [], []
    for s in summaries:
        with _part(place, s["task"]) as part:
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
                                   dtype=dtype, fill_value=0, overwrite=True, compressors=compressors())
        else:
            group.create_array("inside/octants", shape=(total, 4), chunks=(layout.row_chunk, 4),
                               shards=(layout.row_shard, 4),
                               dtype="int32", fill_value=0, overwrite=True,
                               compressors=compressors())
        starts = np.concatenate([[0], np.cumsum(counts, dtype=np.int64)])
        for shard in range(math.ceil(total / layout.row_shard)):
            lo, hi = shard * layout.row_shard, min(total, (shard + 1) * layout.row_shard)
            spans = [(summaries[t]["task"], int(starts[t]), int(counts[t])) for t in range(len(summaries))
                     if counts[t] and starts[t] < hi and starts[t] + counts[t] > lo]
            rows_tasks.append((family, shard, spans))
    run_tasks(client, _write_rows, rows_tasks, shared=(place.url,), name="implc-rows", threads=threads)
    bricks_all = np.concatenate(bricks) if bricks else np.empty((0, 3), np.int32)
    small_array(group, layout, "bricks", bricks_all.reshape(-1, 3).astype(np.int32))
    for name, counts in (("voxels/rows", voxel_counts), ("inside/rows", octant_counts)):
        if name.startswith("inside") and not layout.solid:
            continue
        flat = np.concatenate(counts) if counts else np.empty(0, np.int64)
        small_array(group, layout, name, np.concatenate([[0], np.cumsum(flat, dtype=np.int64)]).astype(np.int64))
    if layout.solid:
        rows = np.concatenate(coarse) if coarse else np.empty((0, 4), np.int32)
        small_array(group, layout, "inside/coarse", rows[np.argsort(octant_keys(rows, layout.depth), kind="stable")]
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
            grid = pooled(grid)
    about: dict[str, Any] = dict(group.attrs["implc"])  # type: ignore[arg-type]  # written by create_store
    about["manifest"] = {"complete": True, "tasks": len(summaries), "voxels": int(sum(s["voxels"] for s in summaries)),
                         "inside_octants": int(sum(s["octants"] + s["coarse"] for s in summaries)),
                         "inside_voxels": int(sum(s["inside_voxels"] for s in summaries)),
                         "bricks": int(len(bricks_all)), "shards": int(sum(len(s["shards"]) for s in summaries))}
    place.remove_all("_parts")
    if isinstance(place, FolderPlace):  # an object store's writes are whole or absent
        _remove_abandoned_writes(place.folder)
    group.attrs["implc"] = about  # last: the store is complete


ABANDONED_WRITE = re.compile(r"\.[0-9a-f]{32}\.partial$")
"""The name zarr's local store writes a chunk or shard under before renaming it into place (``NAME.<uuid4
hex>.partial``): a worker killed in the middle of that write leaves one behind."""


def _remove_abandoned_writes(folder: Path) -> None:
    """Delete the files that writers killed mid-write left (:data:`ABANDONED_WRITE`): every task has finished,
    so nothing writes any more, and the task of a killed worker ran again elsewhere (a killed worker leaves
    ``occupancy/c/2/1/3.<uuid>.partial`` beside the shard its task's second run wrote)."""
    for path in folder.rglob("*.partial"):
        if path.is_file() and ABANDONED_WRITE.search(path.name):
            path.unlink(missing_ok=True)


@contextlib.contextmanager
def _replacing(target: Path | str, plan: dict) -> Iterator[StorePlace]:
    """Where :func:`save_zarr` writes: a folder replaced whole when the block completes, or a URL that holds
    nothing yet (:func:`_writing`)."""
    if isinstance(target, str):
        with _writing(target, plan, resume=False) as place:
            yield place
    else:
        with replacing_folder(target, STORE_KIND, is_store_folder, marked=False) as folder:
            yield FolderPlace(folder)


def save_zarr(voxels: Voxels, path: str | os.PathLike[str]) -> Path | str:
    """Write ``voxels`` (with the inside octants, for a solid) as the store :func:`write_zarr` writes at
    ``path`` (a folder, conventionally ending in .zarr, or an object store's URL)."""
    layout = Layout.of(voxels.depth, voxels.bounds, voxels.inside is not None)
    depth, level = layout.depth, layout.task_level
    coords, normals = voxels.coords, voxels.normals
    inside = voxels.inside if voxels.inside is not None else np.empty((0, 4), np.int32)
    target = target_of(path)
    plan: dict = {"surface": None, "options": None}
    with _replacing(target, plan) as place:
        create_store(place.url, layout, plan)
        plan_rows = inside[inside[:, 3] <= level]
        fine = inside[inside[:, 3] > level]
        voxel_cells = coords.astype(np.int64) >> (depth - level)
        voxel_tasks = morton_codes(voxel_cells) if len(coords) else np.empty(0, np.uint64)
        fine_cells = first_cells(fine, depth) >> (depth - level) if len(fine) else np.empty((0, 3), np.int64)
        fine_tasks = morton_codes(fine_cells) if len(fine) else np.empty(0, np.uint64)
        cells = np.concatenate([voxel_cells, fine_cells]).reshape(-1, 3)
        cells = np.unique(cells, axis=0) if len(cells) else cells
        summaries = []
        for t, (cell, full, rows) in enumerate(_task_list(layout, cells, plan_rows)):
            key = morton_codes(np.array([cell], np.int64))[0]
            v0, v1 = np.searchsorted(voxel_tasks, [key, key + np.uint64(1)])
            mine = fine[fine_tasks == key]
            found = TaskVoxels(coords[v0:v1], normals[v0:v1], mine, 0, [0] * abi.TIGHTEN_STATS_WORDS, 0.0)
            summaries.append(store_task(place.url, layout, t, cell, found, rows, full))
        _finish(place, layout, summaries, None, default_workers())
    return target
