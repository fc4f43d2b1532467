"""Worker threads for native calls that release the GIL: how many (:func:`threads`, the process's CPU
affinity), a pool kept per process, and how many rows each call takes so that every thread gets several."""

from __future__ import annotations

import contextlib
import os
import threading
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_EXCEPTION, ThreadPoolExecutor, wait
from contextvars import ContextVar
from typing import Any

import numpy as np

from .context import scoped

CHUNK = 1 << 16
"""The most rows per native call of the batched entry points (a multiple of every vector width)."""
MIN_CHUNK = 1 << 13
"""The fewest rows per native call of an entry point that costs a tenth of a microsecond a row or more
(enclosures, the tape engine's grouped samples), where there are more: below :data:`CHUNK` such rows are
shared out so that each thread gets several calls (:func:`chunk_rows`). F's samples on the compiled kernels
keep :data:`CHUNK`: handing a call to a thread costs more than such a call's rows
(``implc bench --sections mesh`` measures the mesher's batches)."""
CALLS_PER_CORE = 4
"""How many calls each thread gets where :data:`CHUNK` rows per call would give it fewer (several, so that
a thread that finishes first takes another's share: the rows' costs differ)."""


_THREADS: ContextVar[int | None] = ContextVar("implc_threads", default=None)
"""The threads :func:`in_parallel` may use in this context (None: one per core), set by :func:`threads`."""


@contextlib.contextmanager
def threads(count: int | None) -> Iterator[None]:
    """Within the block, the batched entry points run on at most ``count`` threads (None: one per usable
    core), e.g. a mesh contoured with ``workers=1`` (the calling thread alone)."""
    with scoped(_THREADS, count):
        yield


def thread_count() -> int:
    """The threads :func:`in_parallel` uses here: those :func:`threads` allows, or one per usable core."""
    count = _THREADS.get()
    return default_workers() if count is None else count


_POOLS: dict[tuple[int, int], ThreadPoolExecutor] = {}
"""The thread pools :func:`in_parallel` keeps, by (process, threads): starting a pool's threads on every call
costs as much as a batch of samples (a forked child starts its own)."""
_POOLS_LOCK = threading.Lock()


def _pool(workers: int) -> ThreadPoolExecutor:
    key = (os.getpid(), workers)
    with _POOLS_LOCK:
        pool = _POOLS.get(key)
        if pool is None:
            pool = _POOLS[key] = ThreadPoolExecutor(workers, thread_name_prefix="implc-eval")
        return pool


def in_parallel(jobs: list[Callable[[], None]]) -> None:
    """Run independent native calls (each releases the GIL) on :func:`thread_count` threads of a pool kept
    for the process (the jobs themselves on the calling thread where that is one); the first error (or
    Ctrl-C) cancels the jobs not started and is raised once those running finish (they write into the
    caller's arrays)."""
    workers = thread_count()
    if workers <= 1 or len(jobs) <= 1:
        for job in jobs:
            job()
        return
    pool = _pool(workers)  # one pool per count of threads: a batch of fewer jobs leaves some idle
    futures = [pool.submit(job) for job in jobs]
    try:
        done, _ = wait(futures, return_when=FIRST_EXCEPTION)
        for future in done:
            future.result()
    except BaseException:
        for future in futures:
            future.cancel()
        wait(futures)
        raise


_FEWEST: ContextVar[int] = ContextVar("implc_fewest_rows", default=MIN_CHUNK)
"""The fewest rows per call of a costly entry point in this context, set by :func:`fewest_rows`."""


@contextlib.contextmanager
def fewest_rows(count: int) -> Iterator[None]:
    """Within the block, a costly entry point's calls take at least ``count`` rows (:data:`MIN_CHUNK` outside
    one): smaller batches then still spread over the threads, as a test of the sharing needs."""
    with scoped(_FEWEST, count):
        yield


def chunk_rows(rows: int, width: int = 8, fewest: int | None = None) -> int:
    """Rows per native call for ``rows`` rows: :data:`CHUNK`, or fewer (down to ``fewest``, by default the
    context's :func:`fewest_rows`) so that every thread (:func:`thread_count`) gets :data:`CALLS_PER_CORE`
    calls (else the mesher's batches of a few tens of thousands of boxes or points run on one core); a
    multiple of ``width``. Each row's result is its own: the same whatever the rows per call."""
    share = -(-rows // (CALLS_PER_CORE * thread_count()))
    per_call = min(CHUNK, max(_FEWEST.get() if fewest is None else fewest, share))
    return -(-per_call // width) * width


def default_workers() -> int:
    """The cores this process may run on (its CPU affinity): the default count of worker threads."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - non-Linux
        return os.cpu_count() or 1


def max_workers() -> int:
    """The most worker threads a call may ask for: four per usable core, at least eight (more only queue
    for the cores, each with its buffers)."""
    return max(8, 4 * default_workers())


def check_workers(value: Any) -> int:
    """``value`` as a count of worker threads: a whole number from 1 to :func:`max_workers`; ValueError
    (one line) otherwise."""
    most = max_workers()
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 1 <= value <= most:
        raise ValueError(f"workers must be a whole number from 1 to {most} (four per usable core here), "
                         f"got {value!r}")
    return int(value)
