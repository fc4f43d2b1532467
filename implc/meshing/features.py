"""Feature cells, where the analytic normals at the surface's crossings disagree (a crease or corner of
Min/Max CSG): their cell and face points (dual contouring's QEF minimisers) and the fans around them. Every
added point is placed where its sampled sign agrees with one of its cell's (or face's) corners where a
place tried does (:func:`_joined`), so that the mesh's pieces are the grid samples' own."""

from __future__ import annotations

import numpy as np

from .grid import Grid, KeyIndex, Points, face_corner_keys, grid_edge_key, grid_face_ids, square_edge_key
from .tables import CORNERS, KUHN_EDGES, face_axes

FEATURE_COSINE = 0.985
"""A cell is a feature cell where the normal at one of its surface vertices meets the cell's mean normal
at a cosine below this (an angle above about 10°: a crease of 20° or more)."""
QEF_CUTOFF = 0.01
"""Singular values of a QEF below this fraction of the largest are dropped (the point stays near the mean
along those directions)."""
POINT_MARGIN = 1.0 / 32
"""Cell and face points stay this fraction of the cell inside their cell or face."""
NEAR_CORNER = 1.0 / 8
"""Where a point's sign meets none of its corners', it is tried this fraction of the way from each corner
toward the centre instead (1/16 of the cell from the corner along each axis: inside the margin)."""


def _joined(grid: Grid, points: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """``points`` (m, 3), each moved where F's sampled sign there agrees with the sign at one of its
    ``corners`` (m, k, 3) at least, if it does not already: the centre of the corners first, then near
    each corner in turn. A point whose sign meets none of its neighbours' would be a closed bubble of a few
    triangles around it, a sign change of F at the point alone that the grid's samples do not show (Scene
    2 had 298 of its 318 components so); a point that agrees with a corner shares its side's component.
    Where no try agrees (F changes sign between every corner and the point), the point stays."""
    m, k, _ = corners.shape
    corner_in = grid.values(corners.reshape(-1, 3)).reshape(m, k) < 0  # NaN: outside, as the mesher takes it
    lonely = np.flatnonzero(~np.any(corner_in == (grid.values(points) < 0)[:, None], axis=1))
    if not len(lonely):
        return points
    points = points.copy()
    centre = corners.mean(axis=1)
    tries = [centre] + [corners[:, c] + (centre - corners[:, c]) * NEAR_CORNER for c in range(k)]
    for t in tries:
        if not len(lonely):
            break
        inside = grid.values(t[lonely]) < 0
        agree = np.any(corner_in[lonely] == inside[:, None], axis=1)
        points[lonely[agree]] = t[lonely[agree]]
        lonely = lonely[~agree]
    return points


def fan_triangles(grid: Grid, index: KeyIndex, cells, signs, feature, cell_points: Points,
                   face_points: Points, is_feature):
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
            face_in[sel, face] = face_points.inside[face_points.find(grid_face_ids(grid, cells[sel], axis, side))]
    return index.fan_triangles(grid, cells, signs, cell_in, face_in, split)


def _qef(runtime, points, normals, mask, project_out=None):
    """Dual contouring's point per row: the least-squares meeting point of the tangent planes (points
    (m, k, 3), unit normals, ``mask`` which are present), solved around their mean with eigenvalues below
    :data:`QEF_CUTOFF` of the largest dropped. ``project_out``: an axis whose normal component is removed
    first (a face's 2D QEF). Native (``implc_qef``: Jacobi's rotations per row; numpy's eigendecomposition
    costs a call per row)."""
    m, k = mask.shape
    points = np.ascontiguousarray(points, dtype=np.float64)
    normals = np.ascontiguousarray(normals, dtype=np.float64)
    flags = np.ascontiguousarray(mask, dtype=np.uint8)
    out = np.empty((m, 3))
    runtime.qef(points.ctypes.data, normals.ctypes.data, flags.ctypes.data, m, k,
                -1 if project_out is None else project_out, QEF_CUTOFF, out.ctypes.data)
    return out


def feature_cells(runtime, cells, faces, tri_owner, normals):
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


def _edge_data(index: KeyIndex, keys, positions, normals):
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


def place_points(grid, feature_cells, fanned_cells, index: KeyIndex, positions, normals):
    """Cell points (the QEF point of each feature cell, the centre of every other fanned cell) and face
    points (the face's 2D QEF point, for every face of a feature cell), kept inside their cells and faces."""
    corner_keys = grid.key(feature_cells)[:, None] + grid.key(CORNERS)
    keys = np.stack([grid_edge_key(corner_keys[:, u], code) for u, code in KUHN_EDGES], 1)
    p, nrm, ok = _edge_data(index, keys, positions, normals)
    lo = grid.world(feature_cells)
    hi = grid.world(feature_cells + 1)
    margin = (hi - lo) * POINT_MARGIN
    qef = np.clip(_qef(grid.runtime, p, nrm, ok), lo + margin, hi - margin)
    qef = np.where(ok.any(1)[:, None], qef, (lo + hi) / 2)
    qef = _joined(grid, qef, grid.world(feature_cells[:, None] + CORNERS[None]))
    others = fanned_cells
    centres = _joined(grid, (grid.world(others) + grid.world(others + 1)) / 2,
                      grid.world(others[:, None] + CORNERS[None]))
    ids = np.concatenate([grid.cell_key(feature_cells), grid.cell_key(others)])
    first = np.unique(ids, return_index=True)[1]  # a feature cell's QEF point wins over its centre
    cell_points = Points(grid, ids[first], np.concatenate([qef, centres])[first])

    face_ids, face_pos = [], []
    for axis in range(3):
        b, c = face_axes(axis)
        for side in (0, 1):
            ids = grid_face_ids(grid, feature_cells, axis, side)
            _, corner_keys = face_corner_keys(grid, feature_cells, axis, side)
            pairs = [(0, 1), (1, 2), (3, 2), (0, 3), (0, 2)]
            keys = np.stack([square_edge_key(corner_keys, axis, i, j) for i, j in pairs], 1)
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
            square = feature_cells + side * np.eye(3, dtype=np.int64)[axis]
            steps = np.zeros((4, 3), np.int64)
            steps[[1, 2], b] = 1
            steps[[2, 3], c] = 1
            point = _joined(grid, point, grid.world(square[:, None] + steps[None]))
            face_ids.append(ids)
            face_pos.append(point)
    ids, first = np.unique(np.concatenate(face_ids), return_index=True)
    face_points = Points(grid, ids, np.concatenate(face_pos)[first])
    return cell_points, face_points
