"""The dense-grid backend: an occupancy array and a normal per cell, indexed [i, j, k]."""

from __future__ import annotations

import numpy as np


def dense_bytes(depth: int) -> int:
    """Memory of a dense grid at ``depth``: one bool and three float32 per cell."""
    return (1 << (3 * depth)) * 13


class DenseGrid:
    def begin(self, depth, bounds):
        n = 1 << depth
        self.depth, self.bounds = depth, bounds
        self.occupancy = np.zeros((n, n, n), dtype=bool)
        self.normals = np.zeros((n, n, n, 3), dtype=np.float32)

    def add(self, coords, normals):
        i, j, k = coords[:, 0], coords[:, 1], coords[:, 2]
        self.occupancy[i, j, k] = True
        self.normals[i, j, k] = normals

    def finish(self):
        return self
