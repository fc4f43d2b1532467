"""Jobs run at once in forked processes: llvmlite admits one thread into LLVM at a time, so the parts of a
first compile (:mod:`implc.native.jit`) spread over processes instead.

The calling process runs its share of the jobs while each forked worker runs another share and writes its
results back through a pipe. Workers are forked only where that is safe and useful: on Linux, from a
process with one Python thread (a fork copies only the calling thread, and a lock another thread holds
would stay held in the copy), with more than one CPU available. A worker that fails, is killed or writes
a short answer costs only time: its jobs then run in the calling process. Interrupting the caller kills
the workers.
"""

from __future__ import annotations

import os
import struct
import sys
import threading
from collections.abc import Callable, Sequence

MAX_WORKERS = 4
"""Processes at most (the caller included): a first compile has about four parts worth their start."""

_LENGTH = struct.Struct("<Q")


def workers() -> int:
    """How many processes :func:`run` would use for many jobs here and now (1: the caller alone)."""
    if sys.platform != "linux" or threading.active_count() != 1:
        return 1
    return max(1, min(MAX_WORKERS, len(os.sched_getaffinity(0))))


def _share(jobs: int, weights: Sequence[float], count: int) -> list[list[int]]:
    """The jobs' indices in ``count`` shares, balanced by weight (the heaviest placed first); share 0 is
    the caller's and gets the lightest load."""
    shares: list[list[int]] = [[] for _ in range(count)]
    load = [0.0] * count
    for j in sorted(range(jobs), key=lambda j: -weights[j]):
        k = min(range(count), key=lambda k: (load[k], -k))  # ties: a worker before the caller
        shares[k].append(j)
        load[k] += weights[j]
    return shares


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]


def _read_all(fd: int) -> bytes:
    chunks = []
    while chunk := os.read(fd, 1 << 20):
        chunks.append(chunk)
    return b"".join(chunks)


def _answers(data: bytes, count: int) -> list[bytes] | None:
    """The ``count`` results a worker wrote (each its length then its bytes), or None when it wrote fewer."""
    out, at = [], 0
    for _ in range(count):
        if at + _LENGTH.size > len(data):
            return None
        (length,), at = _LENGTH.unpack_from(data, at), at + _LENGTH.size
        if at + length > len(data):
            return None
        out.append(data[at:at + length])
        at += length
    return out


def run(job: Callable[[int], bytes], count: int, weights: Sequence[float]) -> list[bytes]:
    """``[job(0), ..., job(count - 1)]``, the jobs spread over up to :func:`workers` processes by ``weights``
    (their expected costs); ``job`` must give the same answer in any process."""
    if count == 0:
        return []
    processes = min(workers(), count)
    shares = _share(count, weights, processes)
    children: list[tuple[int, int, list[int]]] = []  # (pid, read end, jobs)
    here = list(shares[0])
    try:
        for share in shares[1:]:
            if not share:
                continue
            read_end, write_end = os.pipe()
            try:
                pid = os.fork()
            except OSError:  # no process to be had: this one runs those jobs
                os.close(read_end)
                os.close(write_end)
                here += share
                continue
            if pid == 0:  # the worker: its jobs, then out without running the caller's exit handlers
                status = 1
                try:
                    os.close(read_end)
                    for j in share:
                        result = job(j)
                        _write_all(write_end, _LENGTH.pack(len(result)) + result)
                    status = 0
                finally:
                    os._exit(status)
            os.close(write_end)
            children.append((pid, read_end, share))
        results: dict[int, bytes] = {j: job(j) for j in here}
        while children:
            pid, read_end, share = children[0]
            answers = _answers(_read_all(read_end), len(share))
            _, status = os.waitpid(pid, 0)
            children.pop(0)
            os.close(read_end)
            if answers is None or status != 0:
                answers = [job(j) for j in share]  # the worker failed: its jobs run here
            results.update(zip(share, answers))
        return [results[j] for j in range(count)]
    finally:
        for pid, read_end, _ in children:  # interrupted: the workers not yet waited for go too
            os.kill(pid, 9)
            os.waitpid(pid, 0)
            os.close(read_end)
