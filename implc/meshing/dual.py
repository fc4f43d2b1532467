"""One vertex per crossed cell where that is safe: dual contouring on the cells whose corner signs leave one
sheet, stitched to the cells that keep the tetrahedral construction.

A *dual cell* is a crossed cell, not on the bounds' outer layer and not fanned for a feature, whose inside
corners are edge-connected and whose outside corners are too (:data:`MANIFOLD`: 126 of the 254 crossed
configurations, OpenVDB's ``sAdaptable`` less the two uncrossed ones): no face of it is ambiguous, each
face carries at most one segment of the contour, and one vertex serves the cell. The vertex is the QEF
point of its edges' crossings (dual contouring's least-squares meeting point of their tangent planes),
clamped :data:`DUAL_MARGIN` inside the cell, so creases stay sharp where the cell allows.

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

from .grid import Cells, Grid, KeyIndex, grid_edge_key, square_edge_key
from .tables import CORNERS, SQUARE, face_axes, face_shapes

CELL_POINT = 5
"""The kind of a dual vertex's key (see :mod:`implc.meshing.contour`): the cell's key × 8 + 5."""
DUAL_MARGIN = 1.0 / 256
"""A dual vertex stays this fraction of its cell inside every face of it (as a surface vertex stays inside
its edge): a face of the solid on a grid plane moves that little inward; and a file's float32 rounding
keeps the vertex inside its cell wherever a cell spans 2^9 float32 steps of its coordinates or more."""
ORIENT_ERROR = 1e-15
"""A filtered orientation's sign is taken only where |det| exceeds this times its permanent (Shewchuk's
bound for a 3×3 determinant of rounded differences is about 7.8e-16)."""


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


def dual_rows(grid: Grid, todo: Cells, other: np.ndarray) -> np.ndarray:
    """Which rows of ``todo`` are dual cells: crossed, in :data:`MANIFOLD`, not on the bounds' outer layer
    (their faces there hold caps), not ``other`` (rows that keep the tetrahedral construction)."""
    signs = todo.signs
    inner = np.all((todo.cells > 0) & (todo.cells < grid.n - 1), axis=1)
    dual = MANIFOLD[signs] & (signs != 0) & (signs != 0xFF) & inner
    dual[: len(other)] &= ~other
    return dual


def _orientation_signs(a, b, c, p):
    """The sign of ((b − a) × (c − a)) · (p − a) per row where the doubles certify it, else 0."""
    u, v, w = b - a, c - a, p - a
    cross = np.cross(u, v)
    det = np.einsum("ij,ij->i", cross, w)
    perm = (np.abs(w[:, 0]) * (np.abs(u[:, 1] * v[:, 2]) + np.abs(u[:, 2] * v[:, 1]))
            + np.abs(w[:, 1]) * (np.abs(u[:, 0] * v[:, 2]) + np.abs(u[:, 2] * v[:, 0]))
            + np.abs(w[:, 2]) * (np.abs(u[:, 0] * v[:, 1]) + np.abs(u[:, 1] * v[:, 0])))
    sure = np.abs(det) > ORIENT_ERROR * perm
    return np.where(sure, np.sign(det), 0)


def _splits(v0, v1, v2, v3, p1, p2):
    """Whether the quad v0 v1 v2 v3 (counter-clockwise about p1 → p2) may be split along v0 v2: both its
    triangles have p2 strictly above and p1 strictly below (Ju and Udeshi's test)."""
    ok = np.ones(len(v0), bool)
    for a, b, c in ((v0, v1, v2), (v0, v2, v3)):
        ok &= (_orientation_signs(a, b, c, p2) > 0) & (_orientation_signs(a, b, c, p1) < 0)
    return ok


def _float32(points):
    return points.astype(np.float32).astype(np.float64)


def dual_vertices(grid: Grid, cells: np.ndarray, index: KeyIndex, positions, normals, qef):
    """Each dual cell's vertex: the QEF point of its grid edges' crossings (``positions``, ``normals``:
    the vertices numbered in ``index``; ``qef(points, normals, present)``: the solver, None for the mean
    of the crossings), :data:`DUAL_MARGIN` inside the cell (its centre where no crossing has a usable
    normal)."""
    corner_keys = grid.key(cells)[:, None] + grid.key(CORNERS)
    keys = np.stack([grid_edge_key(corner_keys[:, u], 1 << a) for u in range(8) for a in range(3)
                     if not u >> a & 1], 1)
    rows = index.number(keys, insert=False)
    present: np.ndarray = rows >= 0
    np.maximum(rows, 0, out=rows)
    p, n = np.take(positions, rows, axis=0), np.take(normals, rows, axis=0)
    ok = present & ~np.isnan(n[..., 0])
    n[~ok] = 0
    lo, hi = grid.world(cells), grid.world(cells + 1)
    margin = (hi - lo) * DUAL_MARGIN
    if qef is None:  # the mean of the crossings (creases chamfered)
        mean = np.einsum("ijk,ij->ik", p, present) / np.maximum(present.sum(1), 1)[:, None]
        crossed = np.asarray(present.any(1))
        return np.clip(np.where(crossed[:, None], mean, (lo + hi) / 2), lo + margin, hi - margin)
    point = np.clip(qef(p, n, ok), lo + margin, hi - margin)
    return np.where(ok.any(1)[:, None], point, (lo + hi) / 2)


def dual_triangles(grid: Grid, todo: Cells, dual: np.ndarray, numbers: np.ndarray, points: np.ndarray,
                   index: KeyIndex) -> tuple[np.ndarray, dict]:
    """The dual cells' triangles (see the module docstring): ``numbers``/``points``, per row of ``todo``,
    its dual vertex's number and position (rows not dual: −1); roots and face crossings are the vertices
    ``index`` numbers already. Returns (triangles (T, 3), counts of quads, split quads and fans)."""
    rows = np.flatnonzero(dual)
    cells, signs = todo.cells[rows], todo.signs[rows]
    out = []
    counts = {"quads": 0, "fanned edges": 0, "stitched edges": 0, "cones": 0}
    # every sign-changing edge of a dual cell, once (its lowest corner and axis)
    pieces = []
    for axis in range(3):
        for u in range(8):
            if u >> axis & 1:
                continue
            changes = (signs >> u & 1) != (signs >> (u | 1 << axis) & 1)
            corners = cells[changes] + CORNERS[u]
            pieces.append(grid.key(corners) * 3 + axis)
    edge_ids = np.unique(np.concatenate(pieces))
    lowest, axes = grid.unkey(edge_ids // 3), edge_ids % 3
    for axis in range(3):
        on = axes == axis
        p = lowest[on]
        if not len(p):
            continue
        b, c = (axis + 1) % 3, (axis + 2) % 3
        ring = np.empty((len(p), 4), np.int64)  # counter-clockwise about +axis
        for k, (db, dc) in enumerate(((0, 0), (1, 0), (1, 1), (0, 1))):
            cell = p.copy()
            cell[:, b] -= db
            cell[:, c] -= dc
            ring[:, k] = todo.index.number(grid.cell_key(cell), insert=False)
        if np.any(ring < 0):
            raise AssertionError("a dual cell's edge with a cell around it that is not contoured")
        inside_low = (todo.signs[ring[:, 0]] & 1).astype(bool)  # the edge's lowest corner is corner 0 of ring 0
        v = numbers[ring]
        is_dual = v >= 0
        root = index.number(grid_edge_key(grid.key(p), 1 << axis), insert=False)
        if np.any(root < 0):
            raise AssertionError("a sign-changing edge without its root")
        lean = is_dual.all(1)
        # quads: Ju and Udeshi's diagonal test on the doubles and on float32
        q = np.flatnonzero(lean)
        pos = points[ring[q]]
        p1, p2 = grid.world(p[q]), grid.world(p[q] + np.eye(3, dtype=np.int64)[axis])
        first = _splits(pos[:, 0], pos[:, 1], pos[:, 2], pos[:, 3], p1, p2)
        second = _splits(pos[:, 1], pos[:, 2], pos[:, 3], pos[:, 0], p1, p2)
        pos32, p1_32, p2_32 = _float32(pos), _float32(p1), _float32(p2)
        first &= _splits(pos32[:, 0], pos32[:, 1], pos32[:, 2], pos32[:, 3], p1_32, p2_32)
        second &= _splits(pos32[:, 1], pos32[:, 2], pos32[:, 3], pos32[:, 0], p1_32, p2_32)
        shorter = (np.einsum("ij,ij->i", pos[:, 0] - pos[:, 2], pos[:, 0] - pos[:, 2])
                   <= np.einsum("ij,ij->i", pos[:, 1] - pos[:, 3], pos[:, 1] - pos[:, 3]))
        use_first = first & (shorter | ~second)
        use_second = second & ~use_first
        vq = v[q]
        for sel, (i, j, k, m) in ((use_first, (0, 1, 2, 3)), (use_second, (1, 2, 3, 0))):
            s = np.flatnonzero(sel)
            flip = ~inside_low[q[s]]
            out += [_oriented(np.stack([vq[s, i], vq[s, j], vq[s, k]], 1), flip),
                    _oriented(np.stack([vq[s, i], vq[s, k], vq[s, m]], 1), flip)]
        counts["quads"] += int(np.count_nonzero(use_first | use_second))
        fanned = np.zeros(len(p), bool)
        fanned[q[~(use_first | use_second)]] = True
        counts["fanned edges"] += int(np.count_nonzero(fanned))
        counts["stitched edges"] += int(np.count_nonzero(~lean))
        # fans about the root: every pair of dual cells across a face of a fanned or stitched edge
        for k in range(4):
            pair = np.flatnonzero((fanned | ~lean) & is_dual[:, k] & is_dual[:, (k + 1) % 4])
            tri = np.stack([root[pair], v[pair, k], v[pair, (k + 1) % 4]], 1)
            out.append(_oriented(tri, ~inside_low[pair]))
    # cones over the faces toward the other construction's cells
    for axis in range(3):
        b, c = face_axes(axis)
        for side in (0, 1):
            local = [(side << axis) | (du << b) | (dv << c) for du, dv in SQUARE]
            face_signs = np.stack([(signs >> corner) & 1 for corner in local], 1).astype(bool)
            crossed = face_signs.any(1) & ~face_signs.all(1)
            neighbour = cells.copy()
            neighbour[:, axis] += 1 if side else -1
            across = todo.index.number(grid.cell_key(neighbour), insert=False)
            sel = np.flatnonzero(crossed & ~((across >= 0) & dual[np.maximum(across, 0)]))
            if not len(sel):
                continue
            if np.any(across[sel] < 0):
                raise AssertionError("a dual cell's crossed face toward a cell that is not contoured")
            corner_keys = grid.key(cells[sel])[:, None] + grid.key(CORNERS[local])
            apex = numbers[rows[sel]]
            for shape in face_shapes(axis, side, False):  # counter-clockwise seen from outside the cell
                ks = [k for _, k in shape]
                inside = face_signs[sel][:, ks]
                s = np.flatnonzero(inside.any(1) & ~inside.all(1))
                if not len(s):
                    continue
                inside = inside[s]
                # walking the triangle counter-clockwise, the contour enters the inside across one edge and
                # leaves across another: the cone is (apex, entry, exit)
                keys = np.stack([square_edge_key(corner_keys[s], axis, ks[e], ks[(e + 1) % 3]) for e in range(3)], 1)
                enters = np.stack([~inside[:, e] & inside[:, (e + 1) % 3] for e in range(3)], 1).argmax(1)
                leaves = np.stack([inside[:, e] & ~inside[:, (e + 1) % 3] for e in range(3)], 1).argmax(1)
                pick = np.arange(len(s))
                entry = index.number(keys[pick, enters], insert=False)
                exit_ = index.number(keys[pick, leaves], insert=False)
                if np.any(entry < 0) or np.any(exit_ < 0):
                    raise AssertionError("a face crossing that the other construction did not number")
                out.append(np.stack([apex[s], entry, exit_], 1))
                counts["cones"] += len(s)
    faces = np.concatenate(out) if out else np.zeros((0, 3), np.int64)
    return faces, counts


def _oriented(triangles: np.ndarray, flip: np.ndarray) -> np.ndarray:
    triangles[flip] = triangles[flip][:, ::-1]
    return triangles


def dual_witnesses(grid: Grid, cells: np.ndarray, signs: np.ndarray) -> np.ndarray:
    """(m, 2, 3): for each dual cell, an inside and an outside corner of a sign-changing edge of it."""
    out = np.empty((len(cells), 2, 3))
    found = np.zeros(len(cells), bool)
    for u in range(8):
        for axis in range(3):
            if u >> axis & 1:
                continue
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
