"""Checks of a mesh against independent truths: exact edge counts, exact orientation tests in rationals,
F sampled by numpy, the exact volume; and the surfaces the mesh tests share."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
import sympy

from implc import x, y, z
from implc.compiler.symbols import cartesian_form
from implc.meshing.triangle_mesh import Mesh

BOX_BALL = sympy.Max(sympy.Abs(x) - 0.6, sympy.Abs(y) - 0.6, sympy.Abs(z) - 0.6, 0.75 - sympy.sqrt(x**2 + y**2 + z**2))


SURFACES = {  # name: (expression, bounds)
    "ball": (x**2 + y**2 + z**2 - sympy.Rational(1, 2), ((-1, 1),) * 3),
    "heightfield": (z - sympy.sin(3 * x) * sympy.cos(2 * y) / 3, ((-1, 1),) * 3),  # closed by the box's faces
    "gyroid": (sympy.sin(4 * x) * sympy.cos(4 * y) + sympy.sin(4 * y) * sympy.cos(4 * z)
               + sympy.sin(4 * z) * sympy.cos(4 * x), ((-1, 1),) * 3),
    "box_minus_ball": (BOX_BALL, ((-1, 1),) * 3),
    "off_centre_bounds": (x**2 + y**2 + z**2 - 1, ((-0.3, 1.2), (-1.1, 0.4), (0.1, 0.9))),
}


def numpy_f(expr):
    fn = sympy.lambdify((x, y, z), cartesian_form(expr), modules="numpy")
    return lambda p: np.broadcast_to(np.asarray(fn(p[:, 0], p[:, 1], p[:, 2]), dtype=np.float64), (len(p),))


# -- the independent checks ----------------------------------------------------------------------------
def edge_counts(faces):
    """(undirected edge use counts, directed edge use counts), counted directly."""
    directed = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    _, d = np.unique(directed, axis=0, return_counts=True)
    _, u = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)
    return u, d


def assert_closed_manifold(mesh: Mesh):
    v, f = mesh.vertices, mesh.faces
    assert len(f) > 0
    undirected, directed = edge_counts(f)
    assert np.all(undirected == 2), f"{np.sum(undirected != 2)} edges not in exactly two faces"
    assert np.all(directed == 1), f"{np.sum(directed != 1)} directed edges used twice (orientation flips)"
    assert np.all((f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 2] != f[:, 0]))
    p = v[f]
    area = np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1) / 2
    assert area.min() > 0, "a degenerate triangle"
    import manifold3d
    import pymeshlab
    import trimesh
    solid = manifold3d.Manifold(manifold3d.Mesh(vert_properties=v.astype(np.float32),
                                                tri_verts=f.astype(np.uint32)))
    assert solid.status() == manifold3d.Error.NoError
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=v, face_matrix=f.astype(np.int32)))
    topo = ms.get_topological_measures()
    assert topo["non_two_manifold_edges"] == 0 and topo["non_two_manifold_vertices"] == 0
    assert topo["boundary_edges"] == 0
    ms.compute_selection_by_self_intersections_per_face()
    selected = np.flatnonzero(ms.current_mesh().face_selection_array())
    assert_selected_faces_do_not_meet(v, f, selected)
    tm = trimesh.Trimesh(v, f, process=False)
    assert tm.is_watertight and tm.is_winding_consistent
    assert tm.volume > 0, "oriented inward"
    assert tm.volume == pytest.approx(mesh.volume, rel=1e-9)


def _triple(u, v, w):
    """u · (v × w), exact for rationals."""
    return u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0]) + u[2] * (v[0] * w[1] - v[1] * w[0])


def _orientation(a, b, c, d) -> int:
    """The sign of the volume of (a, b, c, d), exact (rationals from the doubles)."""
    det = _triple(*([q - p for p, q in zip(a, e)] for e in (b, c, d)))
    return (det > 0) - (det < 0)


def _orientation_2d(a, b, c) -> int:
    det = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
    return (det > 0) - (det < 0)


def _segments_meet_2d(p, q, a, b) -> bool:
    o = [_orientation_2d(p, q, a), _orientation_2d(p, q, b), _orientation_2d(a, b, p), _orientation_2d(a, b, q)]
    if o[0] * o[1] <= 0 and o[2] * o[3] <= 0:
        if o == [0, 0, 0, 0]:  # collinear: their extents overlap
            return all(min(p[k], q[k]) <= max(a[k], b[k]) and min(a[k], b[k]) <= max(p[k], q[k]) for k in (0, 1))
        return True
    return False


def _coplanar_segment_meets_triangle(p, q, a, b, c) -> bool:
    """pq and abc in one plane: in the axis plane where the triangle's projection is not degenerate."""
    for drop in range(3):
        keep = [k for k in range(3) if k != drop]
        p2, q2, a2, b2, c2 = ([u[k] for k in keep] for u in (p, q, a, b, c))
        turn = _orientation_2d(a2, b2, c2)
        if turn:
            inside = all(turn * _orientation_2d(u, v, p2) >= 0 for u, v in ((a2, b2), (b2, c2), (c2, a2)))
            return inside or any(_segments_meet_2d(p2, q2, u, v) for u, v in ((a2, b2), (b2, c2), (c2, a2)))
    raise AssertionError("a degenerate triangle")


def _segment_meets_triangle(p, q, a, b, c) -> bool:
    """Whether segment pq meets triangle abc (both closed), exactly."""
    sp, sq = _orientation(a, b, c, p), _orientation(a, b, c, q)
    if sp == sq != 0:
        return False
    if sp == sq == 0:
        return _coplanar_segment_meets_triangle(p, q, a, b, c)
    sides = [_orientation(p, q, a, b), _orientation(p, q, b, c), _orientation(p, q, c, a)]
    return all(s >= 0 for s in sides) or all(s <= 0 for s in sides)


def triangles_meet(first, second) -> bool:
    """Whether two triangles ((3, 3) doubles each) share a point, in exact rational arithmetic: an edge of
    one meets the other (in their plane where they are coplanar)."""
    a, b = ([[Fraction(c) for c in row] for row in t.tolist()] for t in (first, second))
    return any(_segment_meets_triangle(x[i], x[(i + 1) % 3], *y) for x, y in ((a, b), (b, a)) for i in range(3))


def assert_selected_faces_do_not_meet(vertices, faces, selected):
    """pymeshlab's self-intersection selection is a floating-point test with tolerances: on nearly coplanar
    triangles (a plane across an axis, mid-cell) it selects disjoint ones (fuzzing found 800 on one mesh).
    Every pair of the selected faces that shares no vertex and whose boxes overlap is tested exactly: none
    may meet (a pair that shares a vertex is left to the edge and fan counts)."""
    corners = vertices[faces[selected]]
    lo, hi = corners.min(1), corners.max(1)
    for i in range(len(selected)):
        for j in np.flatnonzero(np.all((lo[i] <= hi) & (lo <= hi[i]), axis=1)):
            if j > i and not set(faces[selected[i]]) & set(faces[selected[j]]):
                assert not triangles_meet(corners[i], corners[j]), ("self-intersecting faces", selected[i],
                                                                    selected[j])


def assert_vertices_on_sign_changes(mesh: Mesh, f, bounds, depth, kept):
    """Each vertex lies on the segment between its two witnesses, points of one cell that the voxelizer
    kept where numpy's F is negative and not negative; a vertex named by itself (a cap's corner) lies on
    the bounds where numpy's F is negative."""
    v, w = mesh.vertices, mesh.witnesses
    lo = np.array([b[0] for b in bounds], float)
    hi = np.array([b[1] for b in bounds], float)
    assert np.all(v >= lo) and np.all(v <= hi), "a vertex outside the bounds"
    itself = np.all(w[:, 0] == w[:, 1], axis=1)
    assert np.array_equal(v[itself], w[itself, 0])
    assert np.all(f(v[itself]) < 0)
    on_bounds = (v[itself] == lo) | (v[itself] == hi)
    assert np.all(on_bounds.any(1))
    a, b = w[~itself, 0], w[~itself, 1]
    assert np.all(f(a) < 0) and not np.any(f(b) < 0), "a witness pair without a sign change of numpy's F"
    assert_on_witness_edges_in_kept_cells(mesh, bounds, depth, kept)


def assert_on_witness_edges_in_kept_cells(mesh: Mesh, bounds, depth, kept):
    """Each vertex not named by itself lies strictly inside the segment between its witnesses (a vertex on
    an edge), or strictly inside the one cell of the 2^depth grid that has both witnesses among its corners
    (a dual vertex, one per cell: its witnesses are the ends of an edge of that cell); the witnesses lie in
    one cell, a cell the voxelizer kept (``kept``)."""
    w = mesh.witnesses
    lo = np.array([b[0] for b in bounds], float)
    hi = np.array([b[1] for b in bounds], float)
    n = 1 << depth
    itself = np.all(w[:, 0] == w[:, 1], axis=1)
    a, b, p = w[~itself, 0], w[~itself, 1], mesh.vertices[~itself]
    t = np.einsum("ij,ij->i", p - a, b - a) / np.einsum("ij,ij->i", b - a, b - a)
    on_segment = np.all(np.abs(a + t[:, None] * (b - a) - p) <= 1e-12, axis=1)
    assert np.all((t[on_segment] > 0) & (t[on_segment] < 1))
    ga, gb, gp = ((u - lo) / (hi - lo) * n for u in (a, b, p))
    cell = np.floor(np.minimum(ga, gb) + 1e-9)
    cell = np.minimum(cell, n - 1)
    assert np.all(np.maximum(ga, gb) <= cell + 1 + 1e-9), "witnesses in different cells"
    inner = ~on_segment  # a dual vertex: strictly inside its cell, the witnesses two of that cell's corners
    cell_of_point = np.floor(gp[inner])
    assert np.all((gp[inner] > cell_of_point) & (cell_of_point < n)), "a dual vertex on a grid plane"
    for ends in (ga[inner], gb[inner]):
        corner = np.round(ends)
        assert np.allclose(ends, corner, rtol=0, atol=1e-9), "a dual vertex's witness that is not a grid corner"
        assert np.all((corner >= cell_of_point) & (corner <= cell_of_point + 1)), "a dual vertex outside its cell"
    cell[inner] = cell_of_point
    keys = (cell[:, 0] * n + cell[:, 1]) * n + cell[:, 2]
    kept_keys = (kept[:, 0].astype(np.int64) * n + kept[:, 1]) * n + kept[:, 2]
    assert np.all(np.isin(keys.astype(np.int64), kept_keys)), "a vertex in a cell the voxelizer did not keep"


def exact_volume(mesh: Mesh) -> Fraction:
    """The volume the mesh encloses, in exact rational arithmetic over its vertices' doubles (the
    divergence theorem, each triangle's signed tetrahedron with the origin)."""
    exact = [[Fraction(c) for c in row] for row in mesh.vertices.tolist()]
    return sum((_triple(exact[i], exact[j], exact[k]) for i, j, k in mesh.faces.tolist()), Fraction(0)) / 6


def assert_volume_within(mesh: Mesh, lo: float, hi: float):
    """lo <= the mesh's exact volume <= hi: Mesh.volume's double sum first, and where that lies outside
    (it can, by its rounding, where the solid fills the bounds and lo = hi up to an ulp) the exact sum."""
    if not lo <= mesh.volume <= hi:
        assert Fraction(lo) <= exact_volume(mesh) <= Fraction(hi), (lo, mesh.volume, hi)


# -- sharp features -----------------------------------------------------------------------------------
def point_triangle_distance(p, tri):
    """Distance from point ``p`` to each triangle of ``tri`` (T, 3, 3): the closest point by region
    (Ericson, Real-Time Collision Detection, 5.1.5)."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    ab, ac = b - a, c - a
    d1, d2 = (ab * (p - a)).sum(1), (ac * (p - a)).sum(1)
    d3, d4 = (ab * (p - b)).sum(1), (ac * (p - b)).sum(1)
    d5, d6 = (ab * (p - c)).sum(1), (ac * (p - c)).sum(1)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(all="ignore"):
        denom = va + vb + vc
        closest = a + ab * (vb / denom)[:, None] + ac * (vc / denom)[:, None]
        regions = [
            ((d1 <= 0) & (d2 <= 0), a),
            ((d3 >= 0) & (d4 <= d3), b),
            ((d6 >= 0) & (d5 <= d6), c),
            ((vc <= 0) & (d1 >= 0) & (d3 <= 0), a + ab * (d1 / (d1 - d3))[:, None]),
            ((vb <= 0) & (d2 >= 0) & (d6 <= 0), a + ac * (d2 / (d2 - d6))[:, None]),
            ((va <= 0) & (d4 >= d3) & (d5 >= d6), b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)))[:, None]),
        ]
    done = np.zeros(len(tri), bool)
    for mask, point in regions:
        pick = mask & ~done
        closest[pick] = point[pick]
        done |= pick
    return np.linalg.norm(closest - p, axis=1)
