"""Storage backends: where the voxels go, behind one small interface.

The voxelizer calls ``begin(depth, bounds)``, then ``add(coords, normals)`` with batches in Morton
order ((n, 3) uint32 cell indices and (n, 3) float32 unit normals), then ``finish()``, whose result
becomes ``Voxels.storage``. A backend may also offer ``reserve(voxels)``, called after ``begin`` with
the voxelizer's estimate of the voxel count. Any object with these three methods is a backend; a plain callable
``fn(coords, normals)`` is wrapped as one that streams each batch to it.
"""

from __future__ import annotations

from .coords import CoordinateList
from .dense import DenseGrid
from .octree import Octree, OctreeBuilder

BACKENDS = {"octree": OctreeBuilder, "grid": DenseGrid, "coords": CoordinateList}


class CallbackStorage:
    """Hands every batch to ``fn(coords, normals)`` as it arrives."""

    def __init__(self, fn):
        self.fn = fn

    def begin(self, depth, bounds):
        pass

    def add(self, coords, normals):
        self.fn(coords, normals)

    def finish(self):
        return None


def make_backend(storage):
    """A backend from a name ("octree", "grid", "coords"), a backend object or a callable."""
    if isinstance(storage, str):
        try:
            return BACKENDS[storage]()
        except KeyError:
            raise ValueError(f"unknown storage {storage!r}: use one of {', '.join(BACKENDS)}, "
                             "a backend object (begin/add/finish) or a callable") from None
    if all(hasattr(storage, m) for m in ("begin", "add", "finish")):
        return storage
    if callable(storage):
        return CallbackStorage(storage)
    raise ValueError(f"storage must be a name ({', '.join(BACKENDS)}), a backend object or a callable, "
                     f"got {type(storage).__name__}")


def bytes_per_voxel(storage) -> float:
    """A planning figure for the memory estimate (voxel arrays kept by Voxels included). The default
    octree: 12 bytes of float32 normal and about 10 of nodes per voxel kept, and the tasks' buffers
    while they run, rounded up from the peak that ``implc bench --sections scale`` measures."""
    return {"octree": 32, "coords": 24}.get(storage, 24) if isinstance(storage, str) else 24


__all__ = [
    "BACKENDS",
    "CallbackStorage",
    "CoordinateList",
    "DenseGrid",
    "Octree",
    "OctreeBuilder",
    "bytes_per_voxel",
    "make_backend",
]
