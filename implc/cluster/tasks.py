"""Beyond one process: a voxelization's tasks on a Dask cluster (``implc[cluster]``), or in this process
through the same code.

A task is one octant of the grid at the *task level* (:func:`task_level`: cubes of at most 2^10 cells per
axis, at least 4³ of them): its worker rebuilds the surface from its :class:`~implc.cluster.recipe.SurfaceRecipe`
(compiled once per worker process, :func:`implc.cluster.recipe.build`), subdivides the octant
(:func:`task_voxels`) and returns or stores what it found. Dask schedules the tasks, retries those of a
worker that died, and reports progress; nothing here schedules. Tasks are pure functions of their
arguments, so a task run twice gives the same result.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import logging
import re
import resource
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..common.threads import default_workers
from ..common.untrusted import printable
from ..engines.walk import Subdivider, SubdivisionStats
from ..errors import ClusterError
from ..native import abi
from .recipe import SurfaceRecipe, build

LOCAL = "local:"
"""``local:N``: a cluster of N worker processes (one thread each) started and stopped by implc."""
TASK_EDGE_LOG2 = 10
"""A task's octant spans at most 2^10 cells per axis: a fraction of a second of work on the paper's scenes
(``implc bench --sections cluster``), long enough that scheduling a task costs little beside it."""
MIN_TASK_LEVEL = 2
"""At least the 4³ octants of level 2 (where the bricks allow): enough tasks to balance a few workers."""


def task_level(depth: int, brick_level: int) -> int:
    """The level of a run's tasks: octants of at most 2^TASK_EDGE_LOG2 cells per axis, at level
    MIN_TASK_LEVEL or deeper, never below the bricks (``brick_level``: each brick lies in one task)."""
    if not 0 <= brick_level <= depth:
        raise ValueError(f"the bricks' level must be from 0 to the depth {depth}, got {brick_level}")
    return min(brick_level, max(MIN_TASK_LEVEL, depth - TASK_EDGE_LOG2))


def cell_level(depth: int, brick_level: int, level: int) -> int:
    """The level a task's octant is subdivided to before its threads share the cells (two levels below
    it, at least the bricks', above the leaves)."""
    return min(depth - 1, max(brick_level, level + 2))


@dataclass
class TaskVoxels:
    """What one task found: voxels (Morton order) with normals, a solid's inside octants below the task's
    octant, and the work it took."""
    coords: np.ndarray
    normals: np.ndarray
    inside: np.ndarray
    evaluations: int
    tightened: list
    seconds: float


def subdivider_for(surface: Any, depth: int, *, solid: bool, options: dict, workers: int = 1) -> Subdivider:
    """The subdivider of a run with the voxelizer's tightness ``options`` (``mean_value_levels``,
    ``refine_leaves``; their defaults where absent)."""
    return Subdivider(surface, depth, workers, surface.runtime, solid=solid,
                      mean_value_levels=min(options.get("mean_value_levels", 0), depth),
                      refine_leaves=options.get("refine_leaves", "auto"))


def run_stats(depth: int, threads: int, seconds: float, tasks: Iterable[tuple[int, list, float]]) -> SubdivisionStats:
    """The statistics of a run from its tasks' (interval evaluations, second-look counts, busy seconds),
    over ``seconds`` of wall time on ``threads``."""
    stats = SubdivisionStats(depth=depth, workers=threads, kept_per_level=[1] + [0] * depth)
    busy = 0.0
    for evaluations, tightened, task_seconds in tasks:
        stats.interval_evaluations += evaluations
        stats.tightened = [a + b for a, b in zip(stats.tightened, tightened)]
        busy += task_seconds
    stats.worker_busy = [busy / threads] * threads
    stats.seconds["subdivide"] = stats.seconds["total"] = seconds
    return stats


def task_voxels(surface: Any, depth: int, cell: Any, level: int, *, solid: bool, options: dict, workers: int = 1,
                to_level: int | None = None) -> TaskVoxels:
    """The voxels below the octant ``cell`` at ``level`` (its threads share the cells at ``to_level``,
    default :func:`cell_level` with the bricks at the task level), as :func:`implc.voxelize` finds them."""
    t0 = time.perf_counter()
    to_level = cell_level(depth, level, level) if to_level is None else to_level
    sub = subdivider_for(surface, depth, solid=solid, options=options, workers=workers)
    cells, pre = sub.cells_below(cell, level, to_level)
    coords: list[np.ndarray] = []
    normals: list[np.ndarray] = []
    inside = [pre]

    def emit(c: np.ndarray, n: np.ndarray) -> None:  # the task's buffers are reused: copies
        coords.append(c.copy())
        normals.append(n.copy())

    if len(cells):
        sub.run(emit, plan=(cells, to_level), emit_inside=(lambda rows: inside.append(rows.copy())) if solid else None)
    return TaskVoxels(np.concatenate(coords) if coords else np.empty((0, 3), np.uint32),
                      np.concatenate(normals) if normals else np.empty((0, 3), np.float32),
                      np.concatenate(inside) if solid else np.empty((0, abi.INSIDE_WORDS), np.int32),
                      sub.stats.interval_evaluations, list(sub.stats.tightened), time.perf_counter() - t0)


def peak_memory() -> int:
    """This process's peak resident memory so far, in bytes (Linux reports kilobytes)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def _distributed():
    try:
        import distributed
    except ImportError:
        raise ClusterError("running on a cluster needs Dask's distributed package: pip install 'implc[cluster]'") \
            from None
    return distributed


def parse_address(cluster: Any) -> Any:
    """``cluster`` checked: a ``distributed.Client``, ``local:N`` (N >= 1) or a scheduler's address
    (``tcp://host:port``, ``tls://…``, ``host:port``); ClusterError otherwise."""
    if not isinstance(cluster, str):
        if type(cluster).__name__ == "Client" and hasattr(cluster, "submit"):
            return cluster
        raise ClusterError(f"cluster must be 'local:N', a scheduler address or a distributed.Client, "
                           f"not a {type(cluster).__name__}")
    shown = shown_address(cluster)
    if cluster.startswith(LOCAL):
        count, most = cluster[len(LOCAL):], max_local_workers()
        if not (count.isascii() and count.isdigit() and len(count) <= 6) or not 1 <= int(count) <= most:
            raise ClusterError(f"--cluster {shown}: local:N needs a worker count N from 1 to {most} (four per usable "
                               "core: local workers are processes on this machine)")
        return cluster
    if "://" in cluster:
        scheme, _, rest = cluster.partition("://")
        if scheme not in ("tcp", "tls", "inproc", "ucx", "ws", "wss") or not rest:
            raise ClusterError(f"--cluster {shown}: not a scheduler address (tcp://host:port) or local:N")
        return cluster
    host, _, port = cluster.rpartition(":")
    if not host or not (port.isascii() and port.isdigit()):
        raise ClusterError(f"--cluster {shown}: not a scheduler address (tcp://host:port) or local:N")
    return f"tcp://{cluster}"


def shown_address(address: str) -> str:
    """``address`` as messages show it: credentials (``user:password@``) replaced by ``***@``."""
    return printable(re.sub(r"(?<=://)[^/@\s]*@|^[^/@\s:]*:[^/@\s]*@", "***@", str(address)), 120)


def max_local_workers() -> int:
    """The most worker processes ``local:N`` starts: four per usable core."""
    return 4 * default_workers()


def local_cluster(workers: int) -> Any:
    """A LocalCluster of ``workers`` processes, one thread each, its dashboard on a free port. The
    workers' environment leaves out Dask's ``MALLOC_TRIM_THRESHOLD_``: with it glibc maps and unmaps
    every block of 128 KiB or more, and a brick's blocks are 16 MiB (tasks then take markedly more CPU;
    see docs/guide/cluster.md for workers started by hand)."""
    import dask
    distributed = _distributed()
    environ = dict(dask.config.get("distributed.nanny.pre-spawn-environ", {}))
    environ.pop("MALLOC_TRIM_THRESHOLD_", None)
    with dask.config.set({"distributed.nanny.pre-spawn-environ": environ}):
        return distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                        dashboard_address=":0", silence_logs=logging.ERROR)


@contextlib.contextmanager
def connect(cluster: Any, *, say: Callable[[str], None] | None = None) -> Iterator[Any]:
    """A ``distributed.Client`` for ``cluster`` (see :func:`parse_address`), closed after the block
    (with the LocalCluster of ``local:N``; a Client passed in stays open). ``say`` receives the
    dashboard's address."""
    cluster = parse_address(cluster)
    if not isinstance(cluster, str):
        yield cluster
        return
    distributed = _distributed()
    with contextlib.ExitStack() as stack:
        if cluster.startswith(LOCAL):
            local = local_cluster(int(cluster[len(LOCAL):]))
            stack.callback(local.close)
            client = distributed.Client(local)
        else:
            try:
                client = distributed.Client(cluster, timeout="10s")
            except Exception as exc:  # unreachable, or a transport without its configuration (tls://, ucx://)
                why = " ".join(str(exc).split())
                for secret in re.findall(r"([^/@\s]+)@", cluster):  # whatever the library echoed of the address
                    why = why.replace(secret, "***")
                raise ClusterError(f"cannot connect to the Dask scheduler at {shown_address(cluster)}: "
                                   f"{printable(why, 160) or type(exc).__name__}") from None
        stack.callback(client.close)
        if say is not None:
            say(f"cluster  {shown_address(cluster)}: {len(client.scheduler_info().get('workers', {}))} workers, "
                f"dashboard {client.dashboard_link}")
        yield client


def worker_threads(client: Any) -> int:
    """Threads of the cluster's workers, all together (at least 1)."""
    return max(1, sum(client.nthreads().values()))


NO_WORKERS_SECONDS = 60.0
"""How long a run waits for a worker when the cluster has none (they died, or none ever joined)."""
POLL_SECONDS = 0.05
"""How often a run looks for finished tasks while none is ready (Ctrl-C is seen then too)."""


def run_tasks(client: Any, function: Callable[..., Any], tasks: Sequence[tuple], *, shared: tuple = (),
              name: str = "implc", on_result: Callable[[Any], None] | None = None, threads: int = 1,
              no_workers_seconds: float = NO_WORKERS_SECONDS) -> list[Any]:
    """``function(*shared, *task)`` for every task: on ``client``'s workers (None: here, ``threads`` at a time),
    results in the tasks' order; ``on_result`` sees each as it arrives. ``shared`` travels with every
    task (a recipe is text: small, and a worker that joins late needs nothing else). Ctrl-C or a
    failure cancels the tasks still queued before it propagates (one already running finishes: Dask
    cannot stop it); a cluster without workers for ``no_workers_seconds`` and a scheduler that goes away
    are each a ClusterError."""
    if client is None:
        return _run_here(function, tasks, shared, on_result, threads)
    results: list[Any] = [None] * len(tasks)
    distributed = _distributed()
    token = f"{name}-{time.time_ns():x}"
    futures = [client.submit(function, *shared, *task, key=f"{token}-{i}", pure=False)
               for i, task in enumerate(tasks)]
    index = {future.key: i for i, future in enumerate(futures)}
    pending = distributed.as_completed(futures)
    watch = _Watch(client, no_workers_seconds)
    try:
        while not pending.is_empty():
            for done in _finished(pending, watch):
                try:
                    result = done.result()
                except Exception as exc:
                    if type(exc).__name__ == "KilledWorker":  # Dask gave up on it: its workers kept dying
                        raise ClusterError(f"a task's workers died repeatedly (Dask's KilledWorker: "
                                           f"{printable(str(exc), 200)}); see the workers' logs") from None
                    if _lost_scheduler(exc):
                        raise ClusterError("the Dask scheduler went away during the run") from None
                    raise
                results[index[done.key]] = result
                if on_result is not None:
                    on_result(result)
    except BaseException:
        with contextlib.suppress(Exception):
            client.cancel(futures, force=True)
        raise
    return results


class _Watch:
    """Whether the cluster still has workers, asked at most once a second; ClusterError once it has had
    none for ``seconds``."""

    def __init__(self, client: Any, seconds: float):
        self.client, self.seconds = client, seconds
        self.none_since: float | None = None
        self.asked = 0.0

    def check(self) -> None:
        if time.monotonic() - self.asked < 1.0:
            return
        self.asked = time.monotonic()
        try:
            workers = self.client.scheduler_info().get("workers", {})
        except Exception:
            raise ClusterError("the Dask scheduler went away during the run") from None
        if workers:
            self.none_since = None
            return
        now = time.monotonic()
        self.none_since = now if self.none_since is None else self.none_since
        if now - self.none_since >= self.seconds:
            raise ClusterError(f"the cluster has had no workers for {self.seconds:.0f} s (they died, or none "
                               "joined); see the workers' logs")


def _finished(pending: Any, watch: _Watch) -> list[Any]:
    """The futures of ``pending`` (a distributed.as_completed) finished by now, at least one, checking the
    cluster while waiting for them."""
    while True:
        batch = pending.next_batch(block=False)
        if batch:
            return batch
        watch.check()
        time.sleep(POLL_SECONDS)


def _lost_scheduler(exc: BaseException) -> bool:
    """Whether ``exc`` says the scheduler (or the connection to it) is gone."""
    return type(exc).__name__ in ("FutureCancelledError", "CancelledError", "CommClosedError", "StreamClosedError")


def _run_here(function, tasks, shared, on_result, threads: int) -> list[Any]:
    """:func:`run_tasks` in this process: a pool of threads (the native work and Zarr's compression
    release the GIL). Ctrl-C drops the tasks not started and waits for the running ones (each short)."""
    results: list[Any] = [None] * len(tasks)
    with concurrent.futures.ThreadPoolExecutor(max(1, threads), thread_name_prefix="implc-task") as pool:
        futures = {pool.submit(function, *shared, *task): i for i, task in enumerate(tasks)}
        try:
            for future in concurrent.futures.as_completed(futures):
                results[futures[future]] = future.result()
                if on_result is not None:
                    on_result(results[futures[future]])
        except BaseException:
            pool.shutdown(wait=True, cancel_futures=True)
            raise
    return results


def plan_tasks(surface: Any, depth: int, level: int, *, solid: bool, options: dict) -> tuple[np.ndarray, np.ndarray]:
    """The octants at ``level`` that may meet the surface (the tasks) and the inside octants above them."""
    cells, inside = subdivider_for(surface, depth, solid=solid, options=options).cells_below((0, 0, 0), 0, level)
    return cells, inside if solid else np.empty((0, abi.INSIDE_WORDS), np.int32)


def _gather_task(recipe: SurfaceRecipe, depth: int, solid: bool, options: dict, level: int, cell) -> TaskVoxels:
    return task_voxels(build(recipe), depth, cell, level, solid=solid, options=options)


def gather_voxels(client: Any, recipe: SurfaceRecipe, surface: Any, depth: int, *, solid: bool, options: dict,
                  progress: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, SubdivisionStats]:
    """Every voxel (and a solid's inside octants) found on ``client``'s workers, gathered here in Morton
    order: what :func:`implc.voxelize` returns with ``cluster=``."""
    t0 = time.perf_counter()
    level = task_level(depth, depth - 1)
    cells, plan_inside = plan_tasks(surface, depth, level, solid=solid, options=options)
    threads = worker_threads(client)
    with task_progress(progress, len(cells), f"voxelize {1 << depth}³ on the cluster") as advance:
        parts = run_tasks(client, _gather_task, [(level, tuple(map(int, c))) for c in cells],
                          shared=(recipe, depth, solid, options), name="implc-voxelize",
                          on_result=lambda r: advance(len(r.coords)))
    stats = run_stats(depth, threads, time.perf_counter() - t0,
                      ((p.evaluations, p.tightened, p.seconds) for p in parts))
    stats.task_level, stats.tasks = level, len(cells)
    coords = np.concatenate([p.coords for p in parts]) if parts else np.empty((0, 3), np.uint32)
    normals = np.concatenate([p.normals for p in parts]) if parts else np.empty((0, 3), np.float32)
    inside = np.concatenate([plan_inside] + [p.inside for p in parts]) if solid else None
    return coords, normals, inside, stats


@contextlib.contextmanager
def task_progress(progress: bool, total: int, desc: str) -> Iterator[Callable[[int], None]]:
    """``advance(voxels)`` for each finished task: a progress bar of tasks with the voxels so far and
    their rate (with ``progress``; otherwise it does nothing), closed after the block."""
    if not progress:
        yield lambda voxels: None
        return
    from tqdm import tqdm
    bar = tqdm(total=total, unit="task", desc=desc, leave=False)
    started, found = time.perf_counter(), [0]

    def advance(voxels: int) -> None:
        found[0] += voxels
        rate = found[0] / max(time.perf_counter() - started, 1e-9)
        bar.set_postfix_str(f"{found[0]:,} voxels, {rate / 1e6:.1f} M/s", refresh=False)
        bar.update(1)

    try:
        yield advance
    finally:
        bar.close()
