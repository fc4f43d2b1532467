"""Slice stacks: one 1-bit image per z layer of the voxels (the solid where the inside is classified), the
input of voxel 3D printers and of any tool that reads image stacks.

Layers are produced one after another from the voxels and the inside octants, never as a dense volume:
an octant of level L covers the same square in 2^(depth − L) consecutive layers, so each level keeps one
image at its own resolution and enlarges it only when the layer leaves its octants. Image pixel (row,
column) is cell (i = column, j = n − 1 − row) of the layer: x to the right, y up.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from ..voxelizer.voxelize import Voxels

FORMATS = {"png": ".png", "tiff": ".tif"}


def layers(voxels: Voxels) -> Iterator[tuple[int, np.ndarray]]:
    """Yield (z, image) for every z layer: ``image`` an (n, n) bool array as described above."""
    n = 1 << voxels.depth
    order = np.argsort(voxels.coords[:, 2], kind="stable")
    by_z = voxels.coords[order]
    starts = np.searchsorted(by_z[:, 2], np.arange(n + 1))
    inside = voxels.inside if voxels.inside is not None else np.empty((0, 4), dtype=np.int32)
    levels: dict[int, tuple[np.ndarray, np.ndarray, Any, int]] = {}  # rows, bounds, the cached layer, its k
    for level in np.unique(inside[:, 3]):
        rows = inside[inside[:, 3] == level]
        rows = rows[np.argsort(rows[:, 2], kind="stable")]
        bounds = np.searchsorted(rows[:, 2], np.arange((1 << int(level)) + 1))
        levels[int(level)] = (rows, bounds, None, -1)
    for z in range(n):
        image = np.zeros((n, n), dtype=bool)  # indexed [i, j] until the end
        for level, (rows, bounds, cached, cached_k) in levels.items():
            size = 1 << (voxels.depth - level)
            k = z // size
            if k != cached_k:  # the octants of this level covering layer z, enlarged to voxels
                coarse = np.zeros((1 << level, 1 << level), dtype=bool)
                here = rows[bounds[k]:bounds[k + 1]]
                coarse[here[:, 0], here[:, 1]] = True
                cached = np.repeat(np.repeat(coarse, size, axis=0), size, axis=1) if size > 1 else coarse
                levels[level] = (rows, bounds, cached, k)
            image |= cached
        cells = by_z[starts[z]:starts[z + 1]]
        image[cells[:, 0], cells[:, 1]] = True
        yield z, np.flipud(image.T)


def _is_slice_stack(folder: Path) -> bool:
    """Whether ``folder`` holds nothing but a slice stack (one written before outputs were marked)."""
    return all(re.fullmatch(r"layer_\d+\.(png|tif)", p.name) and p.is_file() for p in folder.iterdir())


def save_slices(voxels: Voxels, folder: str | os.PathLike[str], fmt: str = "png") -> Path:
    """Write ``folder/layer_00000.png`` ... (or ``.tif``), one 1-bit image per z layer, bottom first. The
    folder is written under a temporary name beside it and renamed into place: an interrupted save leaves
    no partial stack, and an existing folder is replaced only once the new one is complete."""
    from PIL import Image

    from ..common.atomic_file import replacing_folder
    if fmt not in FORMATS:
        raise ValueError(f"unknown slice format {fmt!r}: use {' or '.join(FORMATS)}")
    folder = Path(folder)
    with replacing_folder(folder, "slices", _is_slice_stack, marked=False) as tmp:
        digits = max(5, len(str((1 << voxels.depth) - 1)))
        options = {"compression": "group4"} if fmt == "tiff" else {"optimize": False}
        for z, image in layers(voxels):
            Image.fromarray(image).convert("1").save(tmp / f"layer_{z:0{digits}d}{FORMATS[fmt]}", **options)
    return folder
