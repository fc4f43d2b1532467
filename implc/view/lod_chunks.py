"""Levels of detail for viewing: the octree cut into chunks that a viewer fetches by id, coarse first.

Chunk (L, i, j, k) is the octree node at level L with those coordinates; it holds the surface's nodes
:data:`CHUNK_LEVELS` levels below it (its *point level* m = min(L + CHUNK_LEVELS, depth)), each with the
mean normal of the voxels below it, as :meth:`implc.voxelizer.storage.octree.Octree.level` computes. A chunk's
children (L + 1, 2i + a, 2j + b, 2k + c) hold the same surface at twice the resolution, so a viewer shows
a cut of the chunk tree and replaces a chunk by its children where the camera needs more detail. Chunks
exist from level 0 to ``depth − CHUNK_LEVELS`` (the last ones hold the voxels themselves).

A chunk's bytes (little-endian): a 64-byte header of uint32 (magic, format, L, i, j, k, m, point count,
then the point counts of its eight children, 0 where a child holds no surface), then each point's cell
within the chunk (3 × uint8: coordinates at level m minus the chunk's first cell there, below 2^6), then
each point's normal octahedron-encoded in 2 × uint8.

For a cut-away, :meth:`LodChunks.section` gives the cells of one layer (a plane across an axis) at a
point level: the boundary nodes there and, for a solid, every cell of the inside octants crossing it (as
:func:`implc.view.render.cross_section` at that level): a 32-byte header of uint32 (section magic, format,
axis, layer index, level, cell count, 0, 0), then the two other coordinates of each cell as uint32.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from ..engines.morton import morton_codes
from .json_text import json_bytes
from .render import cross_section

CHUNK_LEVELS = 6
"""Levels from a chunk to its points: at most 64³ cells per chunk; a surface puts a few thousand there."""
MAGIC = 0x43504D49  # "IMPC"
SECTION_MAGIC = 0x53504D49  # "IMPS"
FORMAT = 1
HEADER_BYTES = 64


def encode_normals(normals: np.ndarray) -> np.ndarray:
    """Octahedral encoding of (n, 3) vectors (any length; zero gives +z) as (n, 2) uint8."""
    n = np.asarray(normals, dtype=np.float32)
    length = np.abs(n).sum(axis=1)
    inverse = np.divide(1, length, out=np.zeros_like(length), where=length > 0)
    x, y = n[:, 0] * inverse, n[:, 1] * inverse
    below = n[:, 2] < 0  # the lower half folds over the diagonals
    folded_x = np.where(below, np.copysign(1 - np.abs(y), x), x)
    folded_y = np.where(below, np.copysign(1 - np.abs(x), y), y)
    out = np.empty((len(n), 2), dtype=np.uint8)
    out[:, 0] = np.clip(np.rint(folded_x * 127.5 + 127.5), 0, 255)
    out[:, 1] = np.clip(np.rint(folded_y * 127.5 + 127.5), 0, 255)
    return out


def decode_normals(encoded: np.ndarray) -> np.ndarray:
    """The inverse of :func:`encode_normals` (unit vectors), as the viewer's shader computes it."""
    f = encoded.astype(np.float64) / 255 * 2 - 1
    n = np.column_stack([f, 1 - np.abs(f[:, 0]) - np.abs(f[:, 1])])
    t = np.maximum(-n[:, 2], 0)
    n[:, 0] += np.where(n[:, 0] >= 0, -t, t)
    n[:, 1] += np.where(n[:, 1] >= 0, -t, t)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


class LodChunks:
    """The chunks of one voxelization (anything with Morton-ordered ``coords``, ``normals``, ``depth``,
    ``bounds``): a pyramid of levels (Morton codes, cells, sums of normals) computed once, chunks cut
    from it on request."""

    def __init__(self, voxels, name: str = "", view: tuple[float, float] | None = None):
        """``view``: the camera's (azimuth, elevation) in degrees, as implc render's (default 35, 25)."""
        self.depth, self.bounds, self.name = int(voxels.depth), voxels.bounds, name
        self.view = tuple(map(float, view)) if view is not None else (35.0, 25.0)
        self.voxels = len(voxels.coords)
        self.max_chunk_level = max(self.depth - CHUNK_LEVELS, 0)
        first_level = min(CHUNK_LEVELS, self.depth)
        coords = np.asarray(voxels.coords, dtype=np.uint32)
        sums = np.asarray(voxels.normals, dtype=np.float32)
        codes = morton_codes(coords)
        if len(codes) and np.any(codes[1:] < codes[:-1]):  # voxels from elsewhere: put them in order
            order = np.argsort(codes, kind="stable")
            codes, coords, sums = codes[order], coords[order], sums[order]
        self.levels: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        for level in range(self.depth, first_level - 1, -1):
            if level < self.depth:  # the parents of the level below (a Morton code shifted by 3), their normal sums
                parents = codes >> np.uint64(3)
                starts = np.flatnonzero(np.r_[True, parents[1:] != parents[:-1]]) if len(parents) else \
                    np.empty(0, np.int64)
                codes, coords = parents[starts], coords[starts] >> np.uint32(1)
                sums = np.add.reduceat(sums, starts, axis=0) if len(starts) else sums[:0]
            self.levels[level] = (codes, coords, sums)  # normals encoded per chunk, when asked for
        self.solid = getattr(voxels, "inside", None) is not None
        self.inside = np.empty((0, 4), np.int64)  # the octree's inside entries as rows (i, j, k, level)
        if self.solid:
            levels, cells = voxels.octree.inside_nodes()
            self.inside = np.column_stack([cells.astype(np.int64), levels.astype(np.int64)])

    def point_level(self, level: int) -> int:
        return min(level + CHUNK_LEVELS, self.depth)

    def _range(self, level: int, cell, point_level: int) -> tuple[int, int]:
        keys = self.levels[point_level][0]
        shift = np.uint64(3 * (point_level - level))
        code = morton_codes(np.array([cell], dtype=np.int64))[0]
        lo, hi = code << shift, (code + np.uint64(1)) << shift
        first, last = np.searchsorted(keys, np.array([lo, hi], dtype=np.uint64))
        return int(first), int(last)

    def count(self, level: int, cell) -> int:
        if not 0 <= level <= self.max_chunk_level or any(not 0 <= c < (1 << level) for c in cell):
            return 0
        a, b = self._range(level, cell, self.point_level(level))
        return b - a

    def chunk(self, level: int, i: int, j: int, k: int) -> bytes | None:
        """The bytes of chunk (level, i, j, k), or None where it does not exist (no surface there, or
        outside the chunk tree)."""
        cell = (int(i), int(j), int(k))
        if not 0 <= level <= self.max_chunk_level or any(not 0 <= c < (1 << level) for c in cell):
            return None
        m = self.point_level(level)
        a, b = self._range(level, cell, m)
        if b == a and level > 0:
            return None
        _, coords, sums = self.levels[m]
        local = (coords[a:b] - (np.array(cell, dtype=np.uint32) << np.uint32(m - level))).astype(np.uint8)
        children = [self.count(level + 1, (2 * cell[0] + (c & 1), 2 * cell[1] + (c >> 1 & 1), 2 * cell[2] + (c >> 2)))
                    for c in range(8)] if level < self.max_chunk_level else [0] * 8
        header = np.zeros(HEADER_BYTES // 4, dtype=np.uint32)
        header[:8] = (MAGIC, FORMAT, level, *cell, m, b - a)
        header[8:16] = children
        return header.tobytes() + local.tobytes() + encode_normals(sums[a:b]).tobytes()

    def section(self, axis: int, index: int, level: int) -> bytes | None:
        """Layer ``index`` across ``axis`` at point level ``level`` (see the module's docstring), or None
        where there is no such layer."""
        if axis not in (0, 1, 2) or level not in self.levels or not 0 <= index < (1 << level):
            return None
        layer = SimpleNamespace(coords=self.levels[level][1], depth=level,
                                inside=self.inside[self.inside[:, 3] <= level] if self.solid else None)
        cells = cross_section(layer, axis, index)
        header = np.zeros(8, dtype=np.uint32)
        header[:6] = (SECTION_MAGIC, FORMAT, axis, index, level, len(cells))
        return header.tobytes() + np.ascontiguousarray(cells[:, [a for a in range(3) if a != axis]]).tobytes()

    def chunk_ids(self, max_bytes: int | None = None):
        """Every chunk id (level, i, j, k), coarse levels first (Morton order within a level), stopping
        before ``max_bytes`` of chunks would be passed (for an embedded, self-contained viewer)."""
        total = 0
        for level in range(self.max_chunk_level + 1):
            m = self.point_level(level)
            keys, coords, _ = self.levels[m]
            if len(coords):  # the distinct chunks, in Morton order (one sort of codes, not of rows)
                shifted = coords >> np.uint32(m - level)
                cells = shifted[np.unique(morton_codes(shifted), return_index=True)[1]]
            else:
                cells = np.zeros((1, 3), np.uint32)
            level_bytes = HEADER_BYTES * len(cells) + 5 * len(keys)
            if max_bytes is not None and total + level_bytes > max_bytes and level > 0:
                return
            total += level_bytes
            for cell in cells:
                yield (level, *map(int, cell))

    def meta(self, budget: int = 1_000_000) -> dict:
        """What the viewer needs before its first chunk; ``budget``: points it draws at most per frame."""
        return {"format": FORMAT, "name": self.name, "depth": self.depth,
                "bounds": [list(map(float, b)) for b in self.bounds], "chunk_levels": CHUNK_LEVELS,
                "max_chunk_level": self.max_chunk_level, "voxels": self.voxels, "view": list(self.view),
                "budget": int(budget), "solid": self.solid, "first_level": min(self.levels)}

    def meta_json(self, budget: int = 1_000_000) -> bytes:
        return json_bytes(self.meta(budget))
