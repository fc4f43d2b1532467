"""Morton codes: the voxelizer's order (child octant c = x bit | y bit << 1 | z bit << 2, depth first) as
numbers, for cells of a grid of depth up to 21."""

from __future__ import annotations

import numpy as np


def _spread(v: np.ndarray) -> np.ndarray:
    """The bits of ``v`` (< 2^21) moved to every third bit."""
    v = v.astype(np.uint64) & np.uint64(0x1FFFFF)
    for shift, mask in ((32, 0x1F00000000FFFF), (16, 0x1F0000FF0000FF), (8, 0x100F00F00F00F00F),
                        (4, 0x10C30C30C30C30C3), (2, 0x1249249249249249)):
        v = (v | (v << np.uint64(shift))) & np.uint64(mask)
    return v


def morton_codes(cells: np.ndarray) -> np.ndarray:
    """(n,) uint64 codes of (n, 3) non-negative cell indices; sorting by them is the voxelizer's order."""
    cells = np.asarray(cells)
    return _spread(cells[:, 0]) | (_spread(cells[:, 1]) << np.uint64(1)) | (_spread(cells[:, 2]) << np.uint64(2))
