"""Contouring: the boundary of the solid {F < 0} within the bounds as a closed, oriented triangle mesh.

The mesh is the zero set of the piecewise-linear function that takes F's sampled signs at the vertices of
a tetrahedralization of the voxel grid, cut by the bounds' faces where the solid reaches them:

- **the tetrahedralization**: each cell is split into the six Kuhn (Freudenthal) tetrahedra around its
  main diagonal, the same split in every cell, so neighbours agree on their shared faces (each face cut
  by the diagonal from its lowest to its highest corner). A *feature cell*, where the analytic normals
  at the surface's crossings disagree (a crease or corner of Min/Max CSG runs through it), is split
  instead into a fan from a cell point inside it (dual contouring's QEF minimiser: on the crease) over
  its faces, each face fanned from a face point of its own (the face's 2D QEF minimiser: where the crease
  crosses it); where F has no kink (:attr:`implc.Surface.has_kinks`) only such a cell not proven regular
  is, since a smooth F's surface bends in a proven cell without a crease. Its neighbours fan from their
  centres over the same face triangulations. Every such split is a valid tetrahedralization of the grid:
  points stay strictly inside their cells and faces.
- **marching tetrahedra** over it: each tetrahedron whose vertices' signs differ holds one triangle or
  one quadrilateral (two triangles, split along the diagonal that keeps them on their sides). Each
  surface vertex lies on a tetrahedron edge whose ends have opposite signs, at the root that Newton's
  method along the edge finds there (inside a bracket), kept a little inside the edge; its normal is F's
  gradient where F was last sampled, at most :data:`ROOT_TOLERANCE` of the edge from the vertex.
- **the caps**: each face of the bounds, triangulated as the tetrahedra's faces there, contributes the
  part where the sampled F is negative, so the mesh is closed where the solid meets the bounds. Squares
  inside throughout are merged into aligned blocks (:func:`_cap_blocks`), each a fan from its centre
  corner whose sides are split at every corner the triangles beyond them use (:func:`_block_fans`): a
  box's face at 256³ costs about 9,000 triangles instead of 131,072.

What follows by construction, for any placement of the surface vertices strictly inside their edges:
every edge of the mesh lies in exactly two triangles, consistently oriented (outward: from the negative
to the positive side); no two triangles meet except in a shared edge or vertex, since each triangle lies
in its own tetrahedron and meets the tetrahedron's faces only in the segments shared with its neighbours;
every vertex lies in a cell where F takes both signs at sampled points, so in a cell whose enclosure
contains 0 (the voxelizer keeps every such cell). Only the cells the voxelizer kept are visited, and any
cell that the sampled signs show the surface entering (``MeshStats.added_cells`` counts them, 0 when every
sample agrees with the enclosures), so the mesh is closed whatever the rounding of a single sample.

Vertex keys: every mesh vertex is named by an int64 whose low three bits say what it is (:data:`GRID`: a
grid corner or the crossing on a grid edge; :data:`FACE_CORNER`, :data:`CELL_CORNER`, :data:`FACE_CELL`:
the crossing on an edge from a face or cell point; :data:`FACE_POINT`: a face point on a cap), so that
the cells that share a vertex name it alike.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, field

import numpy as np

from ..engines.surface import Grouping
from ..native import abi
from .contour_native import CONTOURING
from .simplify import SimplifyStats

EDGE_MARGIN = 1.0 / 256
"""How far inside its edge (as a fraction of the edge) a surface vertex is kept: no triangle degenerates."""
ROOT_STEPS = 6
"""The most samples of F (with its gradient) that refine a surface vertex along its edge. Few edges need
more than three (where F bends within a cell), and those few are the vertices furthest from F = 0; six
bring them within a few hundredths of a cell for a few percent more CPU (the "max distance" column of
``implc bench --sections mesh``)."""
ROOT_TOLERANCE = 1e-2
"""A surface vertex is done where Newton's step along its edge moves less than this fraction of the edge:
the vertex takes that step (Newton converges quadratically: where F is smooth along the edge, its distance
to F = 0 is of the order of the step squared; on a ball of radius r at most ROOT_TOLERANCE² × edge² / 2r,
for r = 0.7 in [−1, 1]³ under 10⁻⁵ of a cell at 32³ and 5·10⁻⁷ at 512³), its normal is the gradient where
F was sampled, at most this fraction of the edge away. 10⁻³ took a second sample on two edges in three at
512³ (Scene 1: 1.66 samples a vertex, 1.04 now; bear at 256³ 1.74, 1.22 now), for vertices a hundred
times closer than anyone sees."""
NUDGE = 1e-7
"""Each surface vertex moves along its edge by up to this fraction of the edge, by a hash of its key: the
construction holds for any place inside the edge, and the nudge breaks the exact coplanarity that a
surface aligned with the grid gives (walls of extrusions, faces of boxes), on which floating-point
intersection tests such as pymeshlab's report disjoint coplanar triangles as intersecting."""
FEATURE_COSINE = 0.985
"""A cell is a feature cell where the normal at one of its surface vertices meets the cell's mean normal
at a cosine below this (an angle above about 10°: a crease of 20° or more)."""
QEF_CUTOFF = 0.01
"""Singular values of a QEF below this fraction of the largest are dropped (the point stays near the mean
along those directions)."""
POINT_MARGIN = 1.0 / 32
"""Cell and face points stay this fraction of the cell inside their cell or face."""
GROUP_CELLS = 8
"""F is sampled in groups of this many cells per axis: on the tape engine each group runs the program
simplified over its box."""
GROUPED_PROGRAM = 128
"""The shortest tape-engine program sampled by groups: csg_part's 36 instructions ran 13× slower grouped
(the sorting and gathering of the points), colonnade's 676 twice as fast."""
PROOF_LEVELS = 2
"""How many levels below the grid the proof of regular cells looks, in the cells it has not proven yet."""
DIAGONALS = np.array([(1, 1, 0), (1, -1, 0), (1, 0, 1), (1, 0, -1), (0, 1, 1), (0, 1, -1),
                      (1, 1, 1), (1, 1, -1), (1, -1, 1), (1, -1, -1)], dtype=np.float64)
"""The directions beyond the axes along which the proof of regular cells seeks a derivative of one sign
(the face and body diagonals of a cell, up to sign): on the tape engine, for the cells the axes leave open."""
PROOF_YIELD = 0.25
"""The share of the boxes a level of the proof must prove for the next level to be tried (:func:`_prove`)."""
PROOF_SAMPLE, PROOF_SAMPLE_MIN = 16, 256
"""The first level below the grid, given PROOF_SAMPLE × PROOF_SAMPLE_MIN boxes or more, is tried first on
every PROOF_SAMPLE-th, and on the others only where those gained at least :data:`PROOF_YIELD`: around
colonnade's creases at 512³ it proved 182 of 82,234 cells for 0.2 s of CPU."""
VERTEX_CHUNK = 1 << 18
"""Surface vertices placed, or cells' corners sampled, at a time (:func:`_vertices`, :func:`_corner_signs`):
Scene 1's 1.5 million vertices at 512³ took 0.3 GB more at once, and fresh memory is what a big mesh costs
most."""
CORNERS_PER_CELL = 2
"""The distinct corners a band of cells has per cell, about (1.45 on bear, 1.9 on Scene 1, 2.2 on colonnade):
the size the corners' index starts with."""
MAX_DEPTH = 14
"""The deepest grid contoured: vertex keys hold (2^depth + 1)³ corners times 64 kinds of edge."""

GRID, FACE_CORNER, CELL_CORNER, FACE_CELL, FACE_POINT = range(5)

CORNERS = np.array([[(c >> a) & 1 for a in range(3)] for c in range(8)], dtype=np.int64)
"""A cell's local corner c sits at offset (c & 1, c >> 1 & 1, c >> 2 & 1)."""
SQUARE = ((0, 0), (1, 0), (1, 1), (0, 1))
"""A face's corners in order around it, as steps along its two axes (in increasing order of axis)."""


@dataclass
class MeshStats:
    """What a contouring did: cells, triangles, feature cells, the cells it had to add, seconds per stage;
    and how many of the crossed cells are proven regular: F's derivative along some direction (an axis,
    or on the tape engine one of the cell's face and body :data:`DIAGONALS`) keeps one strict sign wherever
    F may vanish in the cell (its enclosure excludes 0 over the cell, or over each of the sub-boxes
    covering it whose enclosure of F contains 0), so every zero there is a transversal crossing, F has at
    most one zero on each line along that direction, and the surface in the cell is a graph over the plane
    across it — no singular point, no fold, no closed piece inside.
    The others (``unproven_cells``: at a singular point, a thin feature below the grid, a sharp crease or
    where the enclosure is too wide) are meshed all the same, but nothing proves the mesh's topology there."""
    cells: int = 0
    crossed_cells: int = 0
    regular_cells: int = 0
    unproven_cells: int = 0
    feature_cells: int = 0
    added_cells: int = 0
    cap_triangles: int = 0
    triangles: int = 0
    vertices: int = 0
    seconds: dict = field(default_factory=dict)
    simplified: SimplifyStats | None = None  # where the flat parts were simplified (Mesh.simplified)

    def summary(self) -> str:
        total = self.seconds.get("total", 0.0)
        simplified = "" if self.simplified is None else (
            f" (simplified from {self.simplified.triangles_before} in {self.simplified.seconds:.3f} s)")
        return (f"{self.triangles} triangles{simplified}, {self.vertices} vertices from {self.crossed_cells} "
                f"crossed cells of {self.cells} kept ({self.feature_cells} feature cells, {self.added_cells} "
                f"added by the signs, {self.cap_triangles} cap triangles; {self.regular_cells} proven regular, "
                f"{self.unproven_cells} unproven), {total:.3f} s")


# -- tables ------------------------------------------------------------------------------------------
def _oriented_triangles(points: np.ndarray) -> list[list[list[tuple[int, int]]]]:
    """For a tetrahedron with vertex positions ``points`` (4, 3), and each of the 16 sign cases (bit k
    set: vertex k inside), the zero set's triangles as triples of edges (inside vertex, outside vertex),
    ordered so that each triangle's normal points away from the inside.

    The orientation does not depend on where on its edge each vertex lies: the plane of every triangle
    separates the tetrahedron's inside vertices from its outside ones, so it is read off the midpoints."""
    table: list[list[list[tuple[int, int]]]] = []
    for case in range(16):
        inside = [k for k in range(4) if case >> k & 1]
        outside = [k for k in range(4) if not case >> k & 1]
        if len(inside) in (0, 4):
            table.append([])
            continue
        if len(inside) == 1:
            triangles = [[(inside[0], o) for o in outside]]
        elif len(inside) == 3:
            triangles = [[(i, outside[0]) for i in inside]]
        else:  # a quadrilateral (ac, ad, bd, bc), split along ac-bd
            (a, b), (c, d) = inside, outside
            triangles = [[(a, c), (a, d), (b, d)], [(a, c), (b, d), (b, c)]]
        away = points[outside].mean(axis=0) - points[inside].mean(axis=0)
        oriented = []
        for tri in triangles:
            p = [(points[u] + points[v]) / 2 for u, v in tri]
            if np.cross(p[1] - p[0], p[2] - p[0]) @ away < 0:
                tri = [tri[0], tri[2], tri[1]]
            oriented.append(tri)
        table.append(oriented)
    return table


def _kuhn_tables():
    """The six Kuhn tetrahedra of a cell as local corners, and for each and each sign case the triangles'
    vertices as (local corner u, code): the edge from corner u to corner u | code (u's bits are a subset
    of the other end's, as on every edge of a Kuhn tetrahedron)."""
    tets = np.array([(0, 1 << a, (1 << a) | (1 << b), 7) for a, b, _ in itertools.permutations(range(3))])
    count = np.zeros((6, 16), dtype=np.int64)
    corner = np.zeros((6, 16, 2, 3), dtype=np.int64)
    code = np.zeros((6, 16, 2, 3), dtype=np.int64)
    for t, tet in enumerate(tets):
        for case, triangles in enumerate(_oriented_triangles(CORNERS[tet].astype(float))):
            count[t, case] = len(triangles)
            for s, tri in enumerate(triangles):
                for v, (i, o) in enumerate(tri):
                    lo, hi = sorted((tet[i], tet[o]))  # along a Kuhn chain: bits of lo within hi
                    corner[t, case, s, v] = lo
                    code[t, case, s, v] = hi & ~lo
    return tets, count, corner, code


KUHN_TETS, KUHN_COUNT, KUHN_CORNER, KUHN_CODE = _kuhn_tables()
KUHN_EDGES = [(u, v & ~u) for u in range(8) for v in range(8) if u != v and u & v == u]
"""The 19 edges of a cell's Kuhn split, as (lower corner, code)."""
KUHN_SLOT = np.array([KUHN_EDGES.index(edge) if edge[1] else 0  # (0, 0): past the case's triangles
                      for edge in zip(KUHN_CORNER.ravel().tolist(), KUHN_CODE.ravel().tolist())])
KUHN_SLOT = KUHN_SLOT.reshape(KUHN_CORNER.shape)
"""Each triangle vertex's edge as a row of :data:`KUHN_EDGES`."""


def _kuhn_cases() -> np.ndarray:
    """Per sign case of a whole cell (bit c: F < 0 at corner c, 256 cases) its triangles, tetrahedron by
    tetrahedron: (256, 1 + 12 × 3), the count, then each triangle's three edges as rows of
    :data:`KUHN_EDGES` (six tetrahedra, at most two triangles each)."""
    cases = np.zeros((256, 1 + 12 * 3), dtype=np.int64)
    for signs in range(256):
        edges = []
        for t, tet in enumerate(KUHN_TETS):
            case = sum(((signs >> int(corner)) & 1) << v for v, corner in enumerate(tet))
            for s in range(KUHN_COUNT[t, case]):
                edges.extend(KUHN_SLOT[t, case, s])
        cases[signs, 0] = len(edges) // 3
        cases[signs, 1:1 + len(edges)] = edges
    return cases


KUHN_PACKED = np.ascontiguousarray(np.concatenate([np.array(KUHN_EDGES).T.ravel(), _kuhn_cases().ravel()]),
                                   dtype=np.int64)
"""The tables as ``implc_kuhn_triangles`` reads them: the 19 edges' lower corners, their codes, then the
triangles of each of the 256 sign cases of a cell (:func:`_kuhn_cases`)."""
KUHN_CHUNK = 1 << 16
"""Cells per call of the native marching tetrahedra, Kuhn or fans (Ctrl-C is seen between calls)."""
KUHN_NEW_KEYS = 64
"""Room past the index's limit: the keys one cell can add after the check."""
FAN_PAIRS = ((0, 1), (0, 2), (0, 3), (1, 2), (2, 3), (1, 3))
"""A fan tetrahedron (cell point, p, q, r)'s six edges, in the order its edge keys are listed."""


def _fan_tables():
    """Marching tetrahedra on a fan tetrahedron (cell point, p, q, r), p q r counter-clockwise seen from
    outside the cell: per sign case, the triangles as indices into :data:`FAN_PAIRS`."""
    reference = np.array([[1 / 3, 1 / 3, -1], [0, 0, 0], [1, 0, 0], [0, 1, 0]], float)  # outside is +z
    slot = {frozenset(p): k for k, p in enumerate(FAN_PAIRS)}
    count = np.zeros(16, dtype=np.int64)
    edges = np.zeros((16, 2, 3), dtype=np.int64)
    for case, triangles in enumerate(_oriented_triangles(reference)):
        count[case] = len(triangles)
        for s, tri in enumerate(triangles):
            edges[case, s] = [slot[frozenset(pair)] for pair in tri]
    return count, edges


FAN_COUNT, FAN_EDGES = _fan_tables()


def _cap_polygons():
    """For each of the 8 sign cases of a triangle (bit k: vertex k inside), its inside part fanned into
    triangles whose vertices are (k, k): vertex k itself, or (k, k + 1 mod 3): the crossing on that edge."""
    polygons = []
    for case in range(8):
        inside = [bool(case >> k & 1) for k in range(3)]
        polygon = []
        for i in range(3):
            j = (i + 1) % 3
            if inside[i]:
                polygon.append((i, i))
            if inside[i] != inside[j]:
                polygon.append((i, j))
        polygons.append([(polygon[0], polygon[k], polygon[k + 1]) for k in range(1, len(polygon) - 1)])
    return polygons


CAP_POLYGONS = _cap_polygons()


def _face_axes(axis: int) -> tuple[int, int]:
    b, c = [a for a in range(3) if a != axis]
    return b, c


def _reversed_face(axis: int, side: int) -> bool:
    """Whether a face's corners in :data:`SQUARE` order run clockwise seen from outside a cell that has the
    face on ``side`` (0: its lower face on ``axis``)."""
    b, c = _face_axes(axis)
    return float(np.cross(np.eye(3)[b], np.eye(3)[c]) @ np.eye(3)[axis]) * (1 if side else -1) < 0


def _square_edge(axis: int, i: int, j: int) -> tuple[int, int]:
    """The edge between square corners i and j of a face on ``axis`` (adjacent, or the diagonal 0-2) as a
    grid edge: its lower square corner and its code (a bit per axis it steps along)."""
    b, c = _face_axes(axis)
    lo, hi = (i, j) if all(p <= q for p, q in zip(SQUARE[i], SQUARE[j])) else (j, i)
    du, dv = SQUARE[hi][0] - SQUARE[lo][0], SQUARE[hi][1] - SQUARE[lo][1]
    return lo, (du << b) | (dv << c)


def _face_shapes(axis: int, side: int, split: bool):
    """The triangles of a cell's face on (axis, side), counter-clockwise seen from outside the cell: three
    vertices each, ("c", square corner) or ("f", 0) for the face point; fanned from the face point where
    ``split``, else cut by the diagonal 0-2."""
    if split:
        shapes = tuple((("f", 0), ("c", k), ("c", (k + 1) % 4)) for k in range(4))
    else:
        shapes = ((("c", 0), ("c", 1), ("c", 2)), (("c", 0), ("c", 2), ("c", 3)))
    return [(shape[0], shape[2], shape[1]) if _reversed_face(axis, side) else shape for shape in shapes]


def _fan_face_tables() -> np.ndarray:
    """:func:`implc.meshing.contour_native.emit_fan_triangles`'s tables (:data:`implc.native.abi.FAN_TABLES`): the
    faces, :data:`FAN_COUNT`, :data:`FAN_EDGES`, then per (face, split) its triangles, each with its corners'
    inside flags and the six keys of its fan tetrahedron in :data:`FAN_PAIRS` order (the spokes from the
    cell point to its three vertices, then its edges 0-1, 1-2, 2-0), named as :func:`_face_triangles` and
    :func:`_square_edge_key` name them."""
    faces, shapes = [], []
    for axis in range(3):
        b, c = _face_axes(axis)
        for side in (0, 1):
            face = 2 * axis + side
            faces += [axis, side << axis]
            local = [(side << axis) | (du << b) | (dv << c) for du, dv in SQUARE]
            for split in (False, True):
                rows = []
                for shape in _face_shapes(axis, side, split):
                    # a key's slot among the cell's: grid edges 0-63, face corners 64-87, cell corners 88-95,
                    # face cells 96-101
                    flags = [local[k] if kind == "c" else 8 for kind, k in shape]
                    keys = [(CELL_CORNER, local[k], 0, 88 + local[k]) if kind == "c"
                            else (FACE_CELL, face, 0, 96 + face) for kind, k in shape]
                    for v in range(3):
                        (ka, i), (kb, j) = shape[v], shape[(v + 1) % 3]
                        if ka == "c" and kb == "c":
                            lo, code = _square_edge(axis, i, j)
                            keys.append((GRID, local[lo], code, 8 * local[lo] + code))
                        else:
                            k = i if ka == "c" else j
                            keys.append((FACE_CORNER, k, 0, 64 + 4 * face + k))
                    rows += flags + [x for key in keys for x in key]
                block = [len(rows) // (abi.FAN_SHAPE // 4)] + rows
                shapes += block + [0] * (abi.FAN_SHAPE - len(block))
    tables = np.concatenate([faces, FAN_COUNT.ravel(), FAN_EDGES.ravel(), shapes]).astype(np.int64)
    assert len(faces) == abi.FAN_COUNTS and abi.FAN_SHAPES + 12 * abi.FAN_SHAPE == len(tables)
    return tables


FAN_PACKED = _fan_face_tables()
"""The tables as ``implc_fan_triangles`` reads them."""


# -- the grid ----------------------------------------------------------------------------------------
class _Grid:
    """The 2^depth grid over the bounds: corner, cell and face keys, world positions, F's samples."""

    def __init__(self, surface, depth: int, bounds):
        self.surface = surface
        surface.prepare_mesher(CONTOURING.source)
        self.runtime = surface.runtime.library(CONTOURING)  # the mesher's native routines
        self._corners: _KeyIndex | None = None  # the corners sampled so far, and F there
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
        to someone else before the native routine reads it (Scene 1's meshes at 512³ came out with 0 to 6,387
        spurious crease cells when its vertices were placed on two threads)."""
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
        before any is sampled: growing it rehashes every key (Scene 2 at 256³, whose caps add 396,000 corners:
        0.13 s)."""
        self._corner_index(count)

    def _corner_index(self, expected: int) -> _KeyIndex:
        if self._corners is None:
            self._corners = _KeyIndex(self.runtime, max(1 << 16, expected))
        return self._corners

    def corner_values(self, keys: np.ndarray, expected: int | None = None) -> np.ndarray:
        """F at the corners ``keys``, each sampled once for the whole contouring (and remembered);
        ``expected``: how many corners the contouring will sample in all, where known (the index's size)."""
        index = self._corner_index(expected or keys.size // 6)  # a band of cells: one to two corners per cell
        before = index.count
        numbers = index.number(keys)
        self._sample_since(index, before)
        return self._corner_values[numbers]

    def _sample_since(self, index: _KeyIndex, before: int):
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
        b, c = _face_axes(axis)
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


class _Points:
    """Points added to the tetrahedralization (cell points or face points): sorted ids, positions, F there."""

    def __init__(self, grid: _Grid | None, ids: np.ndarray, positions: np.ndarray):
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


def _both_signs(flags: np.ndarray) -> np.ndarray:
    """Rows of sign flags (one row per cell, face or square) that hold both signs: the surface crosses it."""
    return np.asarray(flags.any(1) & ~flags.all(1))


def _grid_edge_key(corner_keys, code):
    return (corner_keys * 8 + code) * 8 + GRID


# -- which cells -------------------------------------------------------------------------------------
class _Cells:
    """The cells being contoured: their indices, where F < 0 at their corners (a byte per cell, bit c for
    corner c), and an index of their keys (numbered by row)."""

    def __init__(self, grid: _Grid, cells: np.ndarray):
        self.grid = grid
        self.cells = np.zeros((0, 3), np.int64)
        self.signs = np.zeros(0, np.uint8)
        self.index = _KeyIndex(grid.runtime, len(cells) + len(cells) // 8 + 1024)  # room for the cells added
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
        # in octree order, 4x faster than its merge sort (Scene 1 at 512³: 4.5 against 17.7 ms)
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


# -- triangles ---------------------------------------------------------------------------------------
class _KeyIndex:
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

    def fan_triangles(self, grid, cells, signs, cell_in, face_in, split):
        """Marching tetrahedra over the fans of cells (native; see :func:`_fan_triangles`), their vertices
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


def _face_ids(grid: _Grid, cells: np.ndarray, axis: int, side: int) -> np.ndarray:
    """The ids of the cells' faces on ``axis`` (0: lower, 1: upper): the face's lowest corner key × 3 + axis."""
    lowest = cells.copy()
    lowest[:, axis] += side
    return grid.key(lowest) * 3 + axis


def _face_corner_keys(grid: _Grid, cells: np.ndarray, axis: int, side: int):
    """For the cells' faces on (axis, side): the four corners in :data:`SQUARE` order as local corner
    indices of the cell, and as corner keys (m, 4)."""
    b, c = _face_axes(axis)
    local = [(side << axis) | (du << b) | (dv << c) for du, dv in SQUARE]
    return local, grid.key(cells)[:, None] + grid.key(CORNERS[local])


def _square_edge_key(corner_keys, axis: int, i: int, j: int):
    """The grid edge key of the edge between square corners i and j (adjacent, or the diagonal 0-2)."""
    lo, code = _square_edge(axis, i, j)
    return _grid_edge_key(corner_keys[:, lo], code)


def _face_triangles(grid, cells, axis, side, split4, face_points: _Points, inside):
    """The triangles of the cells' faces on (axis, side), counter-clockwise seen from outside the cells:
    yields (rows of cells, the triangle's shape (("c", square corner) or ("f", 0) for the face point,
    three times), its vertices' inside flags (m, 3), the vertices' own keys (m, 3), the keys of its edges
    0-1, 1-2, 2-0 (m, 3)). Faces with ``split4`` are fanned from their face point."""
    local, corner_keys = _face_corner_keys(grid, cells, axis, side)
    face_ids = _face_ids(grid, cells, axis, side)
    rows = np.arange(len(cells))
    corner_in = inside[:, local]
    for fanned in (False, True):
        sel = rows[split4 == fanned]
        if not len(sel):
            continue
        fp = face_points.find(face_ids[sel]) if fanned else None
        for shape in _face_shapes(axis, side, fanned):
            flags, selves, edges = [], [], []
            for kind, k in shape:
                if kind == "c":
                    flags.append(corner_in[sel, k])
                    selves.append(_grid_edge_key(corner_keys[sel, k], 0))
                else:
                    flags.append(face_points.inside[fp])
                    selves.append(face_ids[sel] * 8 + FACE_POINT)
            for v in range(3):
                (ka, a), (kb, bb) = shape[v], shape[(v + 1) % 3]
                if ka == "c" and kb == "c":
                    edges.append(_square_edge_key(corner_keys[sel], axis, a, bb))
                else:
                    corner = a if ka == "c" else bb
                    edges.append((face_ids[sel] * 4 + corner) * 8 + FACE_CORNER)
            yield sel, shape, np.stack(flags, 1), np.stack(selves, 1), np.stack(edges, 1)


def _fan_triangles(grid: _Grid, index: _KeyIndex, cells, signs, feature, cell_points: _Points,
                   face_points: _Points, is_feature):
    """Marching tetrahedra over the fans of ``cells`` (each from its cell point over its faces' triangles;
    ``signs``: a byte per cell, bit c set where F < 0 at corner c), native (``implc_fan_triangles``): the
    triangles (T, 3), their vertices numbered in ``index``.
    ``is_feature(cells)`` says which cells are feature cells (their faces, and their neighbours' faces
    toward them, fan from face points)."""
    cell_keys = grid.cell_key(cells)
    cell_in = cell_points.inside[cell_points.find(cell_keys)]
    split = np.zeros((len(cells), 6), bool)
    face_in = np.zeros((len(cells), 6), bool)
    for axis in range(3):
        for side in (0, 1):
            neighbour = cells.copy()
            neighbour[:, axis] += 1 if side else -1
            face = 2 * axis + side
            split[:, face] = feature | is_feature(neighbour)
            sel = np.flatnonzero(split[:, face])
            face_in[sel, face] = face_points.inside[face_points.find(_face_ids(grid, cells[sel], axis, side))]
    return index.fan_triangles(grid, cells, signs, cell_in, face_in, split)


def _cap_triangles(grid: _Grid, face_points: _Points, is_feature, faces=None):
    """The bounds' faces where the sampled F is negative, as triangles of vertex keys ({(axis, side): (T, 3)}),
    and the cells beside them whose face there has both signs (they must be contoured too); ``faces``: only
    those (default: all six); the faces proven outside (:meth:`_Grid.find_outside_faces`) are not sampled."""
    caps, seeds = {}, []
    n = grid.n
    u, v = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    for axis in range(3):
        b, c = _face_axes(axis)
        for side in (0, 1):
            if (axis, side) in grid.outside_faces or (faces is not None and (axis, side) not in faces):
                continue
            out: list[np.ndarray] = []
            grid_of_cells = np.zeros((n, n, 3), np.int64)
            grid_of_cells[..., axis] = side * (n - 1)
            grid_of_cells[..., b], grid_of_cells[..., c] = u, v
            cells = grid_of_cells.reshape(-1, 3)
            local, corner_keys = _face_corner_keys(grid, cells, axis, side)
            keys = grid.face_keys(axis, side)
            values = grid.face_values(axis, side, keys)
            signs = values < 0
            split4 = is_feature(cells)  # squares fanned from a face point, which may be inside where no corner is
            points_inside = face_points.inside[face_points.find(_face_ids(grid, cells[split4], axis, side))]
            if not signs.any() and not points_inside.any():
                continue
            grid.remember(keys.reshape(-1), values.reshape(-1))
            inside = np.zeros((len(cells), 8), bool)
            for k, (du, dv) in enumerate(SQUARE):
                inside[:, local[k]] = signs[cells[:, b] + du, cells[:, c] + dv]
            seeds.append(cells[_both_signs(inside[:, local])])
            whole = inside[:, local].all(1) & ~split4  # squares inside throughout, with no face point
            blocks, in_block = _cap_blocks(whole.reshape(n, n))
            if blocks:  # the corners the triangles beside the blocks use: the other squares' and the blocks'
                used = np.zeros((n + 1, n + 1), bool)
                emitting = ~in_block & (signs[:-1, :-1] | signs[1:, :-1] | signs[:-1, 1:] | signs[1:, 1:])
                for du, dv in SQUARE:
                    used[du:n + du, dv:n + dv] |= emitting
                for size, lowest in blocks:
                    for du, dv in SQUARE:
                        used[lowest[:, 0] + du * size, lowest[:, 1] + dv * size] = True
                out.extend(_block_fans(blocks, used, keys, _reversed_face(axis, side)))
                rest = np.flatnonzero(~in_block.reshape(-1))
                cells, inside, split4 = cells[rest], inside[rest], split4[rest]
            for sel, shape, flags, selves, edges in _face_triangles(grid, cells, axis, side, split4, face_points,
                                                                    inside):
                case = flags[:, 0] | flags[:, 1].astype(np.int64) << 1 | flags[:, 2].astype(np.int64) << 2
                for polygon_case in range(1, 8):
                    pick = case == polygon_case
                    if not pick.any():
                        continue
                    for triple in CAP_POLYGONS[polygon_case]:
                        out.append(np.stack([selves[pick, i] if i == j else edges[pick, i] for i, j in triple], 1))
            caps[axis, side] = np.concatenate(out) if out else np.zeros((0, 3), np.int64)
    return caps, (np.concatenate(seeds) if seeds else np.zeros((0, 3), np.int64))


def _close_over_reached_faces(grid: _Grid, todo: _Cells, start: int):
    """Where the cells from row ``start`` on reach a face of the bounds taken as outside
    (:meth:`_Grid.touched`), that face is sampled after all and the cells are closed under its caps' seeds,
    until none is reached: (cells added, the caps made last, or None where no face was reached)."""
    added, caps = 0, None
    while grid.touched(todo.cells[start:]):
        start = len(todo.cells)  # the cells checked so far reach no other face taken as outside
        caps, seeds = _cap_triangles(grid, _NO_POINTS, _never)
        added += todo.close(seeds, start=start)
    return added, caps


def _cap_blocks(whole: np.ndarray) -> tuple[list[tuple[int, np.ndarray]], np.ndarray]:
    """The squares of a face of the bounds (``whole``, (n, n): inside throughout, no face point) merged into
    aligned blocks of 2^k × 2^k squares (k >= 1), largest first, none touching the face's border (there the
    neighbouring face's cap meets this one square by square): [(size, (m, 2) lowest corners)] and which
    squares the blocks cover (n, n)."""
    n = len(whole)
    mergeable = whole.copy()
    mergeable[[0, -1], :] = mergeable[:, [0, -1]] = False
    covered = np.zeros_like(mergeable)
    levels: list[np.ndarray] = [mergeable]
    while len(levels[-1]) >= 2:  # level k: which aligned 2^k blocks are mergeable throughout
        m = levels[-1]
        half = len(m) // 2
        levels.append(np.asarray(m.reshape(half, 2, half, 2).all((1, 3))))
    blocks = []
    for k in range(len(levels) - 1, 0, -1):
        size = 1 << k
        free = ~covered.reshape(n // size, size, n // size, size).any((1, 3))
        take = levels[k] & free
        if take.any():
            blocks.append((size, np.argwhere(take) * size))
            covered |= np.repeat(np.repeat(take, size, 0), size, 1)
    return blocks, covered


def _block_fans(blocks, used: np.ndarray, keys: np.ndarray, flip: bool):
    """Each block of :func:`_cap_blocks` as a fan from its centre corner over its boundary: its corners and
    every corner along its sides that ``used`` marks ((n + 1)², a corner of a square or block beside it),
    so that each side meets the triangles beyond it edge for edge. Counter-clockwise in the face's axes
    (:data:`SQUARE`), reversed where ``flip``; vertices are the corners' own keys (``keys``: the face's
    corner keys, (n + 1)²)."""
    for size, lowest in blocks:
        steps = np.arange(size)
        # the boundary in SQUARE order: along the first axis, up the second, back, down: (4·size, 2) offsets
        ring = np.concatenate([np.stack([steps, 0 * steps], 1), np.stack([size + 0 * steps, steps], 1),
                               np.stack([size - steps, size + 0 * steps], 1), np.stack([0 * steps, size - steps], 1)])
        points = lowest[:, None, :] + ring[None]  # (m, 4·size, 2)
        on = used[points[..., 0], points[..., 1]]
        on[:, ::size] = True  # the block's own corners
        flat = np.flatnonzero(on)  # in order, block by block; each block's first point is its corner
        width = 4 * size
        following = np.append(flat[1:], -1)
        last = following // width != flat // width  # the block's last point: back to its first
        following = np.where(last, flat // width * width, following)
        p, q = points.reshape(-1, 2)[flat], points.reshape(-1, 2)[following]
        centre = (lowest + size // 2)[flat // width]
        centre, p, q = (_grid_edge_key(keys[uv[:, 0], uv[:, 1]], 0) for uv in (centre, p, q))
        yield np.stack([centre, q, p] if flip else [centre, p, q], 1)


# -- features ----------------------------------------------------------------------------------------
def _qef(runtime, points, normals, mask, project_out=None):
    """Dual contouring's point per row: the least-squares meeting point of the tangent planes (points
    (m, k, 3), unit normals, ``mask`` which are present), solved around their mean with eigenvalues below
    :data:`QEF_CUTOFF` of the largest dropped. ``project_out``: an axis whose normal component is removed
    first (a face's 2D QEF). Native (``implc_qef``: Jacobi's rotations per row; numpy's eigendecomposition
    took a microsecond a row, Scene 2's 26,572 feature cells at 256³ 0.2 s)."""
    m, k = mask.shape
    points = np.ascontiguousarray(points, dtype=np.float64)
    normals = np.ascontiguousarray(normals, dtype=np.float64)
    flags = np.ascontiguousarray(mask, dtype=np.uint8)
    out = np.empty((m, 3))
    runtime.qef(points.ctypes.data, normals.ctypes.data, flags.ctypes.data, m, k,
                -1 if project_out is None else project_out, QEF_CUTOFF, out.ctypes.data)
    return out


def _feature_cells(runtime, cells, faces, tri_owner, normals):
    """Rows of ``cells`` where the normal at one of their triangles' vertices is further than
    FEATURE_COSINE from the cell's mean normal (the sum over its triangles' vertices), or not defined
    (native: ``implc_bent_cells``)."""
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    owner = np.ascontiguousarray(tri_owner, dtype=np.int64)
    normals = np.ascontiguousarray(normals, dtype=np.float64)
    mean = np.zeros((len(cells), 3))
    bent = np.zeros(len(cells), np.uint8)
    runtime.bent_cells(faces.ctypes.data, owner.ctypes.data, len(faces), normals.ctypes.data, len(cells),
                       mean.ctypes.data, FEATURE_COSINE, bent.ctypes.data)
    return np.flatnonzero(bent)


def _edge_data(index: _KeyIndex, keys, positions, normals):
    """Positions, normals and presence of the vertices on the grid edges ``keys`` (absent: no crossing, or
    a normal not usable: NaN throughout, :func:`_edge_roots`; its row's normal 0). Rows taken by np.take
    (several times faster than fancy indexing of (N, 3) arrays)."""
    rows = index.number(keys, insert=False)
    present = rows >= 0
    np.maximum(rows, 0, out=rows)
    found = np.take(normals, rows, axis=0)
    ok = present & ~np.isnan(found[..., 0])
    found[~ok] = 0
    return np.take(positions, rows, axis=0), found, ok


def _place_points(grid, feature_cells, fanned_cells, index: _KeyIndex, positions, normals):
    """Cell points (the QEF point of each feature cell, the centre of every other fanned cell) and face
    points (the face's 2D QEF point, for every face of a feature cell), kept inside their cells and faces."""
    corner_keys = grid.key(feature_cells)[:, None] + grid.key(CORNERS)
    keys = np.stack([_grid_edge_key(corner_keys[:, u], code) for u, code in KUHN_EDGES], 1)
    p, nrm, ok = _edge_data(index, keys, positions, normals)
    lo = grid.world(feature_cells)
    hi = grid.world(feature_cells + 1)
    margin = (hi - lo) * POINT_MARGIN
    qef = np.clip(_qef(grid.runtime, p, nrm, ok), lo + margin, hi - margin)
    qef = np.where(ok.any(1)[:, None], qef, (lo + hi) / 2)
    others = fanned_cells
    centres = (grid.world(others) + grid.world(others + 1)) / 2
    ids = np.concatenate([grid.cell_key(feature_cells), grid.cell_key(others)])
    first = np.unique(ids, return_index=True)[1]  # a feature cell's QEF point wins over its centre
    cell_points = _Points(grid, ids[first], np.concatenate([qef, centres])[first])

    face_ids, face_pos = [], []
    for axis in range(3):
        b, c = _face_axes(axis)
        for side in (0, 1):
            ids = _face_ids(grid, feature_cells, axis, side)
            _, corner_keys = _face_corner_keys(grid, feature_cells, axis, side)
            pairs = [(0, 1), (1, 2), (3, 2), (0, 3), (0, 2)]
            keys = np.stack([_square_edge_key(corner_keys, axis, i, j) for i, j in pairs], 1)
            p, nrm, ok = _edge_data(index, keys, positions, normals)
            lo = grid.world(feature_cells + side * np.eye(3, dtype=np.int64)[axis])
            hi = lo.copy()
            span = grid.world(feature_cells + 1) - grid.world(feature_cells)
            hi[:, [b, c]] += span[:, [b, c]]
            margin = span * POINT_MARGIN
            margin[:, axis] = 0
            point = np.clip(_qef(grid.runtime, p, nrm, ok, project_out=axis), lo + margin, hi - margin)
            point = np.where(ok.any(1)[:, None], point, (lo + hi) / 2)
            point[:, axis] = lo[:, axis]
            face_ids.append(ids)
            face_pos.append(point)
    ids, first = np.unique(np.concatenate(face_ids), return_index=True)
    face_points = _Points(grid, ids, np.concatenate(face_pos)[first])
    return cell_points, face_points


# -- vertices ----------------------------------------------------------------------------------------
def _endpoints(grid: _Grid, keys: np.ndarray, cell_points: _Points, face_points: _Points):
    """The two ends of the edge each key names and F there, (a, b, fa, fb) (a point named by itself: both
    ends the same, its values not used). Rows are selected by index, not by boolean mask (several
    times faster on (N, 3) arrays)."""
    if not np.any(keys & 7 != GRID):  # the first pass: grid edges, and the caps' corners (both ends)
        return grid.edge_ends(keys)
    kind, payload = keys & 7, keys >> 3
    grid_edge = (kind == GRID) & (payload & 7 != 0)
    a, b = np.empty((len(keys), 3)), np.empty((len(keys), 3))
    fa, fb = np.zeros(len(keys)), np.zeros(len(keys))

    def corner(sel, ijk):
        b[sel] = grid.world(ijk)
        fb[sel] = grid.corner_values(grid.key(ijk))

    sel = np.flatnonzero(grid_edge)
    a[sel], b[sel], fa[sel], fb[sel] = grid.edge_ends(keys[sel])
    sel = np.flatnonzero((kind == GRID) & (payload & 7 == 0))
    a[sel] = b[sel] = grid.world(grid.unkey(payload[sel] >> 3))
    sel = np.flatnonzero(kind == FACE_POINT)
    a[sel] = b[sel] = face_points.positions[face_points.find(payload[sel])]
    sel = np.flatnonzero(kind == FACE_CORNER)
    if len(sel):
        face = payload[sel] // 4
        rows = face_points.find(face)
        a[sel], fa[sel] = face_points.positions[rows], face_points.values[rows]
        axis = face % 3
        lowest = grid.unkey(face // 3)
        step = np.array(SQUARE)[payload[sel] % 4]
        for ax in range(3):
            b_ax, c_ax = _face_axes(ax)
            on = axis == ax
            lowest[on, b_ax] += step[on, 0]
            lowest[on, c_ax] += step[on, 1]
        corner(sel, lowest)
    sel = np.flatnonzero(kind == CELL_CORNER)
    if len(sel):
        cell = payload[sel] // 8
        rows = cell_points.find(cell)
        a[sel], fa[sel] = cell_points.positions[rows], cell_points.values[rows]
        corner(sel, grid.cell_unkey(cell) + CORNERS[payload[sel] % 8])
    sel = np.flatnonzero(kind == FACE_CELL)
    if len(sel):
        cell, face = payload[sel] // 6, payload[sel] % 6
        rows = cell_points.find(cell)
        a[sel], fa[sel] = cell_points.positions[rows], cell_points.values[rows]
        cells = grid.cell_unkey(cell)
        ids = np.empty(len(cell), np.int64)
        for f in range(6):
            on = face == f
            ids[on] = _face_ids(grid, cells[on], f // 2, f % 2)
        rows = face_points.find(ids)
        b[sel], fb[sel] = face_points.positions[rows], face_points.values[rows]
    return a, b, fa, fb


def _all_grid_edges(keys: np.ndarray) -> bool:
    """Whether every vertex key names the crossing on a grid edge (kind GRID, a code that is not 0)."""
    return not np.any((keys & 7 != GRID) | (keys & (7 << 3) == 0))


def _vertices(grid: _Grid, keys: np.ndarray, cell_points: _Points, face_points: _Points, witnesses: bool):
    """Positions of the vertices named by ``keys`` (unique): a point itself, or the root of F on its edge
    (:func:`_edge_roots`). Returns (positions, unit normals (NaN at a point named by itself, and where F's
    gradient is not usable), witnesses: (V, 2, 3) the edge's ends, the one where F < 0 first, a point named
    by itself twice; None unless ``witnesses``). Done :data:`VERTEX_CHUNK` keys at a time, so that the
    edges' ends, brackets and samples take memory for a chunk, not for the mesh."""
    n = len(keys)
    positions, normals = np.empty((n, 3)), np.empty((n, 3))
    ends = np.empty((n, 2, 3)) if witnesses else None
    for start in range(0, n, VERTEX_CHUNK):
        rows = slice(start, min(n, start + VERTEX_CHUNK))
        _vertex_chunk(grid, keys[rows], cell_points, face_points, positions[rows], normals[rows],
                      None if ends is None else ends[rows])
    return positions, normals, ends


def _vertex_chunk(grid: _Grid, keys, cell_points: _Points, face_points: _Points, positions, normals, ends):
    """:func:`_vertices` for one chunk of keys, written into ``positions``, ``normals`` and ``ends`` (or None)."""
    a, b, fa, fb = _endpoints(grid, keys, cell_points, face_points)
    every_edge = _all_grid_edges(keys)
    on_edge = np.arange(len(keys)) if every_edge else np.flatnonzero(np.any(a != b, axis=1))
    if ends is not None:
        ends[:, 0], ends[:, 1] = a, b  # a point named by itself: both ends; an edge's are swapped below
    if len(on_edge) == len(keys):
        _edge_roots(grid, keys, a, b, fa, fb, positions, normals)  # a and b: the inside end first
    else:  # the edges' rows taken (np.take: a boolean mask of an (N, 3) array is several times slower)
        positions[:] = a  # a point named by itself: its own position
        a, b = np.take(a, on_edge, axis=0), np.take(b, on_edge, axis=0)
        fa, fb = np.take(fa, on_edge), np.take(fb, on_edge)
        normals[:] = np.nan
        edge_positions, edge_normals = np.empty((len(on_edge), 3)), np.empty((len(on_edge), 3))
        _edge_roots(grid, np.take(keys, on_edge), a, b, fa, fb, edge_positions, edge_normals)
        positions[on_edge], normals[on_edge] = edge_positions, edge_normals
    if ends is not None:
        ends[on_edge, 0], ends[on_edge, 1] = a, b


def _edge_roots(grid: _Grid, keys, a, b, fa, fb, vertices: np.ndarray, normals: np.ndarray) -> None:
    """The surface vertex on each edge (a, b) with values (fa, fb) of opposite signs, and a unit normal:
    Newton's method along the edge from the secant through its ends, inside a bracket (regula falsi where
    a Newton step would leave it), F and its gradient sampled together. An edge is done where Newton's step
    moves less than :data:`ROOT_TOLERANCE` of the edge: its vertex is the Newton point, its normal F's
    gradient at the point sampled, that step away. After :data:`ROOT_STEPS` samples an edge still open
    takes the secant through its bracket, and the gradient there (normals: unit vectors, NaN where F's
    gradient is zero or not finite). Every point is kept :data:`EDGE_MARGIN`
    inside the edge and nudged by the hash of its key (native: ``implc_edge_roots``). Swaps the ends in
    place so that F(a) < 0. The points are grouped once (each stays on its edge): the edges still open at
    each step are a subset of that grouping. Writes the vertices and their unit normals into ``vertices``
    and ``normals`` (C-contiguous, (n, 3))."""
    n = len(keys)
    if not n:
        return
    keys = np.ascontiguousarray(keys, dtype=np.int64)
    rows, state = np.empty(n, np.int64), np.empty((n, 5))
    run = grid.runtime.edge_roots
    ends = [keys.ctypes.data, a.ctypes.data, b.ctypes.data, fa.ctypes.data, fb.ctypes.data, state.ctypes.data]
    tail = [EDGE_MARGIN, NUDGE, ROOT_TOLERANCE]
    if run(0, n, rows.ctypes.data, *ends, None, None, None, vertices.ctypes.data, None, *tail):
        raise AssertionError("a surface vertex's edge does not change sign: the samples are not repeatable")
    # the first samples are taken at the vertices' rows (an edge done at once takes its normal from them);
    # the others' next guesses are packed into ``guesses``
    whole = grid.grouping(vertices)
    guesses = np.empty((n, 3))  # pages of guesses never written cost nothing
    grouping, open_ = whole, n
    for step in range(ROOT_STEPS):
        f, g = grid.values_and_gradients(guesses[:open_] if step else vertices, grouping)
        f, g = np.ascontiguousarray(f, dtype=np.float64), np.ascontiguousarray(g, dtype=np.float64)
        open_ = run(1, open_, rows.ctypes.data, *ends, f.ctypes.data, g.ctypes.data, guesses.ctypes.data,
                     vertices.ctypes.data, normals.ctypes.data, *tail)
        if not open_:
            break
        grouping = whole.subset(rows[:open_]) if whole is not None else None
    if open_:
        run(2, open_, rows.ctypes.data, *ends, None, None, guesses.ctypes.data, vertices.ctypes.data,
            normals.ctypes.data, *tail)
        normals[rows[:open_]] = _unit(grid.gradients(guesses[:open_], grouping))


def _unit(normals: np.ndarray) -> np.ndarray:
    """Gradients normalised in place (NaN where they are not usable)."""
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        normals /= np.sqrt(np.einsum("ij,ij->i", normals, normals))[:, None]  # np.linalg.norm: 3x slower
    normals[np.flatnonzero(~np.isfinite(normals).all(1))] = np.nan
    return normals


def _fill_normals(grid: _Grid, normals, vertices, faces) -> np.ndarray:
    """Normals where the analytic one is not usable: a vertex on one face of the bounds (a cap's corner,
    whose triangles all lie in the face) gets that face's outward normal; one on an edge of the bounds, or
    elsewhere where F's gradient is zero or undefined, its triangles' area-weighted mean normal."""
    bad = np.flatnonzero(np.isnan(normals[:, 0]))  # a normal not usable is NaN throughout (_edge_roots)
    if not len(bad) or not len(faces):
        return normals
    p = np.take(vertices, bad, axis=0)
    low, high = p == grid.lo, p == grid.hi
    on = low | high
    flat = on.sum(1) == 1  # on one face of the bounds only
    normals[bad[flat]] = np.where(on[flat], np.where(high[flat], 1.0, -1.0), 0.0)
    bad = bad[~flat]
    if len(bad):
        mask = np.zeros(len(vertices), bool)
        mask[bad] = True
        # only the triangles around those vertices (column by column: a boolean mask of (F, 3) is 4x slower)
        faces = np.take(faces, np.flatnonzero(mask[faces[:, 0]] | mask[faces[:, 1]] | mask[faces[:, 2]]), axis=0)
        p = np.take(vertices, faces, axis=0)
        area = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        corners = faces.reshape(-1)
        summed = np.stack([np.bincount(corners, np.repeat(area[:, a], 3), minlength=len(vertices))
                           for a in range(3)], 1)[bad]
        with np.errstate(invalid="ignore", divide="ignore"):
            normals[bad] = summed / np.linalg.norm(summed, axis=1)[:, None]
    return normals


# -- the whole -----------------------------------------------------------------------------------------
def contour(surface, cells: np.ndarray, depth: int, bounds=None, *, features: bool = True, witnesses: bool = False):
    """The mesh of ``surface`` (an :class:`implc.Surface`) from the cells the voxelizer kept at ``depth``
    ((N, 3) cell indices): see the module's docstring for what it promises. ``features=False`` keeps the
    Kuhn split everywhere (creases chamfered). ``witnesses=True`` keeps, for each vertex, the ends of the
    edge it was found on (``Mesh.witnesses``, (V, 2, 3): two points of one cell where F has opposite
    signs, the negative one first), so that anyone can check where it lies. Returns an :class:`implc.Mesh`."""
    if not 1 <= depth <= MAX_DEPTH:
        raise ValueError(f"meshes are made at depth 1 to {MAX_DEPTH}, not {depth}")
    from .triangle_mesh import Mesh
    stats = MeshStats()
    t0 = time.perf_counter()
    grid = _Grid(surface, depth, surface.bounds if bounds is None else bounds)
    runtime = grid.runtime
    cells = np.asarray(cells, dtype=np.int64).reshape(-1, 3)
    stats.cells = len(cells)
    grid.find_outside_faces(cells)
    grid.expect_corners(CORNERS_PER_CELL * len(cells) + grid.capped_faces() * grid.k**2)
    todo = _Cells(grid, cells)
    caps, seeds = _cap_triangles(grid, _NO_POINTS, _never)
    t1 = time.perf_counter()
    stats.added_cells = todo.close(seeds)
    added, caps_again = _close_over_reached_faces(grid, todo, 0)
    stats.added_cells += added
    caps = caps if caps_again is None else caps_again
    crossed = np.flatnonzero(todo.crossed())
    stats.crossed_cells = len(crossed)
    index = _KeyIndex(runtime, 4 * len(crossed))
    kuhn, owner = index.kuhn_triangles(grid, todo.cells[crossed], todo.signs[crossed])
    np.take(crossed, owner, out=owner, mode="clip")  # rows of todo.cells, in place (no fresh memory)
    caps = {face: index.number(triangles) for face, triangles in caps.items()}
    t2 = time.perf_counter()
    vertices, normals, ends = _vertices(grid, index.keys(), _NO_POINTS, _NO_POINTS, witnesses)
    t3 = time.perf_counter()
    feature_rows = _feature_cells(runtime, todo.cells, kuhn, owner, normals) if features else []
    proven_rows = np.zeros(0, np.int64)  # rows of todo proven regular already (not proven again below)
    if len(feature_rows) and not surface.has_kinks:  # a smooth F: a crease only where its gradient may vanish
        bent_regular = _regular(grid, todo.cells[feature_rows])
        proven_rows, feature_rows = feature_rows[bent_regular], feature_rows[~bent_regular]
    stats.feature_cells = len(feature_rows)
    mesh = _Pieces(vertices, normals, ends, kuhn, owner, caps)
    del vertices, normals, ends, kuhn, owner, caps  # the pieces hold them, and let each go once it is joined
    if len(feature_rows):
        stats.added_cells += _with_features(grid, todo, feature_rows, index, mesh)
    del index
    grid.forget_samples()
    stats.cap_triangles = sum(map(len, mesh.caps.values()))
    vertices, normals, faces, ends = mesh.compacted()
    normals = _fill_normals(grid, normals, vertices, faces)
    t4 = time.perf_counter()
    crossed = todo.crossed()
    crossed_count = int(np.count_nonzero(crossed))
    crossed[proven_rows] = False
    open_cells = todo.cells[crossed]
    unproven = open_cells[~_regular(grid, open_cells)]
    stats.regular_cells = crossed_count - len(unproven)
    stats.unproven_cells = len(unproven)
    t5 = time.perf_counter()
    stats.triangles, stats.vertices = len(faces), len(vertices)
    stats.seconds = {"signs": t1 - t0, "triangles": t2 - t1, "vertices": t3 - t2, "features": t4 - t3,
                     "proof": t5 - t4, "total": t5 - t0}
    result = Mesh(vertices, faces, normals, stats=stats, bounds=tuple(zip(grid.lo.tolist(), grid.hi.tolist())))
    result.witnesses = ends
    result.unproven_cells = unproven
    return result


def _regular(grid: _Grid, cells: np.ndarray) -> np.ndarray:
    """Whether some derivative of F keeps one strict sign wherever F may vanish in each cell, so that the
    cell is proven regular (:class:`MeshStats`). First over the cells' parents (2³ cells: what holds over a box
    holds over each box inside it, and the surface's cells share a parent three or four at a time), then
    over the cells of the parents not proven, and below them down to :data:`PROOF_LEVELS` levels
    (:func:`_prove`); on the tape engine the cells still open try F's derivatives along the
    :data:`DIAGONALS` the same way (a crease's cells: :func:`_diagonal_signs`), on a sample of them first
    and on the others where the sample gained :data:`PROOF_YIELD` (colonnade's crease cells at 256³: 65%;
    bear's, around smooth blends, 15% for 0.18 s of CPU)."""
    regular = np.zeros(len(cells), bool)
    if not len(cells):
        return regular
    parent_keys, parent_of = _unique_inverse(grid.cell_key(cells // 2))
    parents = grid.cell_unkey(parent_keys)
    proven = np.asarray(_partial_signs(grid, grid.world(np.minimum(2 * parents, grid.n)),
                                       grid.world(np.minimum(2 * parents + 2, grid.n))).any(1))
    regular = proven[parent_of]
    rest = np.flatnonzero(~regular)
    lo, hi = grid.world(cells[rest]), grid.world(cells[rest] + 1)
    regular[rest] = _prove(grid, lo, hi, np.ones((len(rest), 6), bool), PROOF_LEVELS).any(1)
    if grid.surface.engine == "tape":
        rest = np.flatnonzero(~regular)
        sample = np.zeros(len(rest), bool)  # a sample first: the diagonals pay on creases, not on smooth blends
        sample[:: max(1, min(PROOF_SAMPLE, len(rest) // PROOF_SAMPLE_MIN))] = True
        for rows in (rest[sample], rest[~sample]):
            lo, hi = grid.world(cells[rows]), grid.world(cells[rows] + 1)
            wanted = np.ones((len(rows), 2 * len(DIAGONALS)), bool)
            gained = np.asarray(_prove(grid, lo, hi, wanted, PROOF_LEVELS, signs_of=_diagonal_signs).any(1))
            regular[rows] = gained
            if len(gained) and gained.mean() < PROOF_YIELD:
                break
    return regular


def _prove(grid: _Grid, lo, hi, wanted: np.ndarray, levels: int, signs: np.ndarray | None = None,
           sample: bool = True, signs_of=None) -> np.ndarray:
    """Which of the ``wanted`` signs of F's derivatives ((n, 6): rising along x, y, z, then falling; or
    the columns ``signs_of(grid, lo, hi)`` gives, :func:`_partial_signs` by default) are proven over each
    box [lo, hi]: by the box's own enclosures (``signs`` where known), or else by its 8 sub-boxes, down to
    ``levels`` levels. A derivative keeping one sign over every sub-box (but those the surface does not
    meet: :func:`_partial_signs`) keeps it wherever F may vanish in the box they cover; so below a box only
    the signs that every proven sub-box shares are still sought, and a box whose proven sub-boxes share
    none is given up (a crease: one side rises along x, the other along y); and a level pays for the next
    only where it proved at least :data:`PROOF_YIELD` of the boxes it was given (around creases finer
    boxes prove almost nothing: colonnade's, 0.4%). The first level, where ``sample`` and it is given many
    boxes, is tried on a sample of them first (:data:`PROOF_SAMPLE`)."""
    signs_of = signs_of or _partial_signs
    if signs is None:
        signs = signs_of(grid, lo, hi)
    signs &= wanted
    open_ = np.flatnonzero(~signs.any(1) & wanted.any(1))
    if not levels or not len(open_):
        return signs
    if sample and len(open_) >= PROOF_SAMPLE_MIN * PROOF_SAMPLE:
        first = np.zeros(len(open_), bool)
        first[::PROOF_SAMPLE] = True
        if _prove_below(grid, lo, hi, wanted, levels, signs, open_[first], signs_of) < PROOF_YIELD:
            return signs
        open_ = open_[~first]
    _prove_below(grid, lo, hi, wanted, levels, signs, open_, signs_of)
    return signs


def _prove_below(grid: _Grid, lo, hi, wanted, levels: int, signs: np.ndarray, open_: np.ndarray,
                 signs_of) -> float:
    """:func:`_prove`'s next level for the boxes ``open_``: their signs proven by their sub-boxes, in place;
    returns the share of them proven."""
    sub_lo, sub_hi = _halves(lo[open_], hi[open_])  # (m, 8, 3)
    m = len(open_)
    sub = signs_of(grid, sub_lo.reshape(-1, 3), sub_hi.reshape(-1, 3)).reshape(m, 8, -1) & wanted[open_, None]
    proven = sub.any(2)
    sought = np.where(proven[..., None], sub, True).all(1) & wanted[open_]  # what every proven sub-box shares
    signs[open_] = sub.all(1) & sought
    gained = np.asarray(signs[open_].any(1))
    if levels > 1 and gained.mean() >= PROOF_YIELD:
        rows, cols = np.nonzero(~proven & (sought.any(1) & ~gained)[:, None])
        if len(rows):
            sub[rows, cols] = _prove(grid, sub_lo[rows, cols], sub_hi[rows, cols], sought[rows], levels - 1,
                                     sub[rows, cols], sample=False, signs_of=signs_of)
            signs[open_] = sub.all(1) & sought
            gained = np.asarray(signs[open_].any(1))
    return float(gained.mean())


def _unique_inverse(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """np.unique(keys, return_inverse=True) by a stable sort: keys of cells in grid order come in runs, which
    numpy's merge sort takes as they are (twice as fast as the quicksort np.unique uses)."""
    order = np.argsort(keys, kind="stable")
    ordered = keys[order]
    first = np.empty(len(keys), bool)
    first[:1] = True
    np.not_equal(ordered[1:], ordered[:-1], out=first[1:])
    inverse = np.empty(len(keys), np.int64)
    inverse[order] = np.cumsum(first) - 1
    return ordered[first], inverse


def _halves(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The 8 sub-boxes of each box [lo, hi] ((m, 8, 3) lower and upper corners), covering it exactly: the
    outer faces are the box's own, and neighbouring sub-boxes share their inner face's coordinate."""
    mid = lo + (hi - lo) / 2
    edges = np.stack([lo, mid, hi], 1)  # (m, 3 edges, 3 axes)
    index = CORNERS  # sub-box c's lower corner: edge (c >> a & 1) along axis a
    axes = np.arange(3)
    return edges[:, index, axes], edges[:, index + 1, axes]


def _partial_signs(grid: _Grid, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """For each box [lo, hi]: whether F's partial along x, y, z is proven > 0 over the whole box, then
    whether it is proven < 0, (n, 6); all six where F's enclosure over the box excludes 0: the surface does
    not meet the box, so among boxes that cover a cell only those it may meet need a partial's sign (F
    strictly rising along x wherever it may vanish has at most one zero on each line along x: between two
    rising zeros it would have to fall through a third)."""
    if not len(lo):
        return np.zeros((0, 6), bool)
    rising, falling, empty = _signs_along(grid, lo, hi, grid.grouping((lo + hi) / 2))
    return np.concatenate([rising, falling], 1) | empty[:, None]


def _diagonal_signs(grid: _Grid, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """:func:`_partial_signs` for F's derivatives along the :data:`DIAGONALS` (the tape engine's, three at a
    time, each with its own hull at a kink): (n, 2·10), rising along each, then falling; all where F's
    enclosure over the box excludes 0. F rising along a direction d wherever it may vanish in a cell has
    at most one zero on each line along d there, so the surface in the cell is a graph over the plane
    across d: across a crease of Min/Max CSG the two sides' partials along an axis may differ in sign
    (every axis's hull straddles 0) while both rise along a diagonal."""
    count = len(DIAGONALS)
    if not len(lo):
        return np.zeros((0, 2 * count), bool)
    grouping = grid.grouping((lo + hi) / 2)
    rising, falling = [], []
    for first in range(0, count, 3):
        three = DIAGONALS[[min(first + k, count - 1) for k in range(3)]]
        up, down, empty = _signs_along(grid, lo, hi, grouping, three)
        rising.append(up[:, : count - first])
        falling.append(down[:, : count - first])
    return np.concatenate(rising + falling, 1) | empty[:, None]


def _signs_along(grid: _Grid, lo, hi, grouping: Grouping | None, directions=None):
    """Over each box [lo, hi] (the tape engine's program simplified over its group of ``grouping``): whether
    F's derivative along each of three directions (the axes, or the rows of ``directions``) is proven > 0,
    whether it is proven < 0 ((n, 3) each), and whether F's enclosure excludes 0 ((n,))."""
    enclosures = grid.surface.gradient_enclosures(lo, hi, grouping, directions=directions)
    derivatives = enclosures[:, 2:].reshape(-1, 3, 2)
    return derivatives[:, :, 0] > 0, derivatives[:, :, 1] < 0, (enclosures[:, 0] > 0) | (enclosures[:, 1] < 0)


def _never(cells):
    return np.zeros(len(cells), bool)


_NO_POINTS = _Points(None, np.zeros(0, np.int64), np.zeros((0, 3)))
"""No cell or face points: the first pass, every cell split the Kuhn way."""


class _Pieces:
    """The mesh as it is assembled, in blocks joined once at the end (fresh memory is what a big mesh costs
    most): the vertices (numbered by the vertex index) with their normals and witnesses (or None), a block
    per pass; the first pass's triangles with the row of the cell each came from, which of them stay
    (``keep``, after the feature pass), the triangles the feature pass added; the caps', face by face."""

    def __init__(self, vertices, normals, ends, faces, owner, caps):
        self.vertices, self.normals, self.ends = vertices, normals, ends  # the first pass's
        self.added: list[tuple] = []  # the feature pass's vertices, normals, witnesses
        self.faces, self.owner, self.caps = faces, owner, caps
        self.keep: np.ndarray | None = None
        self.more: list[np.ndarray] = []

    def add_vertices(self, vertices, normals, ends):
        self.added.append((vertices, normals, ends))

    def compacted(self):
        """(vertices, normals, faces, witnesses), each written once, with the vertices no triangle uses left
        out (those of the first pass's triangles that the feature pass replaced). The pieces are let go as
        they are joined (this object is empty afterwards): the old and the new mesh are never both whole."""
        caps = [block for block in self.caps.values() if len(block)]
        first = (self.vertices, self.normals, self.ends)
        blocks = [first, *self.added]
        with_ends = self.ends is not None
        source_faces, keep, more = self.faces, self.keep, self.more
        self.vertices = self.normals = self.ends = self.faces = self.owner = self.keep = None
        self.added, self.more, self.caps = [], [], {}
        if keep is None and not caps:
            return first[0], first[1], source_faces, first[2]
        kept = len(source_faces) if keep is None else int(np.count_nonzero(keep))
        faces = np.empty((kept + sum(map(len, more)) + sum(map(len, caps)), 3), np.int64)
        if keep is None:
            faces[:kept] = source_faces
        else:
            # np.take with out= and mode="clip" (the rows are valid): compress with out= is several times slower,
            # and so is take with out= and the default mode (it checks every index before it writes)
            np.take(source_faces, np.flatnonzero(keep), axis=0, out=faces[:kept], mode="clip")
        del source_faces, keep
        at = kept
        for piece in [*more, *caps]:
            faces[at:at + len(piece)] = piece
            at += len(piece)
        del more, caps
        if len(blocks) == 1:
            return first[0], first[1], faces, first[2]
        del first
        used = np.zeros(sum(len(b[0]) for b in blocks), bool)
        used[faces.reshape(-1)] = True
        renumber = np.cumsum(used) - 1
        np.take(renumber, faces, out=faces, mode="clip")  # in place: each index read before its slot is written
        del renumber
        rows = np.flatnonzero(used)  # np.take of rows: several times faster than a boolean mask on (V, 3)
        out = [np.empty((len(rows), 3)), np.empty((len(rows), 3))]
        if with_ends:
            out.append(np.empty((len(rows), 2, 3)))
        start = 0
        while blocks:  # the rows of each block, taken straight into the outputs; the block then let go
            block = blocks.pop(0)
            lo, hi = np.searchsorted(rows, [start, start + len(block[0])])
            for source, target in zip(block, out):
                np.take(source, rows[lo:hi] - start, axis=0, out=target[lo:hi], mode="clip")
            start += len(block[0])
            del block
        return out[0], out[1], faces, (out[2] if with_ends else None)


def _corner_signs(grid: _Grid, cells: np.ndarray) -> np.ndarray:
    """Per cell a byte, bit c set where F < 0 at its corner c (:meth:`_Grid.corner_signs`).
    :data:`VERTEX_CHUNK` cells at a time: the corners' numbers take memory for a chunk."""
    signs = np.empty(len(cells), np.uint8)
    expected = CORNERS_PER_CELL * len(cells)  # the index sized once for all the chunks
    for start in range(0, len(cells), VERTEX_CHUNK):
        part = cells[start:start + VERTEX_CHUNK]
        signs[start:start + len(part)] = grid.corner_signs(part, expected)
    return signs


def _with_features(grid, todo: _Cells, feature_rows, index: _KeyIndex, mesh: _Pieces) -> int:
    """Fan the feature cells (rows of ``todo``) and their neighbours from cell and face points in place of
    their Kuhn split: their triangles in ``mesh`` replaced, the caps made again where a feature cell
    touches the bounds, new vertices numbered on in ``index``. Returns the cells the signs added."""
    feature_cells = todo.cells[feature_rows]
    feature_keys = np.sort(grid.cell_key(feature_cells))

    def is_feature(c):
        ok = np.all((c >= 0) & (c < grid.n), axis=1)
        keys = grid.cell_key(np.clip(c, 0, grid.n - 1))
        rows = np.minimum(np.searchsorted(feature_keys, keys), len(feature_keys) - 1)
        return ok & (feature_keys[rows] == keys)

    neighbours = [feature_cells]
    for axis in range(3):
        for step in (-1, 1):
            c = feature_cells.copy()
            c[:, axis] += step
            neighbours.append(c[(c[:, axis] >= 0) & (c[:, axis] < grid.n)])
    fanned_keys = np.unique(grid.cell_key(np.concatenate(neighbours)))
    before = len(todo.cells)
    todo.add_keys(fanned_keys)
    added = todo.close(np.zeros((0, 3), np.int64), start=before)
    more, caps_again = _close_over_reached_faces(grid, todo, before)
    added += more
    reached = caps_again is not None  # a face taken as outside that the fanned cells, or those the signs added, reach
    fanned = np.zeros(len(todo.cells), bool)
    fanned[todo.index.number(fanned_keys, insert=False)] = True
    cell_points, face_points = _place_points(grid, feature_cells, grid.cell_unkey(fanned_keys), index,
                                             mesh.vertices, mesh.normals)
    first_new = index.count
    mesh.keep = ~fanned[mesh.owner]
    fresh = np.arange(before, len(todo.cells))
    fresh = fresh[~fanned[fresh] & todo.crossed()[before:]]  # added by the signs: Kuhn
    kuhn, owner = index.kuhn_triangles(grid, todo.cells[fresh], todo.signs[fresh])
    rows = np.flatnonzero(fanned)
    fan = _fan_triangles(grid, index, todo.cells[rows], todo.signs[rows], is_feature(todo.cells[rows]),
                         cell_points, face_points, is_feature)
    mesh.more = [kuhn, fan]
    # the caps again where a feature cell lies on a face of the bounds (its square fanned from a face point)
    redo = {(axis, side) for axis in range(3) for side in (0, 1)
            if np.any(feature_cells[:, axis] == side * (grid.n - 1))}
    if redo or reached:
        caps = _cap_triangles(grid, face_points, is_feature, None if reached else redo)[0]
        mesh.caps.update({face: index.number(triangles) for face, triangles in caps.items()})
    keys = index.keys()[first_new:]
    vertices, normals, ends = _vertices(grid, keys, cell_points, face_points, mesh.ends is not None)
    mesh.add_vertices(vertices, normals, ends)
    return added
