"""The parallel subdivider: plans octant tasks, balances them over worker threads, gathers results in order.

After the paper's Fig. 3, with today's means: a plan pass subdivides the root down to a coarse level
and keeps the octants that may meet the surface; those become tasks, handed to workers as they go idle
(a shared counter). Each worker runs the native depth-first subdivider (:mod:`implc.codegen.runtime`)
on its task with the GIL released, then the native normal kernel, and returns the task's voxels. The
calling thread (the paper's master) hands finished tasks to the storage backend strictly in task order,
so the voxels arrive in Morton order and the result is identical for every worker count.

Ctrl-C or an error in a worker raises a cancel flag that native code polls every octant; every thread is
joined before the exception reaches the caller.
"""

from __future__ import annotations

import os
import threading
import time
from dataclasses import dataclass, field

import numpy as np

from .codegen.runtime import GEOMETRY_DOUBLES, MAX_DEPTH, STACK_ENTRIES
from .runtime import Runtime

OUTPUT_CHUNK = 1 << 16
"""Voxels one native call writes before returning to drain its buffer."""


@dataclass
class SubdivisionStats:
    """What a voxelization did: work, per-level survivors, stage times, per-worker busy time.

    ``seconds``: wall time of each stage (plan, subdivide — the parallel phase, normals included —,
    storage — time the calling thread spent in the backend —, finish, total). ``worker_busy``: seconds
    each worker spent in native work, of which ``worker_normals`` computing normals.
    """

    depth: int
    workers: int
    tasks: int = 0
    task_level: int = 0
    interval_evaluations: int = 0
    kept_per_level: list = field(default_factory=list)
    seconds: dict = field(default_factory=dict)
    worker_busy: list = field(default_factory=list)
    worker_normals: list = field(default_factory=list)
    worker_tasks: list = field(default_factory=list)

    @property
    def parallel_yield(self) -> float:
        """The paper's yield t1 / (n · tn), with t1 estimated as the summed busy time of all workers."""
        wall = self.seconds.get("subdivide", 0.0)
        return sum(self.worker_busy) / (self.workers * wall) if wall > 0 else 1.0

    def summary(self) -> str:
        return (f"{self.interval_evaluations} interval evaluations, {self.tasks} tasks at level {self.task_level}, "
                f"{self.workers} workers, yield {self.parallel_yield:.0%}")


def default_workers() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - non-Linux
        return os.cpu_count() or 1


def geometry(bounds, depth: int) -> np.ndarray:
    """Origin, outward pad and cell size per level, as the native subdivider reads them."""
    geom = np.zeros(GEOMETRY_DOUBLES)
    for a, (lo, hi) in enumerate(bounds):
        geom[a] = lo
        geom[3 + a] = (abs(lo) + abs(hi)) * 2.0**-50  # covers the rounding of lo + i·h
        for level in range(MAX_DEPTH + 1):
            geom[6 + 3 * level + a] = (hi - lo) / 2.0**level
    return geom


class _Worker:
    """Per-thread native buffers and counters."""

    def __init__(self, depth):
        self.stack = np.zeros(4 * STACK_ENTRIES, dtype=np.int32)
        self.state = np.zeros(2, dtype=np.int64)
        self.out = np.empty((OUTPUT_CHUNK, 3), dtype=np.uint32)
        self.stats = np.zeros(MAX_DEPTH + 2, dtype=np.int64)
        self.depth = depth
        self.busy = 0.0
        self.normals = 0.0
        self.tasks = 0


class Subdivider:
    """Runs one voxelization of ``surface`` to ``depth``; ``emit(coords, normals)`` receives the voxels."""

    def __init__(self, surface, depth: int, workers: int, runtime: Runtime, max_voxels: int | None = None):
        self.surface = surface
        self.depth = depth
        self.workers = workers
        self.runtime = runtime
        self.max_voxels = max_voxels
        self.geom = geometry(surface.bounds, depth)
        leaf = self.geom[6 + 3 * depth: 9 + 3 * depth]
        self.leaf_geom = np.concatenate([self.geom[:3], leaf])
        self.box = surface.native.address("implc_interval")
        self.gradient = surface.native.address("implc_gradient")
        self.point = surface.native.address("implc_point")
        self.cancel = np.zeros(1, dtype=np.int32)
        self.stats = SubdivisionStats(depth=depth, workers=workers, kept_per_level=[1] + [0] * depth)

    # -- native steps ------------------------------------------------------------------------------
    def _run_task(self, w: _Worker, cell, level: int, depth: int) -> np.ndarray:
        """All kept cells at ``depth`` below ``cell`` (at ``level``), in Morton order."""
        w.stack[:4] = (*cell, level)
        w.state[:] = (1, depth)
        chunks = []
        while True:
            n = self.runtime.subdivide(self.box, self.geom.ctypes.data, w.stack.ctypes.data, w.state.ctypes.data,
                                       w.out.ctypes.data, len(w.out), w.stats.ctypes.data, self.cancel.ctypes.data)
            if n:
                chunks.append(w.out[:n].copy())
            if w.state[0] == 0 or self.cancel[0]:
                break
        return np.concatenate(chunks) if chunks else np.zeros((0, 3), dtype=np.uint32)

    def _normals(self, coords: np.ndarray) -> np.ndarray:
        normals = np.empty((len(coords), 3), dtype=np.float32)
        if len(coords):
            self.runtime.normals(self.gradient, self.point, self.leaf_geom.ctypes.data, coords.ctypes.data,
                                 len(coords), normals.ctypes.data)
        return normals

    # -- orchestration ---------------------------------------------------------------------------
    def plan(self) -> tuple[np.ndarray, int]:
        """Tasks: the cells at a coarse level that may meet the surface (and that level)."""
        level = min(self.depth, 3 if self.workers <= 4 else 4)
        w = _Worker(level)
        t0 = time.perf_counter()
        cells = self._run_task(w, (0, 0, 0), 0, level)
        self.stats.seconds["plan"] = time.perf_counter() - t0
        self._absorb(w)
        self.stats.task_level = level
        self.stats.tasks = len(cells)
        return cells, level

    def _absorb(self, w: _Worker):
        self.stats.interval_evaluations += int(w.stats[0])
        for level in range(1, self.depth + 1):
            self.stats.kept_per_level[level] += int(w.stats[level + 1])
        w.stats[:] = 0

    def run(self, emit, progress=None) -> SubdivisionStats:
        cells, level = self.plan()
        if level == self.depth:  # the plan already reached the leaves
            t0 = time.perf_counter()
            emit(cells, self._normals(cells))
            self.stats.seconds["subdivide"] = time.perf_counter() - t0
            self.stats.worker_busy = [self.stats.seconds["subdivide"]]
            self.stats.worker_normals = [self.stats.seconds["subdivide"]]
            self.stats.worker_tasks = [len(cells)]
            return self.stats
        self._parallel(cells, level, emit, progress)
        return self.stats

    def _parallel(self, cells, level, emit, progress):
        n_tasks = len(cells)
        results: dict[int, tuple] = {}
        errors: list[BaseException] = []
        cond = threading.Condition()
        next_task = [0]
        produced = [0]
        in_flight = threading.Semaphore(4 * self.workers)  # bounds finished-but-unconsumed results
        workers = [_Worker(self.depth) for _ in range(self.workers)]

        def work(w: _Worker):
            try:
                while not self.cancel[0]:
                    in_flight.acquire()
                    with cond:
                        t = next_task[0]
                        next_task[0] += 1
                    if t >= n_tasks:
                        in_flight.release()
                        return
                    t0 = time.perf_counter()
                    coords = self._run_task(w, cells[t], level, self.depth)
                    t1 = time.perf_counter()
                    normals = self._normals(coords)
                    t2 = time.perf_counter()
                    w.busy += t2 - t0
                    w.normals += t2 - t1
                    w.tasks += 1
                    with cond:
                        produced[0] += len(coords)
                        if self.max_voxels is not None and produced[0] > self.max_voxels:
                            raise MemoryError(f"more than max_voxels={self.max_voxels} voxels at depth {self.depth}")
                        results[t] = (coords, normals)
                        cond.notify_all()
            except BaseException as exc:  # noqa: BLE001 - any failure must reach the caller
                self.cancel[0] = 1
                with cond:
                    errors.append(exc)
                    cond.notify_all()

        threads = [threading.Thread(target=work, args=(w,), name=f"implc-worker-{i}", daemon=True)
                   for i, w in enumerate(workers)]
        t_start = time.perf_counter()
        storage_seconds = 0.0
        try:
            for th in threads:
                th.start()
            for t in range(n_tasks):
                with cond:
                    while t not in results and not errors:
                        cond.wait(0.05)  # short waits keep Ctrl-C prompt
                    if errors:
                        raise errors[0]
                    coords, normals = results.pop(t)
                in_flight.release()
                t0 = time.perf_counter()
                emit(coords, normals)
                storage_seconds += time.perf_counter() - t0
                if progress is not None:
                    progress.update(1)
        except BaseException:
            self.cancel[0] = 1
            raise
        finally:
            for _ in threads:
                in_flight.release()  # wake any worker blocked on the semaphore
            for th in threads:
                th.join()
        self.stats.seconds["subdivide"] = time.perf_counter() - t_start
        self.stats.seconds["storage"] = storage_seconds
        for w in workers:
            self._absorb(w)
        self.stats.worker_busy = [w.busy for w in workers]
        self.stats.worker_normals = [w.normals for w in workers]
        self.stats.worker_tasks = [w.tasks for w in workers]
