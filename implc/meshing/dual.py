"""One vertex per crossed cell where that is safe: dual contouring on the cells whose corner signs leave one
sheet, stitched to the cells that keep the tetrahedral construction.

A *dual cell* is a crossed cell, not on the bounds' outer layer, whose inside corners are edge-connected
and whose outside corners are too (:data:`MANIFOLD`: 126 of the 254 crossed configurations, OpenVDB's
``sAdaptable`` less the two uncrossed ones): no face of it is ambiguous, each face carries at most one
segment of the contour, and one vertex serves the cell. The vertex is the QEF
point of its edges' crossings (dual contouring's least-squares meeting point of their tangent planes),
clamped :data:`DUAL_MARGIN` inside the cell, so creases stay sharp where the cell allows; its normal is F's
gradient there.

The triangles, all oriented from F < 0 to F ≥ 0:

- a sign-changing grid edge whose four cells are all dual gives a quad over their vertices, split along a
  diagonal that passes Ju and Udeshi's test ("Intersection-free contouring on an octree grid", 2006):
  both triangles separate the edge's two ends, tested with filtered orientation predicates that answer
  only where the double's sign is certain, on the doubles and again on the float32 values a file keeps;
  where neither diagonal passes, four triangles fanned about the edge's root;
- an edge with a cell of the other kind among its four gives, for each pair of dual cells across one of
  its faces, the fan triangle (root, their vertices);
- a dual cell's face toward a cell of the other kind is coned from the dual vertex over that face's
  contour as the tetrahedral construction draws it (the face cut by its diagonal from the lowest to the
  highest corner), so the two sides share that polyline.

Why nothing meets: with every dual vertex strictly inside its cell, a fan triangle or a quad's triangle
across the face between dual cells D and N lies in the "diamond" conv(edge, v_D, v_N), whose part in D lies
in the pyramid from v_D over that face (the segment v_D v_N leaves D through that face, since D and N
share the other two coordinates' ranges); a cone lies in the pyramid from v_D over its face; the pyramids
of one cell over different faces meet only in their shared sides; and the other construction's
triangles stay in their own cells. Ju and Udeshi show that the diamonds of different edges do not
overlap. The stitch is this argument, not a published result: property tests over random CSG gate it.
"""

from __future__ import annotations

import numpy as np

from ..common.threads import in_parallel
from .features import QEF_CUTOFF
from .grid import Cells, Grid, KeyIndex
from .tables import CELL_EDGES, CORNERS, DUAL_PACKED

CELL_POINT = 5
"""The kind of a dual vertex's key (see :mod:`implc.meshing.contour`): the cell's key × 8 + 5."""
DUAL_CHUNK = 1 << 15
"""Dual cells per native call (the calls run on the workers' threads; Ctrl-C is seen between them)."""
DUAL_MARGIN = 1.0 / 256
"""A dual vertex stays this fraction of its cell inside every face of it (as a surface vertex stays inside
its edge): a face of the solid on a grid plane moves that little inward; and a file's float32 rounding
keeps the vertex inside its cell wherever a cell spans 2^9 float32 steps of its coordinates or more."""
def _connected(corners: list[int]) -> bool:
    if not corners:
        return True
    seen, todo = {corners[0]}, [corners[0]]
    while todo:
        c = todo.pop()
        for axis in range(3):
            d = c ^ (1 << axis)
            if d in corners and d not in seen:
                seen.add(d)
                todo.append(d)
    return len(seen) == len(corners)


MANIFOLD = np.array([_connected([c for c in range(8) if s >> c & 1])
                     and _connected([c for c in range(8) if not s >> c & 1]) for s in range(256)])
"""Per sign byte (bit c: F < 0 at corner c), whether the inside corners are edge-connected and the outside
ones are too."""


def dual_rows(grid: Grid, todo: Cells) -> np.ndarray:
    """Which rows of ``todo`` are dual cells: crossed, in :data:`MANIFOLD`, not on the bounds' outer layer
    (their faces there hold caps)."""
    signs = todo.signs
    inner = np.all((todo.cells > 0) & (todo.cells < grid.n - 1), axis=1)
    return MANIFOLD[signs] & (signs != 0) & (signs != 0xFF) & inner


def dual_vertices(grid: Grid, cells: np.ndarray, edges: np.ndarray, positions, normals, sharp: bool) -> np.ndarray:
    """Each dual cell's vertex (native: ``implc_dual_points``): the QEF point of its edges' crossings
    (``edges``: their vertex numbers, (m, 12), −1 where the edge keeps its sign; ``positions``,
    ``normals``: those vertices'), or where not ``sharp`` their mean (creases chamfered),
    :data:`DUAL_MARGIN` of the cell inside each face of it (its centre where no crossing has a usable
    normal)."""
    out = np.empty((len(cells), 3))
    edges = np.ascontiguousarray(edges, dtype=np.int64)
    cells = np.ascontiguousarray(cells, dtype=np.int64)
    positions = np.ascontiguousarray(positions, dtype=np.float64)
    normals = np.ascontiguousarray(normals, dtype=np.float64)

    def job(start, count):
        return lambda: grid.runtime.dual_points(
            edges[start:].ctypes.data, count, positions.ctypes.data, normals.ctypes.data, cells[start:].ctypes.data,
            grid.geometry.ctypes.data, QEF_CUTOFF, DUAL_MARGIN, int(sharp), out[start:].ctypes.data)

    in_parallel([job(start, min(DUAL_CHUNK, len(cells) - start)) for start in range(0, len(cells), DUAL_CHUNK)])
    return out


def dual_triangles(grid: Grid, todo: Cells, rows: np.ndarray, edges: np.ndarray, first: int, points: np.ndarray,
                   index: KeyIndex) -> tuple[np.ndarray, dict]:
    """The triangles of the dual cells at ``rows`` of ``todo`` (see the module docstring; native:
    ``implc_dual_triangles``): ``edges`` their crossings' vertex numbers (m, 12), their own vertices
    numbered ``first`` on, at ``points``; the face diagonals' crossings are the vertices ``index`` numbers
    already. Returns (triangles (T, 3), counts of quads, edges fanned, edges stitched, cones)."""
    m = len(rows)
    cells = np.ascontiguousarray(todo.cells[rows], dtype=np.int64)
    signs = np.ascontiguousarray(todo.signs[rows], dtype=np.uint8)
    edges = np.ascontiguousarray(edges, dtype=np.int64)
    points = np.ascontiguousarray(points, dtype=np.float64)
    dual_of_row = np.full(len(todo.cells), -1, np.int64)
    dual_of_row[rows] = np.arange(m)
    starts = list(range(0, m, DUAL_CHUNK))
    pieces: list[np.ndarray] = [np.zeros((0, 3), np.int64)] * len(starts)
    tallies = np.zeros((len(starts), 5), np.int64)

    def job(k):
        def run():
            start = starts[k]
            count = min(DUAL_CHUNK, m - start)
            # room for the most a cell gives (12 edges of 4 triangles, 6 faces of 2): pages never written cost nothing
            faces = np.empty((60 * count, 3), np.int64)
            tally = tallies[k]  # a row of tallies, held by it for the call
            written = grid.runtime.dual_triangles(
                cells[start:].ctypes.data, signs[start:].ctypes.data, edges[start:].ctypes.data, first,
                points.ctypes.data, start, count, DUAL_PACKED.ctypes.data, grid.geometry.ctypes.data,
                todo.index.table.ctypes.data, todo.index.bits, dual_of_row.ctypes.data, index.table.ctypes.data,
                index.bits, faces.ctypes.data, tally.ctypes.data)
            pieces[k] = faces[:written].copy()
        return run

    in_parallel([job(k) for k in range(len(starts))])  # each chunk its own triangles: the same mesh on any count
    counts = tallies.sum(0)
    if counts[4]:
        raise AssertionError(f"{counts[4]} cells or face crossings beside dual cells were never contoured")
    names = ("quads", "fanned edges", "stitched edges", "cones")
    return (np.concatenate(pieces) if pieces else np.zeros((0, 3), np.int64)), dict(zip(names, counts.tolist()))


def dual_witnesses(grid: Grid, cells: np.ndarray, signs: np.ndarray) -> np.ndarray:
    """(m, 2, 3): for each dual cell, an inside and an outside corner of a sign-changing edge of it."""
    out = np.empty((len(cells), 2, 3))
    found = np.zeros(len(cells), bool)
    for u, axis in CELL_EDGES:
        w = u | 1 << axis
        here = ~found & ((signs >> u & 1) != (signs >> w & 1))
        inside_u = (signs >> u & 1).astype(bool)
        s = np.flatnonzero(here)
        a, b = cells[s] + CORNERS[u], cells[s] + CORNERS[w]
        first = np.where(inside_u[s][:, None], a, b)
        second = np.where(inside_u[s][:, None], b, a)
        out[s, 0], out[s, 1] = grid.world(first), grid.world(second)
        found |= here
    return out
