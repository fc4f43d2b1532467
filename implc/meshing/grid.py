"""The grid the contouring works on: cells and corners named by keys, F's samples at them (on the surface's
engine, a band at a time), the index of vertex keys, the cells it visits and the faces between them."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..engines.surface import Grouping
from .contour_native import CONTOURING
from .tables import (
    CELL_EDGE_PACKED,
    CORNERS,
    FAN_PACKED,
    GRID,
    KUHN_CHUNK,
    KUHN_NEW_KEYS,
    KUHN_PACKED,
    SQUARE,
    face_axes,
    square_edge,
)

GROUP_CELLS = 8
"""F is sampled in groups of this many cells per axis: on the tape engine each group runs the program
simplified over its box."""
GROUPED_PROGRAM = 128
"""The shortest tape-engine program sampled by groups: below it, sorting and gathering the points costs
more than the shorter per-group programs save, above it they gain (``benchmarks/against_revision.py --task
mesh`` on csg_part and colonnade)."""
VERTEX_CHUNK = 1 << 18
"""Surface vertices placed, or cells' corners sampled, at a time (:func:`surface_vertices`,
:func:`_corner_signs`): a big mesh's memory then follows the chunk, since fresh memory is what a big mesh
costs most (``benchmarks/against_revision.py --task implc.mesh`` measures the peak)."""
CORNERS_PER_CELL = 2
"""The distinct corners a band of cells has per cell, about (1.45 on bear, 1.9 on Scene 1, 2.2 on colonnade):
the size the corners' index starts with."""


@dataclass(frozen=True)
class Effort:
    """How the contouring spends its work and memory; the mesh's promises hold for every value (tests vary
    them). ``vertex_chunk``: :data:`VERTEX_CHUNK`; the proof of regular cells (:mod:`implc.meshing.proofs`):
    ``proof_levels`` below the grid, ``proof_yield`` the share a level must prove for the next to be tried,
    and the first level tried on every ``proof_sample``-th box first where there are ``proof_sample`` ×
    ``proof_sample_min`` boxes or more."""

    vertex_chunk: int = VERTEX_CHUNK
    proof_levels: int = 2
    proof_yield: float = 0.25
    proof_sample: int = 16
    proof_sample_min: int = 256


class Grid:
    """The 2^depth grid over the bounds: corner, cell and face keys, world positions, F's samples; ``effort``:
    how the work is chunked and how far the proofs look."""

    def __init__(self, surface, depth: int, bounds, effort: Effort = Effort()):
        self.effort = effort
        self.surface = surface
        surface.prepare_mesher(CONTOURING.source)
        self.runtime = surface.runtime.library(CONTOURING)  # the mesher's native routines
        self._corners: KeyIndex | None = None  # the corners sampled so far, and F there
        self._corner_values = np.zeros(0)
        self._faces: dict[tuple[int, int], np.ndarray] = {}  # (axis, side): F at the corners of that face of the bounds
        self.outside_faces: set[tuple[int, int]] = set()  # faces of the bounds proven outside: not sampled
        self.n = 1 << depth
        self.k = self.n + 1  # corners per axis
        self.lo = np.array([float(lo) for lo, _ in bounds])
        self.hi = np.array([float(hi) for _, hi in bounds])
        self.step = (self.hi - self.lo) / self.n
        self.groups_per_axis = max(1, self.n // GROUP_CELLS)
        self.geometry = np.concatenate([[self.k, self.n], self.lo, self.step, self.hi]).astype(np.float64)
        """The grid as the native corner routines read it: corners and cells per axis, lo, step, hi. Held
        here: an address taken from a temporary array points at freed memory, which the allocator may hand
        to someone else before the native routine reads it (meshes came out with spurious crease cells when
        their vertices were placed on two threads)."""
        # the compiled kernels have no use for groups, and a short program gains less than sorting costs
        self.grouped = surface.engine == "tape" and len(surface.program) >= GROUPED_PROGRAM

    def key(self, ijk: np.ndarray) -> np.ndarray:
        """Corner keys."""
        return (ijk[..., 0] * self.k + ijk[..., 1]) * self.k + ijk[..., 2]

    def unkey(self, key: np.ndarray) -> np.ndarray:
        return np.stack([key // (self.k * self.k), key // self.k % self.k, key % self.k], axis=-1)

    def cell_key(self, cells: np.ndarray) -> np.ndarray:
        return (cells[..., 0] * self.n + cells[..., 1]) * self.n + cells[..., 2]

    def cell_unkey(self, key: np.ndarray) -> np.ndarray:
        return np.stack([key // (self.n * self.n), key // self.n % self.n, key % self.n], axis=-1)

    def world(self, ijk: np.ndarray) -> np.ndarray:
        """World coordinates of corner indices (the last corner of an axis is its upper bound exactly)."""
        ijk = np.asarray(ijk)
        out = self.lo + ijk * self.step
        last = ijk == self.n
        if last.any():
            out[last] = np.broadcast_to(self.hi, out.shape)[last]
        return out

    def values(self, points: np.ndarray, grouping: Grouping | None = None) -> np.ndarray:
        """F at points (:meth:`implc.Surface.eval` with ``fast``: the vector elementary functions, as the
        voxelizer samples); on the tape engine, for a long program, each point's program simplified over
        its group of cells (:meth:`implc.Surface.eval_grouped`; ``grouping``: the points' :meth:`grouping`,
        where several calls share it), and NaN where F is not finite (outside, as where its interval
        engine finds F may be undefined)."""
        points = np.ascontiguousarray(points.reshape(-1, 3), dtype=np.float64)
        if self.grouped:
            values = self.surface.eval_grouped(points, grouping or self.grouping(points))[0]
        else:
            values = self.surface.eval(points, fast=True)
        if self.surface.engine == "tape":
            values[~np.isfinite(values)] = np.nan
        return values

    def gradients(self, points: np.ndarray, grouping: Grouping | None = None) -> np.ndarray:
        """F's analytic gradient at points, as :meth:`values` groups them."""
        return self.values_and_gradients(points, grouping)[1]

    def values_and_gradients(self, points: np.ndarray, grouping: Grouping | None = None):
        """(F, its analytic gradient) at points in one pass, as :meth:`values` groups them (F NaN where it
        is not finite on the tape engine, as there)."""
        points = np.ascontiguousarray(points.reshape(-1, 3), dtype=np.float64)
        if not self.grouped:
            values, gradients = self.surface.value_and_gradient(points, fast=True)
        else:
            values, gradients = self.surface.eval_grouped(points, grouping or self.grouping(points), gradient=True)
        if self.surface.engine == "tape":
            values[~np.isfinite(values)] = np.nan
        return values, gradients

    def grouping(self, points: np.ndarray) -> Grouping | None:
        """The points sorted by :meth:`groups` for the tape engine (None where :attr:`grouped` is not set):
        it holds for any points each no further than a cell from the point it was made from, in every
        axis (a surface vertex moving along its edge)."""
        return Grouping(self.groups(points), self.group_boxes) if self.grouped else None

    def groups(self, points: np.ndarray) -> np.ndarray:
        """The group of :data:`GROUP_CELLS`³ cells each point lies in (by its coordinates: a point on a
        group's face may go to either side, and every group's box reaches a cell beyond its cells)."""
        m = self.groups_per_axis
        scale = 1.0 / (self.step * GROUP_CELLS)
        label = np.zeros(len(points), np.int64)
        for a in range(3):  # axis by axis: (N, 3) temporaries cost several times more
            g = (points[:, a] - self.lo[a]) * scale[a]
            np.clip(g, 0, m - 1, out=g)  # and truncated below: the floor of what is not negative
            label *= m
            label += g.astype(np.int64)
        return label

    def group_boxes(self, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The boxes of groups: their cells and one more cell all round, within the bounds."""
        m = self.groups_per_axis
        g = np.stack([labels // (m * m), labels // m % m, labels % m], axis=-1)
        lo = np.maximum(self.lo + (g * GROUP_CELLS - 1) * self.step, self.lo)
        hi = np.minimum(self.lo + ((g + 1) * GROUP_CELLS + 1) * self.step, self.hi)
        return lo, hi

    def corner_points(self, keys: np.ndarray) -> np.ndarray:
        """World coordinates of corner keys (native: ``implc_corner_points``)."""
        keys = np.ascontiguousarray(keys, dtype=np.int64)
        points = np.empty((len(keys), 3))
        self.runtime.corner_points(keys.ctypes.data, len(keys), self.geometry.ctypes.data, points.ctypes.data)
        return points

    def expect_corners(self, count: int):
        """Size the corners' index for ``count`` corners (the cells' and the caps' faces', :meth:`capped_faces`),
        before any is sampled: growing it rehashes every key."""
        self._corner_index(count)

    def _corner_index(self, expected: int) -> KeyIndex:
        if self._corners is None:
            self._corners = KeyIndex(self.runtime, max(1 << 16, expected))
        return self._corners

    def corner_values(self, keys: np.ndarray, expected: int | None = None) -> np.ndarray:
        """F at the corners ``keys``, each sampled once for the whole contouring (and remembered);
        ``expected``: how many corners the contouring will sample in all, where known (the index's size)."""
        index = self._corner_index(expected or keys.size // 6)  # a band of cells: one to two corners per cell
        before = index.count
        numbers = index.number(keys)
        self._sample_since(index, before)
        return self._corner_values[numbers]

    def _sample_since(self, index: KeyIndex, before: int):
        """Sample F at the corners numbered from ``before`` on, and keep it with the others."""
        if index.count > before:
            fresh = self.values(self.corner_points(index.keys()[before:]))
            self._corner_values = np.ascontiguousarray(np.concatenate([self._corner_values, fresh]), dtype=np.float64)

    def corner_signs(self, cells: np.ndarray, expected: int) -> np.ndarray:
        """Per cell a byte, bit c set where F < 0 at its corner c (NaN counts as outside): each distinct
        corner sampled once for the whole contouring (and remembered), numbered and read natively
        (``implc_cell_corners``, ``implc_corner_signs``); ``expected``: how many corners the contouring will
        sample in all (the index's size)."""
        index = self._corner_index(expected)
        before = index.count
        numbers = index.cell_corners(self.key(cells), self.key(CORNERS))
        self._sample_since(index, before)
        signs = np.empty(len(cells), np.uint8)
        self.runtime.corner_signs(numbers.ctypes.data, len(cells), self._corner_values.ctypes.data, signs.ctypes.data)
        return signs

    def face_keys(self, axis: int, side: int) -> np.ndarray:
        """The corner keys of a face of the bounds, (n + 1, n + 1) in the order of its two other axes."""
        b, c = face_axes(axis)
        corners = np.zeros((self.k, self.k, 3), np.int64)
        corners[..., axis] = side * self.n
        corners[..., b], corners[..., c] = np.meshgrid(np.arange(self.k), np.arange(self.k), indexing="ij")
        return self.key(corners)

    def capped_faces(self) -> int:
        """How many faces of the bounds not taken as outside have a corner where F < 0 (sampled here, once):
        their corners enter the corners' index with the caps."""
        faces = [(axis, side) for axis in range(3) for side in (0, 1) if (axis, side) not in self.outside_faces]
        return sum(bool(np.any(self.face_values(*face, self.face_keys(*face)) < 0)) for face in faces)

    def face_values(self, axis: int, side: int, keys: np.ndarray) -> np.ndarray:
        """F at the corners ``keys`` of a face of the bounds, sampled once (and remembered by the face): most
        faces are outside the solid everywhere, and their corners never enter the corner index."""
        if (axis, side) not in self._faces:
            self._faces[axis, side] = self.values(self.corner_points(keys.reshape(-1))).reshape(keys.shape)
        return self._faces[axis, side]

    def find_outside_faces(self, cells: np.ndarray):
        """The faces of the bounds that none of the voxelizer's ``cells`` touches and where F > 0 at the
        centre: F > 0 all over them, so they hold no cap and are not sampled (:attr:`outside_faces`). Every
        cell not kept has an enclosure that excludes 0: F keeps one sign over the whole cell, and cells
        that share a point share it, so F keeps one sign over a face no kept cell touches."""
        for axis in range(3):
            for side in (0, 1):
                if np.any(cells[:, axis] == side * (self.n - 1)):
                    continue
                centre = (self.lo + self.hi) / 2
                centre[axis] = (self.lo, self.hi)[side][axis]
                if self.values(centre[None])[0] > 0:
                    self.outside_faces.add((axis, side))

    def forget_samples(self):
        """Let the corners' index and F's samples there go (the mesh's vertices are placed)."""
        self._corners, self._corner_values = None, np.zeros(0)

    def touched(self, cells: np.ndarray) -> bool:
        """Whether some of ``cells`` (added by the samples' signs) touch a face taken as outside: that face
        is sampled after all (taken out of :attr:`outside_faces`), and its caps must be made again."""
        touched = {(axis, side) for axis, side in self.outside_faces
                   if np.any(cells[:, axis] == side * (self.n - 1))}
        self.outside_faces -= touched
        return bool(touched)

    def remember(self, keys: np.ndarray, values: np.ndarray):
        """Keep F's ``values`` sampled at the corners ``keys`` (those not sampled yet)."""
        index = self._corner_index(keys.size)
        before = index.count
        numbers = index.number(keys)
        fresh = np.empty(index.count - before)
        new = numbers >= before
        fresh[numbers[new] - before] = values[new]
        self._corner_values = np.concatenate([self._corner_values, fresh])

    def edge_ends(self, keys: np.ndarray):
        """For vertex keys of grid edges: the edges' corners in world coordinates and F there, (a, b, fa, fb),
        from the corners sampled so far (native: ``implc_edge_ends``): every such corner is a corner of a
        cell contoured, a cap's included."""
        keys = np.ascontiguousarray(keys, dtype=np.int64)
        a, b = np.empty((len(keys), 3)), np.empty((len(keys), 3))
        fa, fb = np.empty(len(keys)), np.empty(len(keys))
        if not len(keys):
            return a, b, fa, fb
        index = self._corners
        if index is None:
            raise AssertionError("edge ends looked up before any corner was sampled")
        missing = self.runtime.edge_ends(keys.ctypes.data, len(keys), self.geometry.ctypes.data,
                                         index.table.ctypes.data, index.bits, self._corner_values.ctypes.data,
                                         a.ctypes.data, b.ctypes.data, fa.ctypes.data, fb.ctypes.data)
        if missing:
            raise AssertionError(f"{missing} corners of surface vertices' edges were never sampled")
        return a, b, fa, fb


class Points:
    """Points added to the tetrahedralization (cell points or face points): sorted ids, positions, F there."""

    def __init__(self, grid: Grid | None, ids: np.ndarray, positions: np.ndarray):
        order = np.argsort(ids, kind="stable")
        self.ids, self.positions = ids[order], positions[order]
        self.values = grid.values(self.positions) if grid is not None and len(ids) else np.zeros(0)  # None: empty
        self.inside = self.values < 0

    def find(self, ids: np.ndarray) -> np.ndarray:
        """The rows of ``ids`` (each must be present)."""
        rows = np.searchsorted(self.ids, ids)
        if len(ids) and (rows.max() >= len(self.ids) or np.any(self.ids[rows] != ids)):
            raise AssertionError("a face or cell point that was not placed")
        return rows


def both_signs(flags: np.ndarray) -> np.ndarray:
    """Rows of sign flags (one row per cell, face or square) that hold both signs: the surface crosses it."""
    return np.asarray(flags.any(1) & ~flags.all(1))


def grid_edge_key(corner_keys, code):
    return (corner_keys * 8 + code) * 8 + GRID


class Cells:
    """The cells being contoured: their indices, where F < 0 at their corners (a byte per cell, bit c for
    corner c), and an index of their keys (numbered by row)."""

    def __init__(self, grid: Grid, cells: np.ndarray):
        self.grid = grid
        self.cells = np.zeros((0, 3), np.int64)
        self.signs = np.zeros(0, np.uint8)
        self.index = KeyIndex(grid.runtime, len(cells) + len(cells) // 8 + 1024)  # room for the cells added
        self.add(cells)

    def add(self, more: np.ndarray) -> int:
        """Append the cells of ``more`` not yet here (their corners sampled), in the order of their keys;
        returns how many."""
        return self.add_keys(self.grid.cell_key(more))

    def add_keys(self, keys: np.ndarray) -> int:
        """:meth:`add` for the cells' keys (row r of :attr:`cells` has the index's key r)."""
        if self.index.count:  # most are here already (the neighbours close() proposes): only the others sorted
            keys = keys[self.index.number(keys, insert=False) < 0]
        before = self.index.count
        # the values sorted (any sort gives the same array): numpy's default sort takes the voxelizer's cells,
        # in octree order, several times faster than its merge sort
        self.index.number(np.sort(keys))
        fresh = self.index.keys()[before:]
        if not len(fresh):
            return 0
        cells = self.grid.cell_unkey(fresh)
        self.cells = np.concatenate([self.cells, cells])
        self.signs = np.concatenate([self.signs, _corner_signs(self.grid, cells)])
        return len(fresh)

    def close(self, seeds: np.ndarray, start: int = 0) -> int:
        """Add the ``seeds`` and every cell that the surface of the sampled signs enters across a face from
        a cell here (from row ``start`` on: the earlier ones are closed already), until none is missing;
        returns how many were added."""
        added = self.add(seeds)
        n = self.grid.n
        while True:
            signs = self.signs[start:]
            keys = self.index.keys()[start:]  # the rows' own keys
            candidates = []
            for axis in range(3):
                stride = n ** (2 - axis)  # a cell key's step along the axis
                coordinate = self.cells[start:, axis]
                for side in (0, 1):
                    face = np.uint8(sum(1 << c for c in range(8) if (c >> axis) & 1 == side))
                    on_face = signs & face
                    beyond = coordinate < n - 1 if side else coordinate > 0  # the neighbour is in the grid
                    rows = np.flatnonzero((on_face != 0) & (on_face != face) & beyond)
                    candidates.append(keys[rows] + (stride if side else -stride))  # keys: no (N, 3) temporaries
            start = len(self.cells)
            fresh = self.add_keys(np.concatenate(candidates))
            if not fresh:
                return added
            added += fresh

    def crossed(self) -> np.ndarray:
        return (self.signs != 0) & (self.signs != 0xFF)


class KeyIndex:
    """Int64 keys numbered in the order first seen (the native ``implc_hash_index``), growing as needed."""

    def __init__(self, runtime, expected: int):
        self.runtime = runtime
        self.bits = max(12, int(np.ceil(np.log2(max(expected, 1) * 2))))
        self.state = np.zeros(2, np.int64)
        self._allocate()

    def _allocate(self):
        self.table = np.full(2 << self.bits, -1, np.int64)
        self.uniques = np.empty(self.limit + KUHN_NEW_KEYS, np.int64)

    @property
    def limit(self) -> int:
        """Keys held before the table grows (half its slots)."""
        return 1 << (self.bits - 1)

    @property
    def count(self) -> int:
        return int(self.state[0])

    def keys(self) -> np.ndarray:
        return self.uniques[: self.count]

    def _grow(self):
        keys = self.keys().copy()
        self.bits += 1
        self._allocate()
        self.state[0] = 0
        self._call(keys, True)

    def _call(self, keys, insert):
        keys = np.ascontiguousarray(keys, dtype=np.int64)
        numbers = np.empty(len(keys), np.int64)
        self.runtime.hash_index(self.table.ctypes.data, self.bits, keys.ctypes.data, len(keys), int(insert),
                                numbers.ctypes.data, self.uniques.ctypes.data, self.state.ctypes.data)
        return numbers

    def number(self, keys: np.ndarray, insert: bool = True) -> np.ndarray:
        """The numbers of ``keys`` (absent ones inserted, or −1 with ``insert=False``). Inserted a slice at
        a time that cannot pass the limit even if all its keys are new, so that the table grows with the
        keys it holds, not with the repeats it is shown (a cell's corners are shown up to eight times)."""
        flat = np.ascontiguousarray(keys.reshape(-1), dtype=np.int64)
        if not insert or self.count + len(flat) <= self.limit:
            return self._call(flat, insert).reshape(keys.shape)
        numbers = np.empty(len(flat), np.int64)
        start = 0
        while start < len(flat):
            room = self.limit - self.count
            if room < min(len(flat) - start, self.limit // 4):
                self._grow()
                continue
            stop = start + min(len(flat) - start, room)
            numbers[start:stop] = self._call(flat[start:stop], True)
            start = stop
        return numbers.reshape(keys.shape)

    def _over_cells(self, n: int, chunk: int, call):
        """Runs a native routine that numbers its cells' vertices here over ``n`` cells, ``chunk`` at a time:
        ``call(start, count)`` returns the cells it did, fewer where the index filled up (it is grown, and
        the rest done next; state[1] counts the triangles it wrote, from 0 each call)."""
        start = 0
        while start < n:
            count = min(chunk, n - start)
            self.state[1] = 0
            done = call(start, count)
            start += done
            if done < count:
                self._grow()

    def _index_words(self):
        return (self.table.ctypes.data, self.bits, self.uniques.ctypes.data, self.limit, self.state.ctypes.data)

    def cell_corners(self, lowest: np.ndarray, offsets: np.ndarray) -> np.ndarray:
        """The numbers of the 8 corners of each cell (``lowest``: its lowest corner key; ``offsets``: the
        corners' key offsets), absent ones inserted (native): (n * 8,)."""
        lowest = np.ascontiguousarray(lowest, dtype=np.int64)
        offsets = np.ascontiguousarray(offsets, dtype=np.int64)
        numbers = np.empty(8 * len(lowest), np.int64)

        def call(start, count):
            return self.runtime.cell_corners(lowest[start:].ctypes.data, count, offsets.ctypes.data,
                                             *self._index_words(), numbers[8 * start:].ctypes.data)

        self._over_cells(len(lowest), KUHN_CHUNK, call)
        return numbers

    def kuhn_triangles(self, grid, cells: np.ndarray, signs: np.ndarray):
        """Marching tetrahedra over the Kuhn split of each cell (native; ``signs``: a byte per cell, bit c
        set where F < 0 at corner c), its vertices numbered here: the triangles (T, 3) and the row of
        ``cells`` each came from."""
        lowest = np.ascontiguousarray(grid.key(cells), dtype=np.int64)
        flags = np.ascontiguousarray(signs, dtype=np.uint8)
        offsets = np.ascontiguousarray(grid.key(CORNERS), dtype=np.int64)
        # room for the most a cell can give (6 tetrahedra, 2 triangles each): the pages never written cost nothing
        faces = np.empty((12 * len(cells), 3), np.int64)
        owners = np.empty(12 * len(cells), np.int64)
        written = 0

        def call(start, count):
            nonlocal written
            done = self.runtime.kuhn_triangles(
                lowest[start:].ctypes.data, offsets.ctypes.data, flags[start:].ctypes.data, count,
                KUHN_PACKED.ctypes.data, *self._index_words(), faces[written:].ctypes.data,
                owners[written:].ctypes.data)
            fresh = int(self.state[1])
            owners[written:written + fresh] += start
            written += fresh
            return done

        self._over_cells(len(cells), KUHN_CHUNK, call)
        return faces[:written], owners[:written]

    def dual_edges(self, grid, cells: np.ndarray, signs: np.ndarray) -> np.ndarray:
        """The numbers of the vertices on each cell's 12 edges (:data:`implc.meshing.tables.CELL_EDGES`
        order), −1 where the edge keeps its sign, numbered here (native): (n, 12)."""
        lowest = np.ascontiguousarray(grid.key(cells), dtype=np.int64)
        flags = np.ascontiguousarray(signs, dtype=np.uint8)
        offsets = np.ascontiguousarray(grid.key(CORNERS), dtype=np.int64)
        numbers = np.empty((len(cells), 12), np.int64)

        def call(start, count):
            return self.runtime.dual_edges(lowest[start:].ctypes.data, offsets.ctypes.data, flags[start:].ctypes.data,
                                           count, CELL_EDGE_PACKED.ctypes.data, *self._index_words(),
                                           numbers[start:].ctypes.data)

        self._over_cells(len(cells), KUHN_CHUNK, call)
        return numbers

    def fan_triangles(self, grid, cells, signs, cell_in, face_in, split):
        """Marching tetrahedra over the fans of cells (native; see :func:`fan_triangles`), their vertices
        numbered here: the triangles (T, 3)."""
        lowest = np.ascontiguousarray(grid.key(cells), dtype=np.int64)
        cell_keys = np.ascontiguousarray(grid.cell_key(cells), dtype=np.int64)
        offsets = np.ascontiguousarray(grid.key(CORNERS), dtype=np.int64)
        flags = [np.ascontiguousarray(a, dtype=np.uint8) for a in (signs, cell_in, face_in, split)]
        # room for the most a cell can give (6 faces, 4 triangles each, 2 each): the pages never written cost nothing
        faces = np.empty((48 * len(cells), 3), np.int64)
        written = 0

        def call(start, count):
            nonlocal written
            done = self.runtime.fan_triangles(
                lowest[start:].ctypes.data, cell_keys[start:].ctypes.data, offsets.ctypes.data,
                flags[0][start:].ctypes.data, flags[1][start:].ctypes.data, flags[2][start:].ctypes.data,
                flags[3][start:].ctypes.data, count, FAN_PACKED.ctypes.data, *self._index_words(),
                faces[written:].ctypes.data)
            written += int(self.state[1])
            return done

        self._over_cells(len(cells), KUHN_CHUNK, call)
        return faces[:written]


def grid_face_ids(grid: Grid, cells: np.ndarray, axis: int, side: int) -> np.ndarray:
    """The ids of the cells' faces on ``axis`` (0: lower, 1: upper): the face's lowest corner key × 3 + axis."""
    lowest = cells.copy()
    lowest[:, axis] += side
    return grid.key(lowest) * 3 + axis


def face_corner_keys(grid: Grid, cells: np.ndarray, axis: int, side: int):
    """For the cells' faces on (axis, side): the four corners in :data:`SQUARE` order as local corner
    indices of the cell, and as corner keys (m, 4)."""
    b, c = face_axes(axis)
    local = [(side << axis) | (du << b) | (dv << c) for du, dv in SQUARE]
    return local, grid.key(cells)[:, None] + grid.key(CORNERS[local])


def square_edge_key(corner_keys, axis: int, i: int, j: int):
    """The grid edge key of the edge between square corners i and j (adjacent, or the diagonal 0-2)."""
    lo, code = square_edge(axis, i, j)
    return grid_edge_key(corner_keys[:, lo], code)


def never(cells):
    return np.zeros(len(cells), bool)


NO_POINTS = Points(None, np.zeros(0, np.int64), np.zeros((0, 3)))
"""No cell or face points: the first pass, every cell split the Kuhn way."""


def _corner_signs(grid: Grid, cells: np.ndarray) -> np.ndarray:
    """Per cell a byte, bit c set where F < 0 at its corner c (:meth:`Grid.corner_signs`).
    ``grid.effort.vertex_chunk`` cells at a time: the corners' numbers take memory for a chunk."""
    signs = np.empty(len(cells), np.uint8)
    expected = CORNERS_PER_CELL * len(cells)  # the index sized once for all the chunks
    chunk = grid.effort.vertex_chunk
    for start in range(0, len(cells), chunk):
        part = cells[start:start + chunk]
        signs[start:start + len(part)] = grid.corner_signs(part, expected)
    return signs
