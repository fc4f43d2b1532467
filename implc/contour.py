"""Contouring: the boundary of the solid {F < 0} within the bounds as a closed, oriented triangle mesh.

The mesh is the zero set of the piecewise-linear function that takes F's sampled values at the vertices
of a tetrahedralization of the voxel grid, cut by the bounds' faces where the solid reaches them:

- **the tetrahedralization**: each cell is split into the six Kuhn (Freudenthal) tetrahedra around its
  main diagonal; the split is the same in every cell, so neighbours agree on their shared faces. A cell
  whose sign pattern says a crease or corner of F runs through it (its edge crossings' gradients
  disagree) is split instead into a fan from a *feature point* inside it (dual contouring's QEF
  minimiser, kept strictly inside the cell) over its faces, each face fanned from a feature point of its
  own where a feature crosses it. Every such split is a valid tetrahedralization of the grid.
- **marching tetrahedra** over it: each tetrahedron whose vertices' signs differ holds one triangle or
  one quadrilateral (two triangles, split along the diagonal that keeps them on their sides). Each
  surface vertex lies on a tetrahedron edge whose ends have opposite signs, at the root found there by
  regula falsi, kept a little inside the edge.
- **the caps**: each face of the bounds, triangulated as the tetrahedra's faces there, contributes the
  part where the sampled F is negative, so the mesh is closed where the solid meets the bounds.

What follows by construction, for any placement of the surface vertices strictly inside their edges:
every edge of the mesh lies in exactly two triangles, consistently oriented (outward: the normal
points from the negative to the positive side); no two triangles meet except in a shared edge or vertex,
since each triangle lies in its own tetrahedron and meets the tetrahedron's faces only in the segments
shared with its neighbours; every vertex lies in a cell where F takes both signs at sampled points, so
a cell whose enclosure contains 0 (the voxelizer keeps every such cell; :func:`contour` counts any it
had to add). Only the cells the voxelizer kept are visited; any cell that the sampled signs show the
surface leaving into is added, so the mesh is closed whatever the rounding of single samples.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, field

import numpy as np

EDGE_MARGIN = 1.0 / 256
"""How far inside its edge (as a fraction of the edge) a surface vertex is kept: no triangle degenerates."""
ROOT_STEPS = 3
"""Regula falsi steps (Illinois) refining each surface vertex along its edge."""
NUDGE = 1e-7
"""Each surface vertex moves along its edge by up to this fraction of the edge, by a hash of its key: the
construction holds for any place inside the edge, and the nudge breaks the exact coplanarity that a
surface aligned with the grid gives (walls of extrusions, faces of boxes), on which floating-point
intersection tests such as pymeshlab's report disjoint coplanar triangles as intersecting."""

CORNERS = np.array([[(c >> a) & 1 for a in range(3)] for c in range(8)], dtype=np.int64)
"""A cell's local corner c sits at offset (c & 1, c >> 1 & 1, c >> 2 & 1)."""


@dataclass
class MeshStats:
    """What a contouring did: cells, triangles, the cells it had to add, seconds per stage."""
    cells: int = 0
    crossed_cells: int = 0
    added_cells: int = 0
    cap_triangles: int = 0
    triangles: int = 0
    vertices: int = 0
    seconds: dict = field(default_factory=dict)

    def summary(self) -> str:
        total = self.seconds.get("total", 0.0)
        return (f"{self.triangles} triangles, {self.vertices} vertices from {self.crossed_cells} crossed cells "
                f"of {self.cells} kept ({self.added_cells} added by the signs, {self.cap_triangles} cap "
                f"triangles), {total:.3f} s")


# -- tables ------------------------------------------------------------------------------------------
def _oriented_triangles(points: np.ndarray) -> list[list[list[tuple[int, int]]]]:
    """For a tetrahedron with vertex positions ``points`` (4, 3), and each of the 16 sign cases (bit k
    set: vertex k inside), the zero set's triangles as triples of edges (inside vertex, outside vertex),
    ordered so that each triangle's normal points away from the inside.

    The orientation does not depend on where on its edge each vertex lies: the plane of every triangle
    separates the tetrahedron's inside vertices from its outside ones, so it is read off the midpoints."""
    table = []
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


def _cap_tables():
    """For each face of the bounds (axis, side): its cells' two triangles as 3D corner offsets, ordered
    counter-clockwise seen from outside, and for each of the 8 sign cases of a triangle the polygon of its
    inside part, fanned into triangles whose vertices are (corner i, corner j): the corner itself where
    i == j, else the crossing on edge i-j."""
    faces = {}
    for axis in range(3):
        b, c = [a for a in range(3) if a != axis]
        e_b, e_c = np.eye(3, dtype=np.int64)[b], np.eye(3, dtype=np.int64)[c]
        square = [np.zeros(3, np.int64), e_b, e_b + e_c, e_c]  # the diagonal 0-2 is the Kuhn one
        for side in (0, 1):
            normal = np.eye(3)[axis] * (1 if side else -1)
            triangles = []
            for tri in ((0, 1, 2), (0, 2, 3)):
                pts = [square[k] for k in tri]
                if np.cross(pts[1] - pts[0], pts[2] - pts[0]) @ normal < 0:
                    pts = [pts[0], pts[2], pts[1]]
                triangles.append(np.array(pts))
            faces[axis, side] = triangles
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
    return faces, polygons


CAP_FACES, CAP_POLYGONS = _cap_tables()


# -- the grid ----------------------------------------------------------------------------------------
class _Grid:
    """The 2^depth grid over the bounds: corner keys, world positions, F's sampled signs."""

    def __init__(self, surface, depth: int, bounds):
        self.surface = surface
        self.n = 1 << depth
        self.k = self.n + 1  # corners per axis
        self.lo = np.array([float(lo) for lo, _ in bounds])
        self.hi = np.array([float(hi) for _, hi in bounds])
        self.step = (self.hi - self.lo) / self.n

    def key(self, ijk: np.ndarray) -> np.ndarray:
        return (ijk[..., 0] * self.k + ijk[..., 1]) * self.k + ijk[..., 2]

    def unkey(self, key: np.ndarray) -> np.ndarray:
        return np.stack([key // (self.k * self.k), key // self.k % self.k, key % self.k], axis=-1)

    def world(self, ijk: np.ndarray) -> np.ndarray:
        """World coordinates of corner indices (the last corner of an axis is its upper bound exactly)."""
        ijk = np.asarray(ijk)
        return np.where(ijk == self.n, self.hi, self.lo + ijk * self.step)

    def values(self, points: np.ndarray) -> np.ndarray:
        return self.surface.eval(np.ascontiguousarray(points.reshape(-1, 3), dtype=np.float64))

    def inside(self, ijk: np.ndarray) -> np.ndarray:
        """Whether the sampled F is negative at each corner (NaN counts as outside)."""
        return (self.values(self.world(ijk)) < 0).reshape(ijk.shape[:-1])


def _cell_keys(grid: _Grid, cells: np.ndarray) -> np.ndarray:
    return (cells[:, 0] * grid.n + cells[:, 1]) * grid.n + cells[:, 2]


def _close(grid: _Grid, cells: np.ndarray, inside: np.ndarray, seeds: np.ndarray):
    """Add to ``cells`` the ``seeds`` and every cell that the surface of the sampled signs enters from them
    across a face, until none is missing. Returns (cells, inside, how many were added)."""
    added, start, pending = 0, 0, seeds
    while True:
        candidates = [pending]
        fresh_inside = inside[start:]
        crossed = fresh_inside.any(1) & ~fresh_inside.all(1)
        for axis in range(3):
            for side in (0, 1):
                face = [c for c in range(8) if (c >> axis) & 1 == side]
                sub = fresh_inside[:, face]
                neighbours = cells[start:][crossed & sub.any(1) & ~sub.all(1)].copy()
                neighbours[:, axis] += 1 if side else -1
                candidates.append(neighbours[(neighbours[:, axis] >= 0) & (neighbours[:, axis] < grid.n)])
        start = len(cells)
        keys = np.unique(_cell_keys(grid, np.concatenate(candidates)))
        known = np.sort(_cell_keys(grid, cells))
        if len(known):
            keys = keys[known[np.minimum(np.searchsorted(known, keys), len(known) - 1)] != keys]
        if not len(keys):
            return cells, inside, added
        fresh = np.stack([keys // (grid.n * grid.n), keys // grid.n % grid.n, keys % grid.n], 1)
        cells = np.concatenate([cells, fresh])
        inside = np.concatenate([inside, grid.inside(fresh[:, None, :] + CORNERS)])
        added += len(fresh)
        pending = np.zeros((0, 3), np.int64)


def _tet_triangles(grid: _Grid, cells: np.ndarray, inside: np.ndarray) -> np.ndarray:
    """Marching tetrahedra over the Kuhn split of each cell: the triangles' vertex keys, (T, 3)."""
    corner_keys = grid.key(cells)[:, None] + grid.key(CORNERS)  # (n, 8)
    bits = inside.astype(np.int64)
    out = []
    rows = np.arange(len(cells))
    for t, tet in enumerate(KUHN_TETS):
        case = bits[:, tet[0]] | bits[:, tet[1]] << 1 | bits[:, tet[2]] << 2 | bits[:, tet[3]] << 3
        count = KUHN_COUNT[t, case]
        for slot in (0, 1):
            sel = count > slot
            c = case[sel]
            corner = KUHN_CORNER[t, c, slot]  # (m, 3)
            code = KUHN_CODE[t, c, slot]
            out.append(corner_keys[rows[sel][:, None], corner] * 8 + code)
    return np.concatenate(out) if out else np.zeros((0, 3), np.int64)


def _cap_triangles(grid: _Grid):
    """The bounds' faces where the sampled F is negative, as triangles of vertex keys (T, 3), and the
    cells beside them whose face there has both signs (they must be contoured too)."""
    out, seeds = [], []
    n = grid.n
    u, v = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    for (axis, side), triangles in CAP_FACES.items():
        b, c = [a for a in range(3) if a != axis]
        ijk = np.zeros((n + 1, n + 1, 3), np.int64)
        ijk[..., axis] = side * n
        ijk[..., b], ijk[..., c] = u, v
        inside = grid.inside(ijk)
        if not inside.any():
            continue
        base = ijk[:-1, :-1].reshape(-1, 3)  # each face cell's lowest corner
        corner_in = {}
        for tri in triangles:
            flags = np.stack([inside[(base[:, b] + o[b]), (base[:, c] + o[c])] for o in tri], 1)
            case = flags[:, 0] | flags[:, 1].astype(np.int64) << 1 | flags[:, 2].astype(np.int64) << 2
            keys = grid.key(base[:, None, :] + tri[None])  # (m, 3) corner keys
            for polygon_case in range(1, 8):
                sel = case == polygon_case
                if not sel.any():
                    continue
                for triple in CAP_POLYGONS[polygon_case]:
                    cols = [_cap_vertex_key(keys[sel], tri, i, j) for i, j in triple]
                    out.append(np.stack(cols, 1))
            for k, o in enumerate(tri):
                corner_in.setdefault(tuple(o), flags[:, k])
        flags = np.stack(list(corner_in.values()), 1)
        mixed = flags.any(1) & ~flags.all(1)
        cell = base[mixed].copy()
        cell[:, axis] = side * (n - 1)
        seeds.append(cell)
    triangles = np.concatenate(out) if out else np.zeros((0, 3), np.int64)
    seeds = np.concatenate(seeds) if seeds else np.zeros((0, 3), np.int64)
    return triangles, seeds


def _cap_vertex_key(keys: np.ndarray, tri: np.ndarray, i: int, j: int) -> np.ndarray:
    if i == j:
        return keys[:, i] * 8
    lo, hi = (i, j) if np.all(tri[i] <= tri[j]) else (j, i)
    diff = tri[hi] - tri[lo]
    return keys[:, lo] * 8 + int(diff[0] + 2 * diff[1] + 4 * diff[2])


# -- vertices ----------------------------------------------------------------------------------------
def _vertices(grid: _Grid, keys: np.ndarray):
    """Positions of the vertices named by ``keys``: a grid corner (code 0) or the root of F on the edge
    from corner ``key >> 3`` along ``code``, refined by regula falsi and kept inside the edge. Returns
    (positions, on_surface mask)."""
    start = grid.unkey(keys >> 3)
    code = keys & 7
    end = start + CORNERS[code]
    on_edge = code != 0
    positions = grid.world(start).astype(np.float64)
    a, b = positions[on_edge], grid.world(end[on_edge]).astype(np.float64)
    fa, fb = grid.values(a), grid.values(b)
    swap = ~(fa < 0)  # make a the inside end
    a[swap], b[swap] = b[swap].copy(), a[swap].copy()
    fa[swap], fb[swap] = fb[swap].copy(), fa[swap].copy()
    if not np.all(fa < 0) or np.any(fb < 0):
        raise AssertionError("a surface vertex's edge does not change sign: the samples are not repeatable")
    t = _edge_roots(grid, a, b, fa, fb)
    hashed = (keys[on_edge].astype(np.uint64) * np.uint64(0x9E3779B97F4A7C15)) >> np.uint64(11)
    t = np.clip(t + NUDGE * (hashed.astype(np.float64) / 2.0**52 - 1.0), EDGE_MARGIN, 1 - EDGE_MARGIN)
    positions[on_edge] = a + t[:, None] * (b - a)
    return positions, on_edge


def _edge_roots(grid: _Grid, a, b, fa, fb) -> np.ndarray:
    """Where on each edge a (F < 0) to b (F >= 0 or NaN) F crosses 0, as t in [EDGE_MARGIN, 1 - EDGE_MARGIN]:
    regula falsi (Illinois), bisection where a value is not finite."""
    t_in, t_out = np.zeros(len(a)), np.ones(len(a))
    f_in, f_out = fa.copy(), fb.copy()
    for _ in range(ROOT_STEPS):
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            guess = t_in - f_in * (t_out - t_in) / (f_out - f_in)
        ok = np.isfinite(guess) & (guess > t_in) & (guess < t_out)
        guess = np.where(ok, guess, (t_in + t_out) / 2)
        f = grid.values(a + guess[:, None] * (b - a))
        neg = f < 0
        # Illinois: halve the value kept at the end that did not move, so the steps do not stall
        f_out = np.where(neg, f_out / 2, f)
        f_in = np.where(neg, f, f_in / 2)
        t_in = np.where(neg, guess, t_in)
        t_out = np.where(neg, t_out, guess)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        t = t_in - f_in * (t_out - t_in) / (f_out - f_in)
    t = np.where(np.isfinite(t) & (t >= t_in) & (t <= t_out), t, (t_in + t_out) / 2)
    return np.clip(t, EDGE_MARGIN, 1 - EDGE_MARGIN)


def _vertex_normals(surface, vertices, faces, on_surface) -> np.ndarray:
    """Unit normals: F's analytic gradient at the surface vertices; the triangles' area-weighted mean where
    that is not usable (a cap's corners, a zero or undefined gradient)."""
    normals = np.zeros_like(vertices)
    if on_surface.any():
        normals[on_surface] = surface.gradient(vertices[on_surface])
    length = np.linalg.norm(normals, axis=1)
    bad = ~(np.isfinite(length) & (length > 0))
    if bad.any():
        p = vertices[faces]
        area = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        summed = np.zeros_like(vertices)
        for k in range(3):
            np.add.at(summed, faces[:, k], area)
        normals[bad] = summed[bad]
        length = np.linalg.norm(normals, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return normals / length[:, None]


def contour(surface, cells: np.ndarray, depth: int, bounds=None):
    """The mesh of ``surface`` (an :class:`implc.Surface`) from the cells the voxelizer kept at ``depth``
    ((N, 3) cell indices): see the module's docstring for what it promises. Returns an
    :class:`implc.Mesh`."""
    from .triangle_mesh import Mesh
    stats = MeshStats()
    t0 = time.perf_counter()
    grid = _Grid(surface, depth, surface.bounds if bounds is None else bounds)
    cells = np.asarray(cells, dtype=np.int64).reshape(-1, 3)
    stats.cells = len(cells)
    inside = grid.inside(cells[:, None, :] + CORNERS)
    caps, seeds = _cap_triangles(grid)
    t1 = time.perf_counter()
    cells, inside, stats.added_cells = _close(grid, cells, inside, seeds)
    crossed = inside.any(1) & ~inside.all(1)
    stats.crossed_cells = int(crossed.sum())
    t2 = time.perf_counter()
    keys = np.concatenate([_tet_triangles(grid, cells[crossed], inside[crossed]), caps])
    stats.cap_triangles = len(caps)
    unique, faces = np.unique(keys, return_inverse=True)
    faces = faces.reshape(-1, 3)
    t3 = time.perf_counter()
    vertices, on_surface = _vertices(grid, unique)
    normals = _vertex_normals(surface, vertices, faces, on_surface)
    t4 = time.perf_counter()
    stats.triangles, stats.vertices = len(faces), len(vertices)
    stats.seconds = {"signs": t1 - t0, "closure": t2 - t1, "triangles": t3 - t2, "vertices": t4 - t3,
                     "total": t4 - t0}
    return Mesh(vertices, faces, normals, stats=stats, bounds=grid_bounds(grid))


def grid_bounds(grid: _Grid) -> tuple[tuple[float, float], ...]:
    return tuple((float(lo), float(hi)) for lo, hi in zip(grid.lo, grid.hi))
