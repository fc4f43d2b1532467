"""The surface vertices: each on a tetrahedron edge whose ends have opposite signs, at the root Newton's
method finds inside the bracket, kept :data:`EDGE_MARGIN` inside the edge, with F's gradient as its normal."""

from __future__ import annotations

import numpy as np

from .grid import Grid, Points, grid_face_ids
from .tables import CELL_CORNER, CORNERS, FACE_CELL, FACE_CORNER, FACE_POINT, GRID, SQUARE, face_axes

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
for r = 0.7 in [−1, 1]³ under 10⁻⁵ of a cell at 32³), its normal is the gradient where F was sampled, at
most this fraction of the edge away. A tenth of it took a second sample on most edges, for vertices a
hundred times closer than anyone sees (``implc bench --sections mesh``: the samples and the distance)."""
NUDGE = 1e-7
"""Each surface vertex moves along its edge by up to this fraction of the edge, by a hash of its key: the
construction holds for any place inside the edge, and the nudge breaks the exact coplanarity that a
surface aligned with the grid gives (walls of extrusions, faces of boxes), on which floating-point
intersection tests such as pymeshlab's report disjoint coplanar triangles as intersecting."""


def _endpoints(grid: Grid, keys: np.ndarray, cell_points: Points, face_points: Points):
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
            b_ax, c_ax = face_axes(ax)
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
            ids[on] = grid_face_ids(grid, cells[on], f // 2, f % 2)
        rows = face_points.find(ids)
        b[sel], fb[sel] = face_points.positions[rows], face_points.values[rows]
    return a, b, fa, fb


def _all_grid_edges(keys: np.ndarray) -> bool:
    """Whether every vertex key names the crossing on a grid edge (kind GRID, a code that is not 0)."""
    return not np.any((keys & 7 != GRID) | (keys & (7 << 3) == 0))


def surface_vertices(grid: Grid, keys: np.ndarray, cell_points: Points, face_points: Points, witnesses: bool):
    """Positions of the vertices named by ``keys`` (unique): a point itself, or the root of F on its edge
    (:func:`_edge_roots`). Returns (positions, unit normals (NaN at a point named by itself, and where F's
    gradient is not usable), witnesses: (V, 2, 3) the edge's ends, the one where F < 0 first, a point named
    by itself twice; None unless ``witnesses``). Done ``grid.effort.vertex_chunk`` keys at a time, so that the
    edges' ends, brackets and samples take memory for a chunk, not for the mesh."""
    n = len(keys)
    positions, normals = np.empty((n, 3)), np.empty((n, 3))
    ends = np.empty((n, 2, 3)) if witnesses else None
    chunk = grid.effort.vertex_chunk
    for start in range(0, n, chunk):
        rows = slice(start, min(n, start + chunk))
        _vertex_chunk(grid, keys[rows], cell_points, face_points, positions[rows], normals[rows],
                      None if ends is None else ends[rows])
    return positions, normals, ends


def _vertex_chunk(grid: Grid, keys, cell_points: Points, face_points: Points, positions, normals, ends):
    """:func:`surface_vertices` for one chunk of keys, written into ``positions``, ``normals`` and ``ends``
    (or None)."""
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


def _edge_roots(grid: Grid, keys, a, b, fa, fb, vertices: np.ndarray, normals: np.ndarray) -> None:
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
        normals[rows[:open_]] = unit_vectors(grid.gradients(guesses[:open_], grouping))


def unit_vectors(normals: np.ndarray) -> np.ndarray:
    """Gradients normalised in place (NaN where they are not usable)."""
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        normals /= np.sqrt(np.einsum("ij,ij->i", normals, normals))[:, None]  # np.linalg.norm: several times slower
    normals[np.flatnonzero(~np.isfinite(normals).all(1))] = np.nan
    return normals


def fill_normals(grid: Grid, normals, vertices, faces) -> np.ndarray:
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
        # only the triangles around those vertices (column by column: a boolean mask of (F, 3) is several times slower)
        faces = np.take(faces, np.flatnonzero(mask[faces[:, 0]] | mask[faces[:, 1]] | mask[faces[:, 2]]), axis=0)
        p = np.take(vertices, faces, axis=0)
        area = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        corners = faces.reshape(-1)
        summed = np.stack([np.bincount(corners, np.repeat(area[:, a], 3), minlength=len(vertices))
                           for a in range(3)], 1)[bad]
        with np.errstate(invalid="ignore", divide="ignore"):
            normals[bad] = summed / np.linalg.norm(summed, axis=1)[:, None]
    return normals
