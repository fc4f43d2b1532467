"""The voxelizer's big buffers (task outputs, the collected voxels, the octree's nodes): numpy arrays
over anonymous memory mappings, so that the page size is this module's choice rather than numpy's.

numpy advises the kernel to back every array over 4 MiB with transparent huge pages. Where the kernel
answers that advice by compacting memory on the first touch (``/sys/kernel/mm/transparent_hugepage/defrag``
set to ``madvise``, the kernel's default), the first touch of each 2 MiB page can stall far longer than
512 small page faults, and fine grids spent more system time than they saved (``implc bench --sections
scale`` measures it). So these arrays carry no advice (small pages unless huge pages are
'always'); ``IMPLC_HUGE_PAGES=1`` in the environment advises huge pages instead, to compare.
Untouched pages of a mapping cost nothing, so a generous capacity is free until written.
"""

from __future__ import annotations

import mmap
import os

import numpy as np


def huge_pages() -> bool:
    """Whether the big buffers ask for huge pages (``IMPLC_HUGE_PAGES=1``)."""
    return os.environ.get("IMPLC_HUGE_PAGES", "") == "1"


def empty(shape, dtype) -> np.ndarray:
    """An uninitialised array (zero-filled in fact: fresh anonymous pages) of ``shape`` and ``dtype``."""
    shape = (shape,) if isinstance(shape, (int, np.integer)) else tuple(shape)
    dtype = np.dtype(dtype)
    nbytes = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
    if nbytes < (1 << 20):  # small: numpy's allocator (no advice below 4 MiB anyway)
        return np.empty(shape, dtype)
    buffer = mmap.mmap(-1, nbytes, flags=mmap.MAP_PRIVATE | mmap.MAP_ANONYMOUS)
    if huge_pages() and hasattr(mmap, "MADV_HUGEPAGE"):
        buffer.madvise(mmap.MADV_HUGEPAGE)
    return np.frombuffer(buffer, dtype=dtype, count=int(np.prod(shape, dtype=np.int64))).reshape(shape)


def grown(array: np.ndarray, rows: int, used: int) -> np.ndarray:
    """A new array of ``rows`` rows like ``array`` holding its first ``used`` rows."""
    out = empty((rows, *array.shape[1:]), array.dtype)
    out[:used] = array[:used]
    return out
