"""The contouring's tables, built once at import: the Kuhn split's tetrahedra and their cases, the fans of
feature cells over their faces, the caps' polygons, the dual cells' edges, rings and faces (the native
cells read them packed)."""

from __future__ import annotations

import itertools

import numpy as np

from ..native import abi

GRID, FACE_CORNER, CELL_CORNER, FACE_CELL, FACE_POINT = range(5)


CORNERS = np.array([[(c >> a) & 1 for a in range(3)] for c in range(8)], dtype=np.int64)
"""A cell's local corner c sits at offset (c & 1, c >> 1 & 1, c >> 2 & 1)."""
SQUARE = ((0, 0), (1, 0), (1, 1), (0, 1))
"""A face's corners in order around it, as steps along its two axes (in increasing order of axis)."""


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


def face_axes(axis: int) -> tuple[int, int]:
    b, c = [a for a in range(3) if a != axis]
    return b, c


def reversed_face(axis: int, side: int) -> bool:
    """Whether a face's corners in :data:`SQUARE` order run clockwise seen from outside a cell that has the
    face on ``side`` (0: its lower face on ``axis``)."""
    b, c = face_axes(axis)
    return float(np.cross(np.eye(3)[b], np.eye(3)[c]) @ np.eye(3)[axis]) * (1 if side else -1) < 0


def square_edge(axis: int, i: int, j: int) -> tuple[int, int]:
    """The edge between square corners i and j of a face on ``axis`` (adjacent, or the diagonal 0-2) as a
    grid edge: its lower square corner and its code (a bit per axis it steps along)."""
    b, c = face_axes(axis)
    lo, hi = (i, j) if all(p <= q for p, q in zip(SQUARE[i], SQUARE[j])) else (j, i)
    du, dv = SQUARE[hi][0] - SQUARE[lo][0], SQUARE[hi][1] - SQUARE[lo][1]
    return lo, (du << b) | (dv << c)


def face_shapes(axis: int, side: int, split: bool):
    """The triangles of a cell's face on (axis, side), counter-clockwise seen from outside the cell: three
    vertices each, ("c", square corner) or ("f", 0) for the face point; fanned from the face point where
    ``split``, else cut by the diagonal 0-2."""
    if split:
        shapes = tuple((("f", 0), ("c", k), ("c", (k + 1) % 4)) for k in range(4))
    else:
        shapes = ((("c", 0), ("c", 1), ("c", 2)), (("c", 0), ("c", 2), ("c", 3)))
    return [(shape[0], shape[2], shape[1]) if reversed_face(axis, side) else shape for shape in shapes]


def _fan_face_tables() -> np.ndarray:
    """:func:`implc.meshing.contour_native.emit_fan_triangles`'s tables (:data:`implc.native.abi.FAN_TABLES`): the
    faces, :data:`FAN_COUNT`, :data:`FAN_EDGES`, then per (face, split) its triangles, each with its corners'
    inside flags and the six keys of its fan tetrahedron in :data:`FAN_PAIRS` order (the spokes from the
    cell point to its three vertices, then its edges 0-1, 1-2, 2-0), named as :func:`_face_triangles` and
    :func:`square_edge_key` name them."""
    faces, shapes = [], []
    for axis in range(3):
        b, c = face_axes(axis)
        for side in (0, 1):
            face = 2 * axis + side
            faces += [axis, side << axis]
            local = [(side << axis) | (du << b) | (dv << c) for du, dv in SQUARE]
            for split in (False, True):
                rows = []
                for shape in face_shapes(axis, side, split):
                    # a key's slot among the cell's: grid edges 0-63, face corners 64-87, cell corners 88-95,
                    # face cells 96-101
                    flags = [local[k] if kind == "c" else 8 for kind, k in shape]
                    keys = [(CELL_CORNER, local[k], 0, 88 + local[k]) if kind == "c"
                            else (FACE_CELL, face, 0, 96 + face) for kind, k in shape]
                    for v in range(3):
                        (ka, i), (kb, j) = shape[v], shape[(v + 1) % 3]
                        if ka == "c" and kb == "c":
                            lo, code = square_edge(axis, i, j)
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


CELL_EDGES = [(u, a) for u in range(8) for a in range(3) if not u >> a & 1]
"""A cell's 12 edges as (lower corner, axis), in the order dual cells list their crossings."""
RING = ((0, 0), (1, 0), (1, 1), (0, 1))
"""The four cells around an edge along axis a, counter-clockwise about +a: the steps back along the axes
(a + 1, a + 2) from the edge's lower corner to each cell's lowest corner."""
EDGE_ROW = 15
"""Words per edge in :data:`DUAL_PACKED`."""
SHAPE_ROW = 12
"""Words per face triangle in :data:`DUAL_PACKED`."""
FACE_ROW = 6 + 2 * SHAPE_ROW
"""Words per face in :data:`DUAL_PACKED`."""
FACE_ROW_START = 12 * EDGE_ROW
"""Where the faces start in :data:`DUAL_PACKED`."""


def _dual_tables() -> np.ndarray:
    """``implc_dual_triangles``' tables: per edge of :data:`CELL_EDGES` (:data:`EDGE_ROW` words) its lower
    corner, axis, the cell's own place in :data:`RING`, then the four ring cells' steps from the cell; per
    face (:data:`FACE_ROW` words, from :data:`FACE_ROW_START`) its axis, side and four corners, then its two
    triangles of the tetrahedral split (counter-clockwise seen from outside the cell), each its three
    corners and, per side from corner i to i + 1, the cell edge it lies on (−1 for the face's diagonal)
    with that side's lower corner and code."""
    words: list[int] = []
    for u, a in CELL_EDGES:
        b, c = (a + 1) % 3, (a + 2) % 3
        mine = (u >> b & 1, u >> c & 1)
        words += [u, a, RING.index(mine)]
        for ob, oc in RING:
            step = [0, 0, 0]
            step[b], step[c] = mine[0] - ob, mine[1] - oc
            words += step
    for axis in range(3):
        b, c = face_axes(axis)
        for side in (0, 1):
            local = [(side << axis) | (du << b) | (dv << c) for du, dv in SQUARE]
            words += [axis, side, *local]
            for shape in face_shapes(axis, side, False):
                ks = [k for _, k in shape]
                words += [local[k] for k in ks]
                for i in range(3):
                    lo, code = square_edge(axis, ks[i], ks[(i + 1) % 3])
                    single = code & (code - 1) == 0
                    edge = CELL_EDGES.index((local[lo], code.bit_length() - 1)) if single else -1
                    words += [edge, local[lo], code]
    assert len(words) == FACE_ROW_START + 6 * FACE_ROW
    return np.array(words, dtype=np.int64)


DUAL_PACKED = _dual_tables()
"""The tables as ``implc_dual_triangles`` reads them."""
CELL_EDGE_PACKED = np.array([u for u, _ in CELL_EDGES] + [1 << a for _, a in CELL_EDGES], dtype=np.int64)
"""The 12 edges' lower corners, then their codes, as ``implc_dual_edges`` reads them."""
