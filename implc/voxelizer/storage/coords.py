"""The coordinate-list backend: the voxels themselves, concatenated in Morton order."""

from __future__ import annotations

import numpy as np


class CoordinateList:
    def begin(self, depth, bounds):
        self.depth, self.bounds = depth, bounds
        self._coords, self._normals = [], []

    def add(self, coords, normals):
        self._coords.append(coords)
        self._normals.append(normals)

    def finish(self):
        coords = np.concatenate(self._coords) if self._coords else np.zeros((0, 3), np.uint32)
        normals = np.concatenate(self._normals) if self._normals else np.zeros((0, 3), np.float32)
        self._coords = self._normals = None
        return coords, normals
