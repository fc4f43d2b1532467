"""Contouring: the boundary of the solid {F < 0} within the bounds as a closed, oriented triangle mesh.

Two constructions share the grid's cells. A crossed cell whose sampled signs leave one sheet, away from
the bounds, is a *dual cell*: one vertex, dual contouring's quads between such cells, and the stitch to
the others (:mod:`implc.meshing.dual`, which says why nothing meets). Every other crossed cell (well under
one in a hundred on the paper's scenes: ambiguous sign patterns, the cells on the bounds) keeps the
*tetrahedral construction*, the zero set of the piecewise-linear function that takes F's sampled signs at
the vertices of a tetrahedralization of the grid, cut by the bounds' faces where the solid reaches them.
``lean=False`` uses the tetrahedral construction everywhere, as follows:

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
  box's face costs a few triangles per block edge instead of two per square.

What follows by construction for the tetrahedral cells, for any placement of the surface vertices strictly
inside their edges:
every edge of the mesh lies in exactly two triangles, consistently oriented (outward: from the negative
to the positive side); no two triangles meet except in a shared edge or vertex, since each triangle lies
in its own tetrahedron and meets the tetrahedron's faces only in the segments shared with its neighbours;
every vertex lies in a cell where F takes both signs at sampled points, so in a cell whose enclosure
contains 0 (the voxelizer keeps every such cell). Only the cells the voxelizer kept are visited, and any
cell that the sampled signs show the surface entering (``MeshStats.added_cells`` counts them, 0 when every
sample agrees with the enclosures), so the mesh is closed whatever the rounding of a single sample.

Vertex keys: every mesh vertex is named by an int64 whose low three bits say what it is (:data:`GRID`: a
grid corner or the crossing on a grid edge; :data:`FACE_CORNER`, :data:`CELL_CORNER`, :data:`FACE_CELL`:
the crossing on an edge from a face or cell point; :data:`FACE_POINT`: a face point on a cap;
:data:`implc.meshing.dual.CELL_POINT`: a dual cell's vertex), so that the cells that share a vertex name it
alike.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .caps import cap_triangles, close_over_reached_faces
from .dual import CELL_POINT, dual_rows, dual_triangles, dual_vertices, dual_witnesses
from .features import fan_triangles, feature_cells, place_points
from .grid import CORNERS_PER_CELL, NO_POINTS, Cells, Effort, Grid, KeyIndex, never
from .proofs import regular
from .simplify import SimplifyStats
from .vertices import fill_normals, surface_vertices, unit_vectors

MAX_DEPTH = 14
"""The deepest grid contoured: vertex keys hold (2^depth + 1)³ corners times 64 kinds of edge."""


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
    dual_cells: int = 0
    dual_counts: dict = field(default_factory=dict)
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
                f"crossed cells of {self.cells} kept ({self.dual_cells} dual, {self.feature_cells} feature cells, "
                f"{self.added_cells} "
                f"added by the signs, {self.cap_triangles} cap triangles; {self.regular_cells} proven regular, "
                f"{self.unproven_cells} unproven), {total:.3f} s")


def contour(surface, cells: np.ndarray, depth: int, bounds=None, *, features: bool = True, witnesses: bool = False,
            effort: Effort = Effort(), lean: bool = True):
    """The mesh of ``surface`` (an :class:`implc.Surface`) from the cells the voxelizer kept at ``depth``
    ((N, 3) cell indices): see the module's docstring for what it promises. ``features=False``: dual
    vertices at the mean of their crossings, not the QEF point (creases chamfered; with ``lean=False`` the
    Kuhn split everywhere). ``witnesses=True`` keeps, for each vertex, two points of one cell where F has
    opposite signs, the negative one first (``Mesh.witnesses``, (V, 2, 3)): the ends of the edge it was
    found on, or for a dual vertex (strictly inside its cell, off every such edge) the ends of an edge of
    its cell that changes sign; so that anyone can check where it lies. ``effort``: how the work is
    chunked and how far the proofs of regular cells look (:class:`implc.meshing.grid.Effort`; the mesh's
    promises hold for any). ``lean=False``: the tetrahedral construction in every cell (about three
    vertices a crossed cell; the feature cells fanned). Returns an :class:`implc.Mesh`."""
    if not 1 <= depth <= MAX_DEPTH:
        raise ValueError(f"meshes are made at depth 1 to {MAX_DEPTH}, not {depth}")
    from .triangle_mesh import Mesh
    stats = MeshStats()
    t0 = time.perf_counter()
    grid = Grid(surface, depth, surface.bounds if bounds is None else bounds, effort)
    runtime = grid.runtime
    cells = np.asarray(cells, dtype=np.int64).reshape(-1, 3)
    stats.cells = len(cells)
    grid.find_outside_faces(cells)
    grid.expect_corners(CORNERS_PER_CELL * len(cells) + grid.capped_faces() * grid.k**2)
    todo = Cells(grid, cells)
    caps, seeds = cap_triangles(grid, NO_POINTS, never)
    t1 = time.perf_counter()
    stats.added_cells = todo.close(seeds)
    added, caps_again = close_over_reached_faces(grid, todo, 0)
    stats.added_cells += added
    caps = caps if caps_again is None else caps_again
    crossed = np.flatnonzero(todo.crossed())
    stats.crossed_cells = len(crossed)
    # the dual cells' candidates number their edges' crossings; the others are split the Kuhn way
    candidates = np.flatnonzero(dual_rows(grid, todo)) if lean else np.zeros(0, np.int64)
    tetrahedral = np.setdiff1d(crossed, candidates, assume_unique=True) if len(candidates) else crossed
    # the vertices to come: about four a tetrahedral cell, a crossing and the cell's own a dual one (a
    # table sized for more costs its pages' first touch: a tenth of Scene 2's contouring at 256³)
    index = KeyIndex(runtime, 4 * len(tetrahedral) + 2 * len(candidates))
    kuhn, owner = index.kuhn_triangles(grid, todo.cells[tetrahedral], todo.signs[tetrahedral])
    np.take(tetrahedral, owner, out=owner, mode="clip")  # rows of todo.cells, in place (no fresh memory)
    edges = index.dual_edges(grid, todo.cells[candidates], todo.signs[candidates])
    caps = {face: index.number(triangles) for face, triangles in caps.items()}
    t2 = time.perf_counter()
    vertices, normals, ends = surface_vertices(grid, index.keys(), NO_POINTS, NO_POINTS, witnesses)
    t3 = time.perf_counter()
    # with dual cells a crease is their QEF vertices' (the few tetrahedral cells chamfer theirs: fanning
    # them would take their dual neighbours too, for thin triangles); without, the feature cells are fanned
    fanning = features and not lean
    feature_rows = feature_cells(runtime, todo.cells, kuhn, owner, normals) if fanning else np.zeros(0, np.int64)
    proven_rows = np.zeros(0, np.int64)  # rows of todo proven regular already (not proven again below)
    if len(feature_rows) and not surface.has_kinks:  # a smooth F: a crease only where its gradient may vanish
        bent_regular = regular(grid, todo.cells[feature_rows])
        proven_rows, feature_rows = feature_rows[bent_regular], feature_rows[~bent_regular]
    stats.feature_cells = len(feature_rows)
    mesh = _Pieces(vertices, normals, ends, kuhn, owner, caps)
    del vertices, normals, ends, kuhn, owner, caps  # the pieces hold them, and let each go once it is joined
    if len(feature_rows):  # only without dual cells
        stats.added_cells += _with_features(grid, todo, feature_rows, index, mesh)
    if len(candidates):
        stats.dual_cells, stats.dual_counts = _with_dual(grid, todo, candidates, edges, index, mesh, features)
    del edges
    del index
    grid.forget_samples()
    stats.cap_triangles = sum(map(len, mesh.caps.values()))
    vertices, normals, faces, ends = mesh.compacted()
    normals = fill_normals(grid, normals, vertices, faces)
    t4 = time.perf_counter()
    crossed = todo.crossed()
    crossed_count = int(np.count_nonzero(crossed))
    crossed[proven_rows] = False
    open_cells = todo.cells[crossed]
    unproven = open_cells[~regular(grid, open_cells)]
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
        if keep is None and not caps and not more:
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


def _with_features(grid, todo: Cells, feature_rows, index: KeyIndex, mesh: _Pieces) -> int:
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
    more, caps_again = close_over_reached_faces(grid, todo, before)
    added += more
    reached = caps_again is not None  # a face taken as outside that the fanned cells, or those the signs added, reach
    fanned = np.zeros(len(todo.cells), bool)
    fanned[todo.index.number(fanned_keys, insert=False)] = True
    cell_points, face_points = place_points(grid, feature_cells, grid.cell_unkey(fanned_keys), index,
                                             mesh.vertices, mesh.normals)
    first_new = index.count
    mesh.keep = ~fanned[mesh.owner]
    fresh = np.arange(before, len(todo.cells))
    fresh = fresh[~fanned[fresh] & todo.crossed()[before:]]  # added by the signs: Kuhn
    kuhn, owner = index.kuhn_triangles(grid, todo.cells[fresh], todo.signs[fresh])
    rows = np.flatnonzero(fanned)
    fan = fan_triangles(grid, index, todo.cells[rows], todo.signs[rows], is_feature(todo.cells[rows]),
                         cell_points, face_points, is_feature)
    mesh.more = [kuhn, fan]
    # the caps again where a feature cell lies on a face of the bounds (its square fanned from a face point)
    redo = {(axis, side) for axis in range(3) for side in (0, 1)
            if np.any(feature_cells[:, axis] == side * (grid.n - 1))}
    if redo or reached:
        caps = cap_triangles(grid, face_points, is_feature, None if reached else redo)[0]
        mesh.caps.update({face: index.number(triangles) for face, triangles in caps.items()})
    keys = index.keys()[first_new:]
    vertices, normals, ends = surface_vertices(grid, keys, cell_points, face_points, mesh.ends is not None)
    mesh.add_vertices(vertices, normals, ends)
    return added


def _with_dual(grid, todo: Cells, rows, edges, index: KeyIndex, mesh: _Pieces, sharp: bool):
    """One vertex for each dual cell (``rows`` of ``todo``, ``edges`` their crossings' vertex numbers) in
    ``mesh``, and their triangles; ``sharp``: QEF vertices (else the crossings' mean). Returns the dual
    cells and the dual construction's counts."""
    cells = todo.cells[rows]
    points = dual_vertices(grid, cells, edges, mesh.vertices, mesh.normals, sharp)
    first = index.count
    index.number(grid.cell_key(cells) * 8 + CELL_POINT)
    faces, counts = dual_triangles(grid, todo, rows, edges, first, points, index)
    mesh.more.append(faces)
    normals = unit_vectors(grid.gradients(points))
    ends = dual_witnesses(grid, cells, todo.signs[rows]) if mesh.ends is not None else None
    mesh.add_vertices(points, normals, ends)
    return len(rows), counts
