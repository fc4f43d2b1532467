"""The parallel subdivider: plans octant tasks, balances them over worker threads, gathers results in order.

After the paper's Fig. 3, with today's means: a plan pass subdivides the root down to a coarse level
and keeps the octants that may meet the surface; those become tasks, handed to workers as they go idle
(a shared counter). Each worker runs the native depth-first walk (:mod:`implc.engines.walk_native`, over the
surface's evaluator: its compiled kernels or the tape engine) on its task with the GIL released: the
voxels, their normals and the second look's marks; then the drop of the marked ones. Finished tasks reach the storage
backend strictly in task order (the paper's master's role, taken by whichever worker finds the next task
ready, so that no extra thread competes for the cores): the voxels arrive in Morton order and the result
is identical for every worker count. With a *placement* (the default octree's), that serial step shrinks
to claiming each task's place in the output; the worker then stores the task there while the next task
is claimed. The calling thread only waits.

Ctrl-C or an error in a worker raises a cancel flag that native code polls every octant; every thread is
joined before the exception reaches the caller.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable, Iterator
from contextvars import ContextVar
from dataclasses import dataclass, field

import numpy as np

from ..common.context import scoped
from ..native import abi, big_arrays
from ..native.abi import GEOMETRY_DOUBLES, MAX_DEPTH
from ..native.runtime import Runtime
from .rows_native import ROWS

TASK_SPAN = 8
"""Levels from a task's cell to its voxels at most, where the plan allows (a surface puts about 4^8 voxels
below a cell eight levels up). Smaller tasks keep fewer voxels waiting for their turn in finished tasks'
buffers: fewer page faults and a lower peak on fine grids, for the same wall time (``implc bench --sections
scale`` measures both)."""
MAX_TASK_LEVEL = 5
"""The deepest level a plan goes to (32³ cells: cheap whatever the grid)."""
OUTPUT_CHUNK = 1 << 16
"""Free rows a task's result has before each native call (it returns when they are full, and the
result grows)."""
TASK_RESERVE = 16
"""A task's buffers reserve this many times the voxels a task usually has (4^span): address space only,
since untouched pages cost nothing, so that a big task's buffers rarely grow (a growth copies, and
touches fresh pages twice over)."""


@dataclass
class SubdivisionStats:
    """What a voxelization did: work, per-level survivors, stage times, per-worker busy time.

    ``seconds``: wall time of each stage (plan, subdivide — the parallel phase, normals included —,
    storage — the time one task at a time spent storing, the serial part —, finish, total).
    ``worker_busy``: seconds each worker spent working (its tasks, storing), of which ``worker_leaves`` in
    the pass after each task's walk (the drop of the leaves its second look proved empty; the normals and
    the second look run in the walk).
    """

    depth: int
    workers: int
    tasks: int = 0
    task_level: int = 0
    interval_evaluations: int = 0
    kept_per_level: list = field(default_factory=list)
    seconds: dict = field(default_factory=dict)
    worker_busy: list = field(default_factory=list)
    worker_leaves: list = field(default_factory=list)
    worker_tasks: list = field(default_factory=list)
    program_length: int = 0
    tightened: list = field(default_factory=lambda: [0] * abi.TIGHTEN_STATS_WORDS)  # leaves tested, dropped
    estimated_voxels: int = 0  # the up-front estimate voxelize() checks memory with
    estimated_bytes: int = 0
    live_ops_per_level: list = field(default_factory=list)
    octants_per_level: list = field(default_factory=list)

    @property
    def parallel_yield(self) -> float:
        """The paper's yield t1 / (n · tn), with t1 estimated as the summed busy time of all workers."""
        wall = self.seconds.get("subdivide", 0.0)
        return sum(self.worker_busy) / (self.workers * wall) if wall > 0 else 1.0

    @property
    def mean_live_ops(self) -> list:
        """Tape engine: the mean length of the program each level's octants ran (MPR's "live ops per
        octant"), None for levels that ran none; empty for compiled kernels."""
        return [ops / n if n else None for ops, n in zip(self.live_ops_per_level, self.octants_per_level)]

    def summary(self) -> str:
        tested, dropped = self.tightened
        second = f", {dropped} of {tested} leaves dropped at a second look" if tested else ""
        return (f"{self.interval_evaluations} interval evaluations{second}, {self.tasks} tasks at level "
                f"{self.task_level}, {self.workers} workers, yield {self.parallel_yield:.0%}")


def geometry(bounds, depth: int) -> np.ndarray:
    """Origin, outward pad and cell size per level, as the native subdivider reads them."""
    geom = np.zeros(GEOMETRY_DOUBLES)
    for a, (lo, hi) in enumerate(bounds):
        geom[a] = lo
        geom[3 + a] = (abs(lo) + abs(hi)) * 2.0**-50  # covers the rounding of lo + i·h
        for level in range(MAX_DEPTH + 2):
            geom[6 + 3 * level + a] = (hi - lo) / 2.0**level
    return geom


@dataclass(frozen=True)
class Buffers:
    """The rows a task's buffers take: ``output_chunk`` free rows before each native call
    (:data:`OUTPUT_CHUNK`), a task's reserve ``task_reserve`` times its usual voxels (:data:`TASK_RESERVE`).
    The voxels are the same for every value (tests make them tiny, so that tasks resume and grow)."""

    output_chunk: int = OUTPUT_CHUNK
    task_reserve: int = TASK_RESERVE


BUFFERS: ContextVar[Buffers] = ContextVar("implc_buffers", default=Buffers())
"""The :class:`Buffers` a :class:`Subdivider` made in this context takes (:func:`buffers` sets them)."""


@contextlib.contextmanager
def buffers(sizes: Buffers) -> Iterator[None]:
    """Within the block, voxelizations size their tasks' buffers by ``sizes``."""
    with scoped(BUFFERS, sizes):
        yield


class _TaskResult:
    """Reusable arrays for one finished task's voxels, written by the native subdivider in place: pooled,
    so that steady state allocates nothing (fresh pages are costly, and page faults from several threads
    contend in the kernel). ``chunk``: the free rows each native call gets."""

    def __init__(self, chunk: int, reserve: int = 0):
        self.count = 0
        self.chunk = chunk
        self._allocate(max(int(reserve), chunk))
        self.inside_count = 0  # a solid's inside octants (abi.INSIDE_WORDS int32 each), allocated on first use
        self.inside = np.empty((0, abi.INSIDE_WORDS), dtype=np.int32)

    def make_inside_room(self, free):
        """At least ``free`` unused inside rows past ``inside_count``."""
        if self.inside_count + free > len(self.inside):
            grown = np.empty((max(self.inside_count + free, 2 * len(self.inside)), abi.INSIDE_WORDS), dtype=np.int32)
            grown[: self.inside_count] = self.inside[: self.inside_count]
            self.inside = grown
        return len(self.inside) - self.inside_count

    def inside_args(self, solid: bool) -> tuple:
        """The native subdividers' (inside, inside_capacity) arguments: NULL and 0 unless ``solid``."""
        if not solid:
            return None, 0
        room = self.make_inside_room(max(self.chunk // 4, 64))  # the native side needs 8 free rows
        return self.inside.ctypes.data + 4 * abi.INSIDE_WORDS * self.inside_count, room

    def _allocate(self, size):
        self.flags = big_arrays.empty(size, np.uint8)  # the normals' flags for tightening, then its marks
        self.coords = big_arrays.empty((size, 3), np.uint32)
        self.masks = big_arrays.empty(size, np.int64)  # each voxel's live-term mask
        self.normals = big_arrays.empty((size, 3), np.float32)
        # raw pointers, taken once: numpy's .ctypes.data costs microseconds per access
        self.coords_ptr, self.masks_ptr = self.coords.ctypes.data, self.masks.ctypes.data
        self.normals_ptr, self.flags_ptr = self.normals.ctypes.data, self.flags.ctypes.data

    def make_room(self, free):
        """At least ``free`` unused rows past ``count`` (doubling, keeping the rows written so far)."""
        if self.count + free > len(self.coords):
            kept = [(name, getattr(self, name)[: self.count]) for name in ("coords", "masks", "normals", "flags")]
            self._allocate(max(self.count + free, 2 * len(self.coords)))
            for name, rows in kept:  # flags too: the walk writes them, and the second look's marks
                getattr(self, name)[: self.count] = rows
        return len(self.coords) - self.count


class _Worker:
    """Per-thread native buffers and counters: the walk's state, frames and statistics, and its evaluator's
    words (``words``, with the buffers they point to kept alive in ``buffers``)."""

    def __init__(self, depth, words: np.ndarray, buffers: tuple = ()):
        self.state = np.zeros(abi.WALK_STATE_WORDS, dtype=np.int64)
        self.frames = np.zeros(abi.WALK_LEVELS * abi.WALK_FRAME_WORDS, dtype=np.int32)
        self.stats = np.zeros(abi.WALK_STATS_WORDS, dtype=np.int64)
        self.tighten_stats = np.zeros(abi.TIGHTEN_STATS_WORDS, dtype=np.int64)
        self.inside_count = np.zeros(1, dtype=np.int64)
        self.depth = depth
        self.words, self.buffers = words, buffers
        # raw pointers, taken once: numpy's .ctypes.data costs microseconds per access
        self.walk_buffers = tuple(a.ctypes.data for a in (words, self.state, self.frames))
        self.stats_ptr = self.stats.ctypes.data
        self.busy = 0.0
        self.leaves = 0.0
        self.tasks = 0


class WalkEvaluator:
    """An evaluator as the driver sees it: its native walk (:mod:`implc.engines.walk_native`, with
    :data:`implc.native.abi.WALK_PARAMS`) and each worker's words (and the buffers they point to, kept alive with
    the worker)."""

    walk: Callable[..., int]

    def worker_words(self) -> tuple[np.ndarray, tuple]:
        raise NotImplementedError


class Subdivider:
    """Runs one voxelization of ``surface`` to ``depth``; ``emit(coords, normals)`` receives the voxels.
    ``evaluator``: the :class:`WalkEvaluator` to run (default: the surface's compiled kernels or tape engine,
    as its engine and the options ask)."""

    def __init__(self, surface, depth: int, workers: int, runtime: Runtime, max_voxels: int | None = None,
                 mean_value_levels: int = 0, prune: bool = True, refine_leaves: bool | str = "auto",
                 solid: bool = False, evaluator: WalkEvaluator | None = None):
        self.surface = surface
        self.depth = depth
        self.workers = workers
        self.buffers = BUFFERS.get()
        self.runtime = runtime
        self.max_voxels = max_voxels
        self.geom = geometry(surface.bounds, depth)
        self.prune = int(bool(prune))
        self.refine = int(refine_leaves is True)
        self.solid = bool(solid)
        self._inside_parts: list[np.ndarray] = []  # a solid's inside octants: the plan's, then each task's
        self._emit_inside = None  # run()'s receiver of each task's inside octants, if any
        # the last mean_value_levels levels use the tighter mean-value kernel
        self.fine_level = depth - mean_value_levels + 1 if mean_value_levels > 0 else MAX_DEPTH + 1
        # the tape engine runs the surface where it is the surface's engine (the mean-value form is compiled only)
        self.program = surface.program if mean_value_levels == 0 else None
        # the second look at the leaves the normals flag (with compiled kernels, their monotonicity bound)
        self.tightens = refine_leaves == "auto"
        if evaluator is None:
            evaluator = surface.walk_evaluator(self.program, depth, mean_value_levels, self.fine_level, self.tightens)
        self.evaluator = evaluator
        self.cancel = np.zeros(1, dtype=np.int32)
        self.geom_ptr = self.geom.ctypes.data
        self.cancel_ptr = self.cancel.ctypes.data
        self.stats = SubdivisionStats(depth=depth, workers=workers, kept_per_level=[1] + [0] * depth)
        self._plan_normals = None  # where the plan reached the leaves: their normals, and the time that took
        self._plan_leaves_seconds = 0.0
        if self.program is not None:
            self.stats.program_length = len(self.program)
            self.stats.live_ops_per_level = [0] * (depth + 1)
            self.stats.octants_per_level = [0] * (depth + 1)

    # -- native steps ------------------------------------------------------------------------------
    def _new_worker(self, depth) -> _Worker:
        return _Worker(depth, *self.evaluator.worker_words())

    def _run_task(self, w: _Worker, cell, level: int, depth: int, result: _TaskResult) -> None:
        """Append all kept cells at ``depth`` below ``cell`` (at ``level``) to ``result``, in Morton order,
        with their normals (and, where tightening, the second look's marks)."""
        frame = level * abi.WALK_FRAME_WORDS
        w.frames[frame: frame + 3] = cell
        w.state[abi.WALK_PHASE] = 0
        w.state[abi.WALK_DEPTH] = depth
        w.state[abi.WALK_TASK_LEVEL] = level
        while True:
            room = result.make_room(self.buffers.output_chunk)
            # the leaves' flags (and so the second look) only where the task reaches the leaves: never for
            # the plan's cells above them
            flags = result.flags_ptr + result.count if self.tightens and depth == self.depth else None
            n = self.evaluator.walk(w.walk_buffers[0], self.prune, self.refine, self.geom_ptr, *w.walk_buffers[1:],
                          result.coords_ptr + 12 * result.count, result.masks_ptr + 8 * result.count,
                          result.normals_ptr + 12 * result.count, flags, room, *result.inside_args(self.solid),
                          w.stats_ptr, self.cancel_ptr)
            result.count += n
            result.inside_count += int(w.state[abi.WALK_INSIDE_COUNT])
            if w.state[abi.WALK_PHASE] == 2 or self.cancel[0]:
                break

    @property
    def inside(self) -> np.ndarray:
        """A solid's inside octants found so far, in task order: (n, 4) int32 rows (i, j, k, level)."""
        parts = [p for p in self._inside_parts if len(p)]
        return np.concatenate(parts) if parts else np.empty((0, abi.INSIDE_WORDS), dtype=np.int32)

    def _leaves(self, w: _Worker, result: _TaskResult) -> None:
        """The end of a task's second look: the leaves it proved empty dropped
        (``implc_drop_marked``, :mod:`implc.engines.rows_native`; a solid's proven-inside ones join the task's
        inside octants)."""
        n = result.count
        if not self.tightens or n == 0:
            return
        inside = None
        if self.solid:
            result.make_inside_room(n)
            inside = result.inside.ctypes.data
            w.inside_count[0] = result.inside_count
        result.count = self.runtime.library(ROWS).drop_marked(self.depth, result.coords_ptr, result.masks_ptr,
                                                result.normals_ptr, result.flags_ptr, n, inside,
                                                w.inside_count.ctypes.data, w.tighten_stats.ctypes.data)
        if self.solid:
            result.inside_count = int(w.inside_count[0])

    # -- orchestration ---------------------------------------------------------------------------
    def plan(self) -> tuple[np.ndarray, int]:
        """Tasks: the cells at a coarse level that may meet the surface (and that level)."""
        # enough tasks to balance the workers (~25 per worker), few enough that per-task overhead stays small,
        # and no more than TASK_SPAN levels below a task where the plan stays cheap (level 5 at most): a
        # task's voxels (about 4^span) sit in buffers that stay allocated, so on fine grids smaller tasks
        # keep the peak memory low
        balance = 2 if self.workers <= 2 else 3 if self.workers <= 16 else 4
        level = min(self.depth, max(balance, min(self.depth - TASK_SPAN, MAX_TASK_LEVEL)))
        t0 = time.perf_counter()
        w, result = self._from_root(level)
        if level == self.depth:  # the plan reached the leaves: their pass now, normals included
            t_leaves = time.perf_counter()
            self._leaves(w, result)
            self._plan_normals = result.normals[: result.count].copy()
            self._plan_leaves_seconds = time.perf_counter() - t_leaves
        cells = result.coords[: result.count].copy()
        self._inside_parts = [result.inside[: result.inside_count].copy()]
        self.stats.seconds["plan"] = time.perf_counter() - t0 - self._plan_leaves_seconds  # the leaves': run()'s
        self._absorb(w)
        self.stats.task_level = level
        self.stats.tasks = len(cells)
        return cells, level

    def count_cells(self, level: int) -> int:
        """How many cells at ``level`` may meet the surface (a subdivision from the root, kept apart from
        the statistics; for the memory estimate)."""
        return self._from_root(level)[1].count

    def cells_below(self, cell, level: int, to_level: int) -> tuple[np.ndarray, np.ndarray]:
        """The cells at ``to_level`` below ``cell`` (at ``level``) that may meet the surface, in Morton
        order, and (a solid) the inside octants found on the way: a plan for :meth:`run` that starts at
        one octant (a cluster's task) instead of the root."""
        if to_level == level:
            return np.array([cell], dtype=np.uint32), np.empty((0, abi.INSIDE_WORDS), dtype=np.int32)
        w, result = self._below(tuple(int(c) for c in cell), level, to_level)
        self._absorb(w)
        return result.coords[: result.count].copy(), result.inside[: result.inside_count].copy()

    def _from_root(self, level: int) -> tuple[_Worker, _TaskResult]:
        """The subdivision of the root down to ``level``: its worker (with its counters) and its cells."""
        return self._below((0, 0, 0), 0, level)

    def _below(self, cell, level: int, to_level: int) -> tuple[_Worker, _TaskResult]:
        """The subdivision of ``cell`` (at ``level``) down to ``to_level``: its worker and its cells."""
        w, result = self._new_worker(to_level), _TaskResult(self.buffers.output_chunk)
        self._run_task(w, cell, level, to_level, result)
        return w, result

    def _absorb(self, w: _Worker):
        self.stats.interval_evaluations += int(w.stats[0])
        for i in range(abi.TIGHTEN_STATS_WORDS):
            self.stats.tightened[i] += int(w.tighten_stats[i])
        w.tighten_stats[:] = 0
        for level in range(1, self.depth + 1):
            self.stats.kept_per_level[level] += int(w.stats[level + 1])
        if self.program is not None:
            for level in range(self.depth + 1):
                self.stats.live_ops_per_level[level] += int(w.stats[abi.WALK_LEVELS + level])
                self.stats.octants_per_level[level] += int(w.stats[2 * abi.WALK_LEVELS + level])
        w.stats[:] = 0

    def run(self, emit, progress=None, plan=None, emit_inside=None, placement=None) -> SubdivisionStats:
        """Voxelize, handing Morton-ordered batches to ``emit``; ``plan``: the result of :meth:`plan` when
        the caller already made it. A solid's inside octants are kept (:attr:`inside`), or with
        ``emit_inside`` handed to it task by task, each task's after its voxels (the plan's stay in
        :attr:`inside`).

        ``placement`` (for a plan that stops above the leaves) replaces ``emit`` with a protocol that
        leaves one thread only the bookkeeping: ``placement.prepare(result, cell)`` in the worker once a
        task is done; ``placement.claim(result)`` in task order, one task at a time (it assigns the
        task's place in the output); ``placement.fill(result, cell, ticket)`` right after, in the worker
        that claimed it, in parallel with other claims and fills (the task's buffers are reused after).
        ``result.count``, ``result.coords`` and ``result.normals`` are the task's voxels."""
        self._emit_inside = emit_inside
        cells, level = plan if plan is not None else self.plan()
        if placement is not None and level == self.depth:
            raise ValueError("a placement needs tasks above the leaves (plan level < depth)")
        if level == self.depth:  # the plan already reached the leaves
            if self.max_voxels is not None and len(cells) > self.max_voxels:
                raise MemoryError(f"more than max_voxels={self.max_voxels} voxels at depth {self.depth}")
            t0 = time.perf_counter()
            emit(cells, self._plan_normals)  # the plan's pass over its leaves wrote them
            # the plan's pass over the leaves is this stage's work (it ran in plan(), on this thread)
            self.stats.seconds["subdivide"] = time.perf_counter() - t0 + self._plan_leaves_seconds
            self.stats.worker_busy = [self._plan_leaves_seconds]
            self.stats.worker_leaves = [self._plan_leaves_seconds]
            self.stats.worker_tasks = [len(cells)]
            return self.stats
        self._parallel(cells, level, emit, progress, placement)
        return self.stats

    def _parallel(self, cells, level, emit, progress, placement):
        n_tasks = len(cells)
        results: dict[int, _TaskResult] = {}
        errors: list[BaseException] = []
        lock = threading.Lock()
        finished = threading.Event()  # all tasks stored, or an error: the only thing the caller waits for
        next_task, next_emit, committing, produced = [0], [0], [False], [0]
        storage_seconds = [0.0]
        in_flight = threading.Semaphore(4 * self.workers)  # bounds finished-but-unstored results
        workers = [self._new_worker(self.depth) for _ in range(self.workers)]
        pool: list[_TaskResult] = []
        reserve = min(self.buffers.task_reserve * 4 ** (self.depth - level), 1 << 22)

        filled = [0]

        def commit_ready(w: _Worker):
            """Hand finished tasks to the backend (or claim their place) in task order; whichever worker
            finds the next one ready does it, so storage needs no extra thread competing for the cores.
            With a placement, the claim is all that runs one task at a time: the claimer then fills the
            task's place while the next task can be claimed."""
            while True:
                with lock:
                    t = next_emit[0]
                    if committing[0] or t not in results or self.cancel[0]:
                        return
                    committing[0] = True
                    result = results.pop(t)
                ticket = None
                t0 = time.perf_counter()
                try:
                    try:
                        if placement is not None:
                            ticket = placement.claim(result)
                        else:
                            emit(result.coords[: result.count], result.normals[: result.count])
                        if self.solid and self._emit_inside is not None:
                            self._emit_inside(result.inside[: result.inside_count])
                        elif self.solid:
                            self._inside_parts.append(result.inside[: result.inside_count].copy())
                        storage_seconds[0] += time.perf_counter() - t0
                        if progress is not None:
                            progress.update(1)
                    finally:
                        with lock:
                            next_emit[0] = t + 1
                            committing[0] = False
                    if placement is not None:
                        placement.fill(result, cells[t], ticket)
                finally:
                    w.busy += time.perf_counter() - t0  # storing is work a single worker would do too
                    in_flight.release()
                    with lock:
                        pool.append(result)
                        filled[0] += 1
                        done = filled[0] == n_tasks
                    if done:
                        finished.set()

        def work(w: _Worker):
            try:
                while not self.cancel[0]:
                    in_flight.acquire()
                    with lock:
                        t = next_task[0]
                        next_task[0] += 1
                    if t >= n_tasks:
                        in_flight.release()
                        return
                    with lock:
                        result = pool.pop() if pool else _TaskResult(self.buffers.output_chunk, reserve)
                    result.count = result.inside_count = 0
                    t0 = time.perf_counter()
                    self._run_task(w, cells[t], level, self.depth, result)
                    t1 = time.perf_counter()
                    self._leaves(w, result)
                    t2 = time.perf_counter()
                    if placement is not None:
                        placement.prepare(result, cells[t])
                    w.busy += time.perf_counter() - t0
                    w.leaves += t2 - t1
                    w.tasks += 1
                    with lock:
                        produced[0] += result.count
                        if self.max_voxels is not None and produced[0] > self.max_voxels:
                            raise MemoryError(f"more than max_voxels={self.max_voxels} voxels at depth {self.depth}")
                        results[t] = result
                    commit_ready(w)
            except BaseException as exc:  # noqa: BLE001 - any failure must reach the caller
                self.cancel[0] = 1
                with lock:
                    errors.append(exc)
                finished.set()

        threads = [threading.Thread(target=work, args=(w,), name=f"implc-worker-{i}", daemon=True)
                   for i, w in enumerate(workers)]
        t_start = time.perf_counter()
        if n_tasks == 0:
            finished.set()
        try:
            for th in threads:
                th.start()
            while not finished.wait(0.05):  # short waits keep Ctrl-C prompt
                pass
            if errors:
                raise errors[0]
        except BaseException:
            self.cancel[0] = 1
            raise
        finally:
            for _ in threads:
                in_flight.release()  # wake any worker blocked on the semaphore
            for th in threads:
                if th.ident is not None:  # Ctrl-C may come while the threads are being started
                    th.join()
        self.stats.seconds["subdivide"] = time.perf_counter() - t_start
        self.stats.seconds["storage"] = storage_seconds[0]
        for w in workers:
            self._absorb(w)
        self.stats.worker_busy = [w.busy for w in workers]
        self.stats.worker_leaves = [w.leaves for w in workers]
        self.stats.worker_tasks = [w.tasks for w in workers]
